// SPDX-License-Identifier: MIT
// TSDF voxels (000-digest §1.3.2) of a box of `dim_x * dim_y * dim_z` voxels, one u32 each
// packing a signed-normalised 16-bit TSDF in [-1, 1] (units of the truncation band of the
// samples averaged into it, truncation_band_m: μ, wider for noisy far samples, so |tsdf| μ never
// exceeds the distance to the surface; low half, two's complement) and a 16-bit integration
// weight (high half; 0 = never observed). A dense map stores them all, x fastest (voxel_index); a
// sparse one only its allocated blocks (map.wgsl). Voxel (x, y, z) has its centre at
// origin + (x + 0.5, y + 0.5, z + 0.5) * voxel_size, in world metres.
// Mirrors `VolumeDesc` in core/src/tsdf.rs and the helpers in core/src/cpu/shared.rs.
#import kinect

struct VolumeDesc {
    // Voxels along x.
    dim_x: u32,
    // Voxels along y.
    dim_y: u32,
    // Voxels along z.
    dim_z: u32,
    // Cap of the integration weight.
    max_weight: u32,
    // World x of the anchor voxel's outer corner (voxel_anchor: (0, 0, 0) for a dense box),
    // metres.
    origin_x_m: f32,
    // World y of the origin corner, metres.
    origin_y_m: f32,
    // World z of the origin corner, metres.
    origin_z_m: f32,
    // Voxel edge, metres.
    voxel_size_m: f32,
    // Truncation distance μ, metres.
    truncation_m: f32,
    // MAP_DENSE (0): every voxel of the box is stored, at voxel_index(); MAP_SPARSE (1): blocks
    // of 8³ voxels are allocated where surfaces are, found through the hash table of
    // shared/map.wgsl, and the box is the addressable range of block keys.
    kind: u32,
    // Sparse: slots of the block hash table (a power of two); dense: 0.
    hash_slots: u32,
    // Sparse: blocks in the voxel pool; dense: 0.
    pool_blocks: u32,
    // How many standard deviations of the Kinect noise model a sample's truncation band spans
    // where that is wider than μ (truncation_band_m); 0: μ at every depth.
    noise_band_sigmas: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

const TSDF_SCALE: f32 = 32767.0;

// Widest truncation band, voxels: 2 sparse blocks, so a pixel's band crosses a bounded number
// of blocks (block_alloc's MAP_MAX_BAND_BLOCKS) and a map fused to a Kinect's full 8 m range
// stays within one pool (fr3_teddy: 72,853 blocks with a 32-voxel cap, more than a pool holds).
// 3σ of the Kinect model reaches it at 6.1 m with 11.7 mm voxels (never within the default 5 m
// range), at 4.1 m with 5 mm voxels.
const MAX_BAND_VOXELS: f32 = 16.0;

// The truncation band of a depth sample measured at `depth_m` metres: μ, widened where the
// sensor's noise is larger to `noise_band_sigmas` standard deviations of the Kinect model
// (kinect.wgsl), at most MAX_BAND_VOXELS. A band narrower than the noise biases the fused
// surface away from the camera (samples in front are clamped to +1, those behind beyond the
// band dropped: 13 mm at 5 m for μ = 4.7 cm); at 3σ both tails hold 0.3 % of the samples.
fn truncation_band_m(d: VolumeDesc, depth_m: f32) -> f32 {
    let noise_m = d.noise_band_sigmas * kinect_sigma_m(depth_m);
    return max(d.truncation_m, min(noise_m, MAX_BAND_VOXELS * d.voxel_size_m));
}

// A voxel whose TSDF is at least this close to +1 (truncation units) is far from any surface:
// at least μ - ½√3 voxel in front of one.
const FAR_TSDF: f32 = 0.999;

// The volume is tiled into bricks of 8³ voxels for empty-space skipping: one word per brick
// (x fastest), non-zero once a voxel in it has held a TSDF below FAR_TSDF (a surface or its
// truncation band may lie in it; never cleared until the volume is reset).
const BRICK_SHIFT: u32 = 3u;

fn brick_dims(d: VolumeDesc) -> vec3<u32> {
    return (vec3<u32>(d.dim_x, d.dim_y, d.dim_z) + vec3<u32>((1u << BRICK_SHIFT) - 1u)) >> vec3<u32>(BRICK_SHIFT);
}

// The brick of voxel (x, y, z).
fn brick_index(d: VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    let b = brick_dims(d);
    return (x >> BRICK_SHIFT) + b.x * ((y >> BRICK_SHIFT) + b.y * (z >> BRICK_SHIFT));
}

fn voxel_index(d: VolumeDesc, x: u32, y: u32, z: u32) -> u32 {
    return x + d.dim_x * (y + d.dim_y * z);
}

const MAP_DENSE: u32 = 0u;
const MAP_SPARSE: u32 = 1u;

// The map kind a pipeline is compiled for (set when it is created, `DeferredPipeline::variant`):
// MAP_DENSE or MAP_SPARSE compile the other kind's paths out of the shared map code (on a CPU
// adapter a branch costs its arithmetic even where no invocation takes it); the default, 2,
// reads the kind from the VolumeDesc.
override MAP_KIND: u32 = 2u;

// Whether `d` is a sparse map (constant in a pipeline compiled for one kind).
fn map_is_sparse(d: VolumeDesc) -> bool {
    if MAP_KIND == MAP_DENSE || MAP_KIND == MAP_SPARSE {
        return MAP_KIND == MAP_SPARSE;
    }
    return d.kind == MAP_SPARSE;
}

// The voxel whose outer corner the origin gives: (0, 0, 0) for a dense box; the middle of a
// sparse map's box (rounded down to a block: a sparse box spans 164 m at 1 cm, and its corner
// that far away would cost f32 positions near the camera tens of micrometres), so positions are
// computed from voxel offsets to it, small numbers near the first camera.
fn voxel_anchor(d: VolumeDesc) -> vec3<u32> {
    if map_is_sparse(d) {
        return (vec3<u32>(d.dim_x, d.dim_y, d.dim_z) >> vec3<u32>(BRICK_SHIFT + 1u)) << vec3<u32>(BRICK_SHIFT);
    }
    return vec3<u32>(0u);
}

fn voxel_centre_in_world(d: VolumeDesc, x: u32, y: u32, z: u32) -> vec3<f32> {
    let offset = vec3<i32>(vec3<u32>(x, y, z)) - vec3<i32>(voxel_anchor(d));
    return vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m) + (vec3<f32>(offset) + vec3<f32>(0.5)) * d.voxel_size_m;
}

