// SPDX-License-Identifier: MIT
//! Each invocation casts the ray of one pixel through the TSDF (000-digest §1.3.3) from the pose
//! in `pose` (the tracker's, a free view's, a virtual sensor's); nothing is written when that
//! pose is inactive (a lost frame keeps the previous prediction). The march starts at the near
//! plane (or the volume's entry) and reads only the nearest voxel while that voxel says the
//! surface is far: unobserved space and the truncated band (TSDF within `FAR_TSDF` of +1, at
//! least μ - ½√3 voxel from any surface) are crossed in steps of `step_factor * μ` with one read
//! per step. Nearer the surface it samples the trilinear TSDF and steps by the sampled distance
//! (at least half a voxel), until the TSDF changes sign from + to - (a ray that reaches negative
//! space any other way, from unobserved space or starting inside an object, ends there: only a
//! back face could follow); the surface point is the
//! linear interpolation of the crossing (the sample before it re-read trilinearly when it was a
//! nearest-voxel one). Writes the world-frame vertex, the depth (camera z) a virtual sensor at
//! this pose would see and the model colour (nearest voxel); `surface_normals` then derives the
//! normals from the vertices. Misses, back faces and unobserved space give NaN / 0. A prediction rendered at the pose a depth image was just fused at may
//! search each ray only within μ + 3σ (Kinect noise) of that pixel's measured depth instead of
//! the whole depth range: the fused surface lies there, and a model surface further in front is
//! one the new measurement sees through. Rays without such a measurement (or every ray, for a
//! free view) search only the depth interval `raycast_range` found for their tile, and a tile
//! no surface brick covers is a miss without a step.
#import invalid
#import camera
#import camera_pose
#import tsdf_sample
#import kinect
#import depth_hint

struct RaycastParams {
    // The volume.
    volume: VolumeDesc,
    // Intrinsics of the rendered images.
    intrinsics: Intrinsics,
    // Nearest depth searched, metres.
    min_depth_m: f32,
    // Farthest depth searched, metres.
    max_depth_m: f32,
    // Largest step as a fraction of μ.
    step_factor: f32,
    // Cap on march steps per ray.
    max_steps: u32,
    // Non-zero: search each ray only near the depth `depth_hint_raw` measured at its pixel (a
    // prediction at the pose that depth was just fused at), within hint_margin_m + 3σ of it.
    use_depth_hint: u32,
    // The truncation distance μ the hint's search window extends either side of it, metres.
    hint_margin_m: f32,
    // Metres per raw unit of `depth_hint_raw`.
    hint_metres_per_unit: f32,
    // Pixels along each edge of a `depth_range_tiles` tile; 0: no range tiles (every ray
    // without a hint searches the whole depth range).
    range_tile_px: u32,
    // Tiles along x.
    range_tiles_x: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}


@group(0) @binding(0) var<uniform> params: RaycastParams;
// The pose to render from.
@group(0) @binding(1) var<uniform> pose: CameraPose;
// Voxel words (TSDF + weight).
@group(0) @binding(2) var<storage, read> tsdf_volume: array<u32>;
// Colour words (one placeholder word when colour is off).
@group(0) @binding(3) var<storage, read> color_volume: array<u32>;
// Out: surface points (x, y, z, 1), world frame.
@group(0) @binding(4) var<storage, read_write> vertex_in_world: array<vec4<f32>>;
// Out: depth along the camera's z, metres.
@group(0) @binding(5) var<storage, read_write> depth_m: array<f32>;
// Out: model colour, RGBA8.
@group(0) @binding(6) var<storage, read_write> color_rgba8: array<u32>;
// The raw sensor depth measured at each pixel from this pose (u16 units, two per word, low half
// first; 0: no return), when `use_depth_hint` is set; one placeholder word otherwise. Raw, not
// the range-clipped metres: a return beyond the depth range still says that nothing stands in
// front of it.
@group(0) @binding(7) var<storage, read> depth_hint_raw: array<u32>;
// Per tile of `range_tile_px`², the camera-depth interval where surfaces may lie (written by
// `raycast_range`: !bits(nearest z), bits(farthest z); 0 farthest: none), when
// `range_tile_px` is non-zero; one placeholder word otherwise.
@group(0) @binding(8) var<storage, read> depth_range_tiles: array<u32>;
// A sparse map's hash table (map.wgsl); one placeholder word for a dense map.
@group(0) @binding(9) var<storage, read> block_table: array<u32>;

