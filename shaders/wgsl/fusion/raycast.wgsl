// SPDX-License-Identifier: MIT
//! Each invocation casts the ray of one pixel through the TSDF (000-digest §1.3.3) from the pose
//! in `pose` (the tracker's, a free view's, a virtual sensor's); nothing is written when that
//! pose is inactive (a lost frame keeps the previous prediction). The march starts at the near
//! plane (or the volume's entry) and reads only the nearest voxel (coarse): unobserved space
//! and the truncated band (TSDF within `FAR_TSDF` of +1, at least μ - ½√3 voxel from any
//! surface) are crossed in steps of `step_factor * μ`; nearer a surface each step is what the
//! nearest voxel's TSDF less half a voxel diagonal allows (no farther than a trilinear sample
//! there could say), at least half a voxel, until the nearest voxel lies within that margin of
//! a surface or behind one.
//! Then (fine) trilinear samples look for a bracket of the crossing, a positive sample before
//! a non-positive one at most two voxels apart (probing back from the candidate, on past a
//! positive sample, or halving; at most `FINE_SAMPLES`); the surface point is the linear
//! interpolation of that bracket. A ray that reaches
//! negative space any other way (from unobserved space, or starting inside an object) ends
//! there: only a back face could follow. A bracket that does not close (an unobserved corner,
//! a ray grazing a surface within the margin) marches on coarsely. Trilinear samples cost
//! most on CPU adapters, which run invocations in lockstep: the coarse march reads one word a
//! step, and the fine step's samples (two for most rays) come after it from one call site. Writes the world-frame vertex, the depth
//! (camera z) a virtual sensor at this pose would see and the model colour (nearest voxel);
//! `surface_normals` then derives the
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

// False in a pipeline for renders without a depth hint (`use_depth_hint` is then 0): compiles
// the hint's window out.
override DEPTH_HINTS: bool = true;

const OPAQUE: u32 = 0xff000000u;
// Coarse-then-fine rounds per ray (a round ends in a hit, a miss, or marches on: a ray
// grazing a surface within the margin without crossing it).
const REFINE_ROUNDS: u32 = 8u;
// Trilinear samples of a fine step, at most.
const FINE_SAMPLES: u32 = 8u;

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
    if DEPTH_HINTS && params.use_depth_hint != 0u {
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
    // How much lower than at a voxel's centre the TSDF may be anywhere within half its
    // diagonal, truncation units (a distance changes by at most one voxel per voxel).
    let nearest_margin = 0.5 * sqrt(3.0) * d.voxel_size_m / d.truncation_m;
    let t_start = t;
    var i = 0u;
    var hit = false;
    var t_hit = 0.0;
    // Whether the last coarse sample, at prev_t, was a positive one.
    var prev_positive = false;
    var prev_t = t;
    for (var round = 0u; round < REFINE_ROUNDS; round++) {
        // Coarse: the nearest voxel only, until it lies within the margin of a surface or
        // behind one.
        var candidate = false;
        loop {
            if i >= params.max_steps || !(t < t_end) {
                break;
            }
            i++;
            let p = origin + dir * t;
            let slot = nearest_slot(d, p);
            if slot == NO_SLOT && map_is_sparse(d) {
                // A block a sparse map never allocated holds no surface: cross it in one step.
                prev_positive = false;
                prev_t = t;
                t = max(block_exit_t(d, origin, inv_dir, p) + 0.01 * d.voxel_size_m, t + min_step);
                continue;
            }
            var word = 0u;
            if slot != NO_SLOT {
                word = tsdf_volume[slot];
            }
            if voxel_weight(word) == 0u {
                prev_positive = false;
                prev_t = t;
                t += max_step;
                continue;
            }
            let n = voxel_tsdf(word);
            // Above the margin the trilinear TSDF here is positive too: march on. (A first
            // positive sample after unobserved space is taken as the start of a bracket.)
            if n > nearest_margin || (n > 0.0 && !prev_positive) {
                prev_positive = true;
                prev_t = t;
                if n >= FAR_TSDF {
                    t += max_step;
                } else {
                    // No farther than a trilinear sample here could say (n less the margin).
                    t += clamp((n - nearest_margin) * d.truncation_m * params.step_factor, min_step, max_step);
                }
                continue;
            }
            // Within the margin of a surface, or behind one: a crossing may be near. Behind a
            // surface without a positive sample before it (a ray starting inside an object, or
            // entering it from unobserved space) no front face can follow: the ray ends here.
            candidate = prev_positive;
            break;
        }
        if !candidate {
            break;
        }
        // Fine: trilinear samples at probes chosen one after another, one sample call per
        // step whatever the probe (lanes run in lockstep, so a lane's extra probe costs every
        // lane one sample, not a loop of its own): first the candidate; then, lacking a
        // positive end, the last positive coarse sample and on back (half a voxel, doubling);
        // lacking a non-positive end, half a voxel past the distance the positive end samples
        // (a surface facing the ray lies within it); with both more than two voxels apart,
        // their midpoint.
        var a_t = 0.0;
        var a = TsdfSample(0.0, false);
        var have_a = false;
        var b_t = 0.0;
        var b = TsdfSample(0.0, false);
        var have_b = false;
        var probe_t = t;
        var back = min_step;
        for (var k = 0u; k < FINE_SAMPLES; k++) {
            let s = sample_tsdf(d, origin + dir * probe_t);
            if !s.valid {
                break;
            }
            if s.tsdf > 0.0 {
                a = s;
                a_t = probe_t;
                have_a = true;
            } else {
                b = s;
                b_t = probe_t;
                have_b = true;
            }
            if !have_a {
                if probe_t > prev_t {
                    probe_t = prev_t;
                } else if probe_t > t_start {
                    probe_t = max(probe_t - back, t_start);
                    back *= 2.0;
                } else {
                    break;
                }
            } else if !have_b {
                probe_t = a_t + min(a.tsdf * d.truncation_m + min_step, max_step);
                if !(probe_t < t_end) {
                    break;
                }
            } else if b_t - a_t > 4.0 * min_step {
                probe_t = 0.5 * (a_t + b_t);
            } else {
                break;
            }
        }
        if have_a && have_b {
            t_hit = a_t + (b_t - a_t) * a.tsdf / (a.tsdf - b.tsdf);
            hit = true;
            break;
        }
        // No bracket (an unobserved corner, a ray grazing a surface within the margin): march
        // on coarsely from the farthest positive sample, or past the candidate.
        prev_positive = have_a;
        prev_t = select(t, a_t, have_a);
        t = select(t, a_t, have_a) + min_step;
    }
    if !hit {
        write_miss(ix);
        return;
    }
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
