// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/raycast_range.wgsl`.

use crate::cpu::shared::{BRICK_SHIFT, brick_dims, transform_point};
use crate::kernels::raycast_range::{CameraPose, RaycastRangeParams};

/// Widens each tile's (!bits(nearest z), bits(farthest z)) pair in `depth_range_tiles` by every
/// surface brick, as the kernel's invocations do (the atomicMax of each becomes a `max`).
pub fn raycast_range(params: &RaycastRangeParams, pose: &CameraPose, surface_bricks: &[u32], depth_range_tiles: &mut [u32]) {
    let d = &params.volume;
    let k = &params.intrinsics;
    let bricks = brick_dims(d);
    if pose.enabled == 0 {
        return;
    }
    for bz in 0..bricks[2] {
        for by in 0..bricks[1] {
            for bx in 0..bricks[0] {
                if surface_bricks[(bx + bricks[0] * (by + bricks[1] * bz)) as usize] == 0 {
                    continue;
                }
                let lo_voxel = [bx, by, bz].map(|b| b << BRICK_SHIFT);
                let dims = [d.dim_x, d.dim_y, d.dim_z];
                let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
                let lo: [f32; 3] = std::array::from_fn(|i| origin[i] + lo_voxel[i] as f32 * d.voxel_size_m);
                let hi: [f32; 3] = std::array::from_fn(|i| origin[i] + (lo_voxel[i] + (1 << BRICK_SHIFT)).min(dims[i]) as f32 * d.voxel_size_m);
                let (mut z_near, mut z_far) = (1e30f32, -1e30f32);
                let (mut u_min, mut u_max, mut v_min, mut v_max) = (1e30f32, -1e30f32, 1e30f32, -1e30f32);
                for corner in 0..8u32 {
                    let pick = |axis: usize| if corner & (1 << axis) != 0 { hi[axis] } else { lo[axis] };
                    let p = transform_point(&pose.camera_from_world, [pick(0), pick(1), pick(2)]);
                    z_near = z_near.min(p[2]);
                    z_far = z_far.max(p[2]);
                    if p[2] > 0.0 {
                        let u = k.fx_px * p[0] / p[2] + k.cx_px;
                        let v = k.fy_px * p[1] / p[2] + k.cy_px;
                        u_min = u_min.min(u);
                        u_max = u_max.max(u);
                        v_min = v_min.min(v);
                        v_max = v_max.max(v);
                    }
                }
                if z_far < params.min_depth_m || z_near > params.max_depth_m {
                    continue;
                }
                let mut px_lo = [0.0f32, 0.0];
                let mut px_hi = [(k.width_px - 1) as f32, (k.height_px - 1) as f32];
                if z_near >= params.min_depth_m && z_near > 0.0 {
                    px_lo = [px_lo[0].max(u_min.floor() - 1.0), px_lo[1].max(v_min.floor() - 1.0)];
                    px_hi = [px_hi[0].min(u_max.ceil() + 1.0), px_hi[1].min(v_max.ceil() + 1.0)];
                    if px_lo[0] > px_hi[0] || px_lo[1] > px_hi[1] {
                        continue;
                    }
                } else {
                    z_near = params.min_depth_m.max(0.0);
                }
                let near_word = !z_near.to_bits();
                let far_word = z_far.min(params.max_depth_m).to_bits();
                let (tx0, ty0) = (px_lo[0] as u32 / params.tile_px, px_lo[1] as u32 / params.tile_px);
                let (tx1, ty1) = (px_hi[0] as u32 / params.tile_px, px_hi[1] as u32 / params.tile_px);
                for ty in ty0..=ty1 {
                    for tx in tx0..=tx1 {
                        let t = (ty * params.tiles_x + tx) as usize;
                        depth_range_tiles[2 * t] = depth_range_tiles[2 * t].max(near_word);
                        depth_range_tiles[2 * t + 1] = depth_range_tiles[2 * t + 1].max(far_word);
                    }
                }
            }
        }
    }
}

/// A tile's depth interval (nearest, farthest camera z, metres) from its two words, or `None`
/// when no surface brick covers it. Twin of the decoding in `raycast.wgsl`.
pub fn tile_depth_range(words: [u32; 2]) -> Option<(f32, f32)> {
    (words[1] != 0).then(|| (f32::from_bits(!words[0]), f32::from_bits(words[1])))
}
