// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/raycast_range.wgsl`.

use crate::cpu::shared::{BRICK_SHIFT, MAP_SPARSE, block_of_key, brick_dims, transform_point, voxel_anchor};
use crate::kernels::GpuIntrinsics;
use crate::kernels::raycast_range::{CameraPose, RaycastRangeParams};

/// Twin of `TILE_UNUSED`: the far word of a tile no ray reads (`raycast_hint_tiles`).
pub const TILE_UNUSED: u32 = u32::MAX;

/// Twin of `MIN_CLIP_DEPTH_M`.
pub const MIN_CLIP_DEPTH_M: f32 = 1e-3;

/// Widens each tile's (!bits(nearest z), bits(farthest z)) pair in `depth_range_tiles` by every
/// surface brick (of the dense box, or pool block of a sparse map), as the kernel's invocations
/// do (the atomicMax of each becomes a `max`).
pub fn raycast_range(params: &RaycastRangeParams, pose: &CameraPose, surface_bricks: &[u32], depth_range_tiles: &mut [u32], block_coords: &[u32]) {
    let d = &params.volume;
    let k = &params.intrinsics;
    let bricks = brick_dims(d);
    if pose.enabled == 0 {
        return;
    }
    let n_bricks = if d.kind == MAP_SPARSE { d.pool_blocks } else { bricks[0] * bricks[1] * bricks[2] };
    for brick in 0..n_bricks {
        if surface_bricks[brick as usize] == 0 {
            continue;
        }
        let b = if d.kind == MAP_SPARSE { block_of_key(block_coords[brick as usize]) } else { [brick % bricks[0], (brick / bricks[0]) % bricks[1], brick / (bricks[0] * bricks[1])] };
        let lo_voxel = b.map(|b| b << BRICK_SHIFT);
        let dims = [d.dim_x, d.dim_y, d.dim_z];
        let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
        let anchor = voxel_anchor(d).map(|a| a as i32);
        let lo: [f32; 3] = std::array::from_fn(|i| origin[i] + (lo_voxel[i] as i32 - anchor[i]) as f32 * d.voxel_size_m);
        let hi: [f32; 3] = std::array::from_fn(|i| origin[i] + ((lo_voxel[i] + (1 << BRICK_SHIFT)).min(dims[i]) as i32 - anchor[i]) as f32 * d.voxel_size_m);
        let Some(BrickFootprint { px_lo, px_hi, z_near_m, z_far_m }) = brick_footprint(k, &pose.camera_from_world, (params.min_depth_m, params.max_depth_m), lo, hi) else {
            continue;
        };
        let near_word = !z_near_m.to_bits();
        let far_word = z_far_m.to_bits();
        let (tx0, ty0) = (px_lo[0] as u32 / params.tile_px, px_lo[1] as u32 / params.tile_px);
        let (tx1, ty1) = (px_hi[0] as u32 / params.tile_px, px_hi[1] as u32 / params.tile_px);
        for ty in ty0..=ty1 {
            for tx in tx0..=tx1 {
                let t = (ty * params.tiles_x + tx) as usize;
                if depth_range_tiles[2 * t + 1] == TILE_UNUSED {
                    continue;
                }
                depth_range_tiles[2 * t] = depth_range_tiles[2 * t].max(near_word);
                depth_range_tiles[2 * t + 1] = depth_range_tiles[2 * t + 1].max(far_word);
            }
        }
    }
}

/// Where the box `lo`..`hi` (world metres) may be seen in an image with intrinsics `k` from
/// `camera_from_world` searching depths `depth_range_m`, as each kernel invocation finds it:
/// the pixel rectangle (first, last; clamped to the image) holding the projection of the box
/// clipped at the near plane, widened by a pixel, and the box's camera-depth interval clipped
/// to the near plane and the farthest depth; `None` when the box adds nothing to any tile.
pub fn brick_footprint(k: &GpuIntrinsics, camera_from_world: &[[f32; 4]; 4], depth_range_m: (f32, f32), lo: [f32; 3], hi: [f32; 3]) -> Option<BrickFootprint> {
    let (min_depth_m, max_depth_m) = depth_range_m;
    let mut corners = [[0.0f32; 3]; 8];
    let (mut z_near, mut z_far) = (1e30f32, -1e30f32);
    for corner in 0..8u32 {
        let pick = |axis: usize| if corner & (1 << axis) != 0 { hi[axis] } else { lo[axis] };
        let p = transform_point(camera_from_world, [pick(0), pick(1), pick(2)]);
        corners[corner as usize] = p;
        z_near = z_near.min(p[2]);
        z_far = z_far.max(p[2]);
    }
    if z_far < min_depth_m || z_near > max_depth_m {
        return None;
    }
    // The box clipped at the near plane: its corners in front and its edges' crossings.
    let z_clip = min_depth_m.max(MIN_CLIP_DEPTH_M);
    let (mut uv_min, mut uv_max) = ([1e30f32; 2], [-1e30f32; 2]);
    let mut include = |uv: [f32; 2]| {
        for i in 0..2 {
            uv_min[i] = uv_min[i].min(uv[i]);
            uv_max[i] = uv_max[i].max(uv[i]);
        }
    };
    for corner in 0..8usize {
        let p = corners[corner];
        if p[2] >= z_clip {
            include([k.fx_px * p[0] / p[2] + k.cx_px, k.fy_px * p[1] / p[2] + k.cy_px]);
        }
        for axis in 0..3 {
            let other = corner | (1 << axis);
            if other != corner {
                let q = corners[other];
                if (p[2] < z_clip) != (q[2] < z_clip) {
                    let t = (z_clip - p[2]) / (q[2] - p[2]);
                    let c: [f32; 3] = std::array::from_fn(|i| p[i] * (1.0 - t) + q[i] * t);
                    include([k.fx_px * c[0] / z_clip + k.cx_px, k.fy_px * c[1] / z_clip + k.cy_px]);
                }
            }
        }
    }
    if uv_min[0] > uv_max[0] {
        return None;
    }
    let px_lo = [0.0f32.max(uv_min[0].floor() - 1.0), 0.0f32.max(uv_min[1].floor() - 1.0)];
    let px_hi = [((k.width_px - 1) as f32).min(uv_max[0].ceil() + 1.0), ((k.height_px - 1) as f32).min(uv_max[1].ceil() + 1.0)];
    if px_lo[0] > px_hi[0] || px_lo[1] > px_hi[1] {
        return None;
    }
    Some(BrickFootprint { px_lo, px_hi, z_near_m: z_near.max(z_clip), z_far_m: z_far.min(max_depth_m) })
}

/// Where a brick may be seen ([`brick_footprint`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BrickFootprint {
    /// First pixel (x, y) of the rectangle, in the image.
    pub px_lo: [f32; 2],
    /// Last pixel (x, y) of the rectangle, in the image.
    pub px_hi: [f32; 2],
    /// Nearest camera depth, metres.
    pub z_near_m: f32,
    /// Farthest camera depth, metres.
    pub z_far_m: f32,
}

/// A tile's depth interval (nearest, farthest camera z, metres) from its two words, or `None`
/// when no surface brick covers it. Twin of the decoding in `raycast.wgsl`.
pub fn tile_depth_range(words: [u32; 2]) -> Option<(f32, f32)> {
    (words[1] != 0).then(|| (f32::from_bits(!words[0]), f32::from_bits(words[1])))
}
