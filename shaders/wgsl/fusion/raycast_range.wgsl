// SPDX-License-Identifier: MIT
//! Each invocation projects one brick of 8³ voxels into the image a raycast is about to render
//! (InfiniTAM's "rendering range" idea): brick i of the dense box (x fastest), or pool block i
//! of a sparse map (at the coordinates `block_coords` holds). A brick that integration marked as possibly holding a surface widens the camera-depth interval of
//! every image tile its box covers, so that rays search only where some surface may lie and
//! tiles no such brick covers are misses without a single step. The box of the brick's voxel
//! cells (every point whose nearest voxel is in the brick) is clipped at the near plane
//! z = `min_depth_m`: its depth interval is [max(nearest corner z, min_depth_m), farthest corner
//! z] and its pixels lie within the bounding rectangle, widened by one pixel, of the projections
//! of the clipped box's vertices (the corners in front of the plane and the points where its
//! edges cross it), so a box beside or around the camera covers only the tiles it can be seen
//! in. Bricks wholly nearer than `min_depth_m` or farther than `max_depth_m`, or outside the
//! image, add nothing.
//!
//! Tiles hold two words, both combined with atomicMax from a cleared (zero) buffer so that no
//! float atomics are needed: !bits(nearest z) and bits(farthest z) (positive floats order as
//! their bits). A tile whose farthest word is 0 meets no surface brick; one marked TILE_UNUSED
//! (every ray in it has a depth hint, `raycast_hint_tiles`) is left as it is. Nothing is written when
//! the pose is disabled (the raycast writes nothing either).
#import camera
#import camera_pose
#import map

// A tile's far word when no ray of the tile reads it (set by `raycast_hint_tiles`).
const TILE_UNUSED: u32 = 0xffffffffu;

// The nearest plane a box is clipped at when the raycast's own nearest depth is 0, metres.
const MIN_CLIP_DEPTH_M: f32 = 1e-3;

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
@group(0) @binding(1) var<uniform> pose: CameraPose;
// One word per brick, non-zero where a surface may lie.
@group(0) @binding(2) var<storage, read> surface_bricks: array<u32>;
// Out (cleared to 0 before): per tile, !bits(nearest z) then bits(farthest z).
@group(0) @binding(3) var<storage, read_write> depth_range_tiles: array<atomic<u32>>;
// The key of each pool block of a sparse map (map.wgsl); one placeholder word for a dense map.
@group(0) @binding(4) var<storage, read> block_coords: array<u32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let d = params.volume;
    let bricks = brick_dims(d);
    let brick = gid.x;
    var n_bricks = bricks.x * bricks.y * bricks.z;
    if d.kind == MAP_SPARSE {
        n_bricks = d.pool_blocks;
    }
    if brick >= n_bricks || pose.enabled == 0u {
        return;
    }
    if surface_bricks[brick] == 0u {
        return;
    }
    let k = params.intrinsics;
    var b = vec3<u32>(brick % bricks.x, (brick / bricks.x) % bricks.y, brick / (bricks.x * bricks.y));
    if d.kind == MAP_SPARSE {
        b = block_of_key(block_coords[brick]);
    }
    let lo_voxel = b << vec3<u32>(BRICK_SHIFT);
    let hi_voxel = min(lo_voxel + vec3<u32>(1u << BRICK_SHIFT), vec3<u32>(d.dim_x, d.dim_y, d.dim_z));
    let origin = vec3<f32>(d.origin_x_m, d.origin_y_m, d.origin_z_m);
    let anchor = vec3<i32>(voxel_anchor(d));
    let lo = origin + vec3<f32>(vec3<i32>(lo_voxel) - anchor) * d.voxel_size_m;
    let hi = origin + vec3<f32>(vec3<i32>(hi_voxel) - anchor) * d.voxel_size_m;
    // The box's corners in the camera frame.
    var corners: array<vec3<f32>, 8>;
    var z_near = 1e30;
    var z_far = -1e30;
    for (var corner = 0u; corner < 8u; corner++) {
        let p_world = select(lo, hi, vec3<bool>((corner & 1u) != 0u, (corner & 2u) != 0u, (corner & 4u) != 0u));
        let p = (pose.camera_from_world * vec4<f32>(p_world, 1.0)).xyz;
        corners[corner] = p;
        z_near = min(z_near, p.z);
        z_far = max(z_far, p.z);
    }
    if z_far < params.min_depth_m || z_near > params.max_depth_m {
        return;
    }
    // The part of the box in front of the near plane z = z_clip projects into the bounding
    // rectangle of that part's vertices: the corners in front of the plane and the points where
    // the box's 12 edges cross it.
    let z_clip = max(params.min_depth_m, MIN_CLIP_DEPTH_M);
    var uv_min = vec2<f32>(1e30);
    var uv_max = vec2<f32>(-1e30);
    for (var corner = 0u; corner < 8u; corner++) {
        let p = corners[corner];
        if p.z >= z_clip {
            let uv = vec2<f32>(k.fx_px * p.x / p.z + k.cx_px, k.fy_px * p.y / p.z + k.cy_px);
            uv_min = min(uv_min, uv);
            uv_max = max(uv_max, uv);
        }
        for (var axis = 0u; axis < 3u; axis++) {
            let other = corner | (1u << axis);
            if other != corner {
                let q = corners[other];
                if (p.z < z_clip) != (q.z < z_clip) {
                    let c = mix(p, q, (z_clip - p.z) / (q.z - p.z));
                    let uv = vec2<f32>(k.fx_px * c.x / z_clip + k.cx_px, k.fy_px * c.y / z_clip + k.cy_px);
                    uv_min = min(uv_min, uv);
                    uv_max = max(uv_max, uv);
                }
            }
        }
    }
    if uv_min.x > uv_max.x {
        return;
    }
    let px_lo = max(vec2<f32>(0.0), floor(uv_min) - vec2<f32>(1.0));
    let px_hi = min(vec2<f32>(f32(k.width_px - 1u), f32(k.height_px - 1u)), ceil(uv_max) + vec2<f32>(1.0));
    if px_lo.x > px_hi.x || px_lo.y > px_hi.y {
        return;
    }
    z_near = max(z_near, z_clip);
    let near_word = ~bitcast<u32>(z_near);
    let far_word = bitcast<u32>(min(z_far, params.max_depth_m));
    let t_lo = vec2<u32>(px_lo) / params.tile_px;
    let t_hi = vec2<u32>(px_hi) / params.tile_px;
    for (var ty = t_lo.y; ty <= t_hi.y; ty++) {
        for (var tx = t_lo.x; tx <= t_hi.x; tx++) {
            let t = ty * params.tiles_x + tx;
            // A tile `raycast_hint_tiles` marked (all its rays have a hint) needs no interval.
            if atomicLoad(&depth_range_tiles[2u * t + 1u]) == TILE_UNUSED {
                continue;
            }
            atomicMax(&depth_range_tiles[2u * t], near_word);
            atomicMax(&depth_range_tiles[2u * t + 1u], far_word);
        }
    }
}
