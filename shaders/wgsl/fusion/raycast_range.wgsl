// SPDX-License-Identifier: MIT
//! Each invocation projects one brick of 8³ voxels into the image a raycast is about to render
//! (InfiniTAM's "rendering range" idea, over the dense store's surface bricks): a brick that
//! `tsdf_integrate` marked as possibly holding a surface widens the camera-depth interval of
//! every image tile its box covers, so that rays search only where some surface may lie and
//! tiles no such brick covers are misses without a single step. The box of the brick's voxel
//! cells (every point whose nearest voxel is in the brick) is bounded by its 8 corners in the
//! camera frame: z within [min, max] of theirs, pixels within the bounding rectangle of their
//! projections widened by one pixel; a box reaching in front of `min_depth_m` covers the whole
//! image from `min_depth_m` on (its projection is unbounded there). Bricks wholly nearer than
//! `min_depth_m` or farther than `max_depth_m`, or outside the image, add nothing.
//!
//! Tiles hold two words, both combined with atomicMax from a cleared (zero) buffer so that no
//! float atomics are needed: !bits(nearest z) and bits(farthest z) (positive floats order as
//! their bits). A tile whose farthest word is 0 meets no surface brick. Nothing is written when
//! the pose is disabled (the raycast writes nothing either).
#import camera
#import camera_pose
#import tsdf

struct RaycastRangeParams {
    // The volume.
    volume: VolumeDesc,
    // Intrinsics of the image the raycast renders.
    intrinsics: Intrinsics,
    // Pixels along each edge of a tile.
    tile_px: u32,
    // Tiles along x (ceil(width / tile_px)).
    tiles_x: u32,
    // Tiles along y (ceil(height / tile_px)).
    tiles_y: u32,
    // Nearest depth the raycast searches, metres.
    min_depth_m: f32,
    // Farthest depth the raycast searches, metres.
    max_depth_m: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: RaycastRangeParams;
// The pose the raycast renders from.
@group(0) @binding(1) var<storage, read> pose: CameraPose;
// One word per brick, non-zero where a surface may lie.
@group(0) @binding(2) var<storage, read> surface_bricks: array<u32>;
// Out (cleared to 0 before): per tile, !bits(nearest z) then bits(farthest z).
@group(0) @binding(3) var<storage, read_write> depth_range_tiles: array<atomic<u32>>;

@compute @workgroup_size(4, 4, 4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.volume;
    let bricks = brick_dims(d);
    if any(gid >= bricks) || pose.enabled == 0u {
        return;
    }
    if surface_bricks[gid.x + bricks.x * (gid.y + bricks.y * gid.z)] == 0u {
        return;
    }
    let k = params.intrinsics;
    let lo_voxel = gid << vec3<u32>(BRICK_SHIFT);
    let hi_voxel = min(lo_voxel + vec3<u32>(1u << BRICK_SHIFT), vec3<u32>(d.dim_x, d.dim_y, d.dim_z));
    let origin = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m);
    let lo = origin + vec3<f32>(lo_voxel) * d.voxel_size_m;
    let hi = origin + vec3<f32>(hi_voxel) * d.voxel_size_m;
    var z_near = 1e30;
    var z_far = -1e30;
    var u_min = 1e30;
    var u_max = -1e30;
    var v_min = 1e30;
    var v_max = -1e30;
    for (var corner = 0u; corner < 8u; corner++) {
        let p_world = select(lo, hi, vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u));
        let p = (pose.camera_from_world * vec4<f32>(p_world, 1.0)).xyz;
        z_near = min(z_near, p.z);
        z_far = max(z_far, p.z);
        if p.z > 0.0 {
            let u = k.fx_px * p.x / p.z + k.cx_px;
            let v = k.fy_px * p.y / p.z + k.cy_px;
            u_min = min(u_min, u);
            u_max = max(u_max, u);
            v_min = min(v_min, v);
            v_max = max(v_max, v);
        }
    }
    if z_far < params.min_depth_m || z_near > params.max_depth_m {
        return;
    }
    var px_lo = vec2<f32>(0.0);
    var px_hi = vec2<f32>(f32(k.width_px - 1u), f32(k.height_px - 1u));
    if z_near >= params.min_depth_m && z_near > 0.0 {
        px_lo = max(px_lo, floor(vec2<f32>(u_min, v_min)) - vec2<f32>(1.0));
        px_hi = min(px_hi, ceil(vec2<f32>(u_max, v_max)) + vec2<f32>(1.0));
        if px_lo.x > px_hi.x || px_lo.y > px_hi.y {
            return;
        }
    } else {
        z_near = max(params.min_depth_m, 0.0);
    }
    let near_word = ~bitcast<u32>(z_near);
    let far_word = bitcast<u32>(min(z_far, params.max_depth_m));
    let t_lo = vec2<u32>(px_lo) / params.tile_px;
    let t_hi = vec2<u32>(px_hi) / params.tile_px;
    for (var ty = t_lo.y; ty <= t_hi.y; ty++) {
        for (var tx = t_lo.x; tx <= t_hi.x; tx++) {
            let t = ty * params.tiles_x + tx;
            atomicMax(&depth_range_tiles[2u * t], near_word);
            atomicMax(&depth_range_tiles[2u * t + 1u], far_word);
        }
    }
}