// World position of the box's voxel (0, 0, 0) outer corner (far away for a sparse map: for
// clipping, not for positions).
fn box_corner_in_world(d: VolumeDesc) -> vec3<f32> {
    return vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m) - vec3<f32>(voxel_anchor(d)) * d.voxel_size_m;
}

// TSDF in [-1, 1] and weight -> one voxel word. The TSDF rounds to nearest, ties to even.
fn pack_voxel(tsdf: f32, weight: u32) -> u32 {
    let t = i32(round(clamp(tsdf, -1.0, 1.0) * TSDF_SCALE));
    return (bitcast<u32>(t) & 0xffffu) | (min(weight, 0xffffu) << 16u);
}

fn voxel_tsdf(word: u32) -> f32 {
    return f32(bitcast<i32>(word << 16u) >> 16u) / TSDF_SCALE;
}

fn voxel_weight(word: u32) -> u32 {
    return word >> 16u;
}

// RGB8 colour of a voxel, packed r | g << 8 | b << 16 (alpha byte unused, 0).
fn pack_rgb8(rgb: vec3<f32>) -> u32 {
    let c = vec3<u32>(round(clamp(rgb, vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0));
    return c.x | (c.y << 8u) | (c.z << 16u);
}

fn unpack_rgb8(word: u32) -> vec3<f32> {
    return vec3<f32>(f32(word & 0xffu), f32((word >> 8u) & 0xffu), f32((word >> 16u) & 0xffu)) / 255.0;
}