const OPAQUE: u32 = 0xff000000u;

fn write_miss(ix: u32) {
    vertex_in_world[ix] = invalid_vec4();
    depth_m[ix] = invalid_f32();
    color_rgba8[ix] = 0u;
}

// The slot of the nearest voxel to a world point (map_lookup.wgsl): NO_SLOT outside the box or
// where a sparse map has no block.
fn nearest_slot(d: VolumeDesc, p_world: vec3<f32>) -> u32 {
    let g = floor((p_world - vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m)) / d.voxel_size_m) + vec3<f32>(voxel_anchor(d));
    if g.x < 0.0 || g.y < 0.0 || g.z < 0.0 || g.x >= f32(d.dim_x) || g.y >= f32(d.dim_y) || g.z >= f32(d.dim_z) {
        return NO_SLOT;
    }
    return voxel_slot(d, u32(g.x), u32(g.y), u32(g.z));
}

// The ray parameter at which the ray (origin `o`, reciprocal direction `inv_dir`) leaves the
// block of 8³ voxels that holds the world point `p`.
fn block_exit_t(d: VolumeDesc, o: vec3<f32>, inv_dir: vec3<f32>, p: vec3<f32>) -> f32 {
    // Blocks are aligned to the anchor (a multiple of a block from the box's corner).
    let anchor_m = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m);
    let edge_m = f32(1u << BRICK_SHIFT) * d.voxel_size_m;
    let lo = anchor_m + floor((p - anchor_m) / edge_m) * edge_m;
    let t_a = (lo - o) * inv_dir;
    let t_b = (lo + vec3<f32>(edge_m) - o) * inv_dir;
    let t_out = max(t_a, t_b);
    return min(min(t_out.x, t_out.y), t_out.z);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = params.intrinsics;
    if gid.x >= k.width_px || gid.y >= k.height_px || pose.enabled == 0u {
        return;
    }
    let ix = gid.y * k.width_px + gid.x;
    let d = params.volume;
    // Ray in world: origin at the camera centre, unit direction; `z_per_t` converts ray length
    // to camera depth.
    let ray_cam = back_project(k, f32(gid.x), f32(gid.y), 1.0);
    let inv_len = 1.0 / length(ray_cam);
    let z_per_t = inv_len;
    let world_from_camera = pose.world_from_camera;
    let origin = world_from_camera[3].xyz;
    let dir = (world_from_camera * vec4<f32>(ray_cam * inv_len, 0.0)).xyz;
    // Clip to the box of voxel centres (where trilinear samples exist) and the depth range.
    let lo = box_corner_in_world(d) + vec3<f32>(0.5 * d.voxel_size_m);
    let hi = lo + vec3<f32>(f32(d.dim_x - 1u), f32(d.dim_y - 1u), f32(d.dim_z - 1u)) * d.voxel_size_m;
    // Axis-parallel rays: a tiny stand-in keeps the slab test finite.
    let safe_dir = select(dir, vec3<f32>(1e-12), abs(dir) < vec3<f32>(1e-12));
    let inv_dir = 1.0 / safe_dir;
    let t0 = (lo - origin) * inv_dir;
    let t1 = (hi - origin) * inv_dir;
    let t_near = min(t0, t1);
    let t_far = max(t0, t1);
    var t = max(max(max(t_near.x, t_near.y), t_near.z), params.min_depth_m / z_per_t);
    var t_end = min(min(min(t_far.x, t_far.y), t_far.z), params.max_depth_m / z_per_t);
    let max_step = params.step_factor * d.truncation_m;
    var hinted = false;
    if params.use_depth_hint != 0u {
        let hint = depth_hint_range(gid.xy);
        if is_valid_f32(hint.x) {
            // The search window: μ + 3σ either side of the measured surface(s).
            t = max(t, (hint.x - params.hint_margin_m - 3.0 * kinect_sigma_m(hint.x)) / z_per_t);
            t_end = min(t_end, (hint.y + params.hint_margin_m + 3.0 * kinect_sigma_m(hint.y)) / z_per_t);
            hinted = true;
        }
    }
    if !hinted && params.range_tile_px != 0u {
        // No measurement here: search where surface bricks lie along this tile's rays, one
        // step either side (the positive sample before a crossing may fall just outside).
        let tile = (gid.y / params.range_tile_px) * params.range_tiles_x + gid.x / params.range_tile_px;
        let far_word = depth_range_tiles[2u * tile + 1u];
        if far_word == 0u {
            write_miss(ix);
            return;
        }
        t = max(t, bitcast<f32>(~depth_range_tiles[2u * tile]) / z_per_t - max_step);
        t_end = min(t_end, bitcast<f32>(far_word) / z_per_t + max_step);
    }
    if !(t < t_end) {
        write_miss(ix);
        return;
    }
    let min_step = 0.5 * d.voxel_size_m;
    var prev_t = t;
    var prev = TsdfSample(0.0, false);
    // Whether `prev` came from the nearest voxel rather than trilinear interpolation.
    var prev_nearest = false;
    var hit = false;
    // The first negative sample after a positive one (the crossing's far side).
    var after = TsdfSample(0.0, false);
    for (var i = 0u; i < params.max_steps && t < t_end; i++) {
        let p = origin + dir * t;
        let slot = nearest_slot(d, p);
        if slot == NO_SLOT && d.kind == MAP_SPARSE {
            // A block a sparse map never allocated holds no surface: cross it in one step.
            prev = TsdfSample(0.0, false);
            prev_nearest = false;
            prev_t = t;
            t = max(block_exit_t(d, origin, inv_dir, p) + 0.01 * d.voxel_size_m, t + min_step);
            continue;
        }
        var word = 0u;
        if slot != NO_SLOT {
            word = tsdf_volume[slot];
        }
        if voxel_weight(word) == 0u {
            prev = TsdfSample(0.0, false);
            prev_nearest = false;
            prev_t = t;
            t += max_step;
            continue;
        }
        if voxel_tsdf(word) >= FAR_TSDF {
            prev = TsdfSample(1.0, true);
            prev_nearest = true;
            prev_t = t;
            t += max_step;
            continue;
        }
        let s = sample_tsdf(d, p);
        if s.valid && s.tsdf <= 0.0 {
            // A crossing from + to -: the surface. Without a positive sample before it (a ray
            // starting inside an object, or entering it from unobserved space) no front face
            // can follow before the back one, so the ray sees nothing here.
            if prev.valid && prev.tsdf > 0.0 {
                after = s;
                hit = true;
            }
            break;
        }
        prev = s;
        prev_nearest = false;
        prev_t = t;
        var step = max_step;
        if s.valid {
            step = clamp(s.tsdf * d.truncation_m * params.step_factor, min_step, max_step);
        }
        t += step;
    }
    if !hit {
        write_miss(ix);
        return;
    }
    // The crossing: the sample before it re-read trilinearly when it was a nearest-voxel one
    // (after the march, so that this sample's code is not part of every step).
    var before = prev;
    if prev_nearest {
        let exact = sample_tsdf(d, origin + dir * prev_t);
        if exact.valid && exact.tsdf > 0.0 {
            before = exact;
        }
    }
    let t_hit = prev_t + (t - prev_t) * before.tsdf / (before.tsdf - after.tsdf);
    let p = origin + dir * t_hit;
    vertex_in_world[ix] = vec4<f32>(p, 1.0);
    depth_m[ix] = t_hit * z_per_t;
    // Nearest voxel centre's colour.
    let g = (p - vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m)) / d.voxel_size_m + vec3<f32>(voxel_anchor(d));
    let c = min(vec3<u32>(max(g, vec3<f32>(0.0))), vec3<u32>(d.dim_x - 1u, d.dim_y - 1u, d.dim_z - 1u));
    let c_slot = voxel_slot(d, c.x, c.y, c.z);
    var rgb = 0u;
    if c_slot != NO_SLOT {
        rgb = color_volume[min(c_slot, arrayLength(&color_volume) - 1u)];
    }
    color_rgba8[ix] = rgb | OPAQUE;
}
