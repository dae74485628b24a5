// SPDX-License-Identifier: MIT
//! Each invocation tests one allocated block of a sparse map (a block on the free list holds
//! EMPTY_KEY and is skipped) against the camera's view and this frame's depth, and
//! appends it to `visible_blocks` (atomicAdd on MAP_COUNTER_VISIBLE; the list has a slot for
//! every pool block, so it cannot overflow) when integration may change one of its voxels: the
//! block's box, bounded by its 8 corners in the camera frame, reaches in front of the camera,
//! its projection (the bounding rectangle of the corners' projections) meets the image, and
//! its nearest point is not behind the deepest depth of the pixels its voxels round to (the
//! `depth_tile_max` tiles that rectangle covers) by more than that depth's truncation band. A
//! voxel takes an update only where depth - z >= -band(depth), and depth + band(depth) grows
//! with depth, so a block beyond that bound (hidden behind the surface seen there, or over
//! pixels without depth) keeps every voxel as it was: listing only the rest changes no voxel
//! (tests/kernels/map/block_visible.rs checks it). A box that straddles the camera plane counts
//! as visible. The visible list's order depends on the order invocations run; its set does not.
//! Nothing is listed when the pose is disabled.
#import camera
#import camera_pose
#import map

struct BlockVisibleParams {
    // The sparse map.
    volume: VolumeDesc,
    // Intrinsics of the depth image.
    intrinsics: Intrinsics,
    // The depth tiles (`depth_tile_max`): edge in pixels, and tiles along x and y.
    tile_px: u32,
    tiles_x: u32,
    tiles_y: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: BlockVisibleParams;
// The pose the depth is fused at.
@group(0) @binding(1) var<uniform> pose: CameraPose;
// The key of each pool block in use.
@group(0) @binding(2) var<storage, read> block_coords: array<u32>;
// The map's counters (map.wgsl).
@group(0) @binding(3) var<storage, read_write> map_counters: array<atomic<u32>>;
// Out: the pool indices of the visible blocks, in any order (MAP_COUNTER_VISIBLE of them).
@group(0) @binding(4) var<storage, read_write> visible_blocks: array<u32>;
// The largest valid depth of each tile of the depth fused, metres (NO_DEPTH_TILE: none).
@group(0) @binding(5) var<storage, read> tile_max_m: array<f32>;

// Slack on the occlusion bound, metres, for the f32 rounding of the corners' and the voxel
// centres' transforms (both within a micrometre at room scale).
const OCCLUSION_SLACK_M: f32 = 1e-3;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let block = gid.x;
    if block >= atomicLoad(&map_counters[MAP_COUNTER_BLOCKS_USED]) || pose.enabled == 0u {
        return;
    }
    let key = block_coords[block];
    if key == EMPTY_KEY {
        // On the free list.
        return;
    }
    let d = params.volume;
    let k = params.intrinsics;
    let edge_m = f32(1u << BRICK_SHIFT) * d.voxel_size_m;
    let lo_voxel = vec3<i32>(block_of_key(key) << vec3<u32>(BRICK_SHIFT)) - vec3<i32>(voxel_anchor(d));
    let lo = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m) + vec3<f32>(lo_voxel) * d.voxel_size_m;
    var z_near = 1e30;
    var z_far = -1e30;
    var uv_min = vec2<f32>(1e30);
    var uv_max = vec2<f32>(-1e30);
    for (var corner = 0u; corner < 8u; corner++) {
        let offset = vec3<f32>(f32(corner & 1u), f32((corner >> 1u) & 1u), f32(corner >> 2u)) * edge_m;
        let p = (pose.camera_from_world * vec4<f32>(lo + offset, 1.0)).xyz;
        z_near = min(z_near, p.z);
        z_far = max(z_far, p.z);
        if p.z > 0.0 {
            let uv = vec2<f32>(k.fx_px * p.x / p.z + k.cx_px, k.fy_px * p.y / p.z + k.cy_px);
            uv_min = min(uv_min, uv);
            uv_max = max(uv_max, uv);
        }
    }
    if z_far <= 0.0 {
        return;
    }
    if z_near > 0.0 {
        let size = vec2<f32>(f32(k.width_px), f32(k.height_px));
        // Voxel centres inside the box project inside the rectangle and round to the nearest
        // pixel (as integration does): the pixels floor(uv + 0.5), clamped to the image.
        if any(uv_max < vec2<f32>(-0.5)) || any(uv_min >= size - vec2<f32>(0.5)) {
            return;
        }
        let px_lo = vec2<u32>(clamp(floor(uv_min + 0.5), vec2<f32>(0.0), size - 1.0));
        let px_hi = vec2<u32>(clamp(floor(uv_max + 0.5), vec2<f32>(0.0), size - 1.0));
        let t_lo = px_lo / params.tile_px;
        let t_hi = px_hi / params.tile_px;
        var deepest = NO_DEPTH_TILE;
        for (var ty = t_lo.y; ty <= t_hi.y; ty++) {
            for (var tx = t_lo.x; tx <= t_hi.x; tx++) {
                deepest = max(deepest, tile_max_m[ty * params.tiles_x + tx]);
            }
        }
        if deepest == NO_DEPTH_TILE || z_near > deepest + truncation_band_m(d, deepest) + OCCLUSION_SLACK_M {
            return;
        }
    }
    visible_blocks[atomicAdd(&map_counters[MAP_COUNTER_VISIBLE], 1u)] = block;
}
