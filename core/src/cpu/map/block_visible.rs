// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_visible.wgsl`. Blocks are listed in pool order; the
//! GPU lists them in any order: compare as sets.

use crate::cpu::shared::{BRICK_SHIFT, EMPTY_KEY, MAP_COUNTER_BLOCKS_USED, MAP_COUNTER_VISIBLE, NO_DEPTH_TILE, block_of_key, transform_point, truncation_band_m, voxel_anchor};
use crate::kernels::block_visible::{BlockVisibleParams, CameraPose};

/// Twin of `OCCLUSION_SLACK_M`.
const OCCLUSION_SLACK_M: f32 = 1e-3;

/// Twin of one invocation: whether pool block `block` (at `key`) may take an update, given the
/// depth tiles' largest depths `tile_max_m`.
pub fn block_is_visible(params: &BlockVisibleParams, pose: &CameraPose, key: u32, tile_max_m: &[f32]) -> bool {
    let d = &params.volume;
    let k = &params.intrinsics;
    let edge_m = (1u32 << BRICK_SHIFT) as f32 * d.voxel_size_m;
    let anchor = voxel_anchor(d);
    let b = block_of_key(key);
    let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
    let lo: [f32; 3] = std::array::from_fn(|i| origin[i] + ((b[i] << BRICK_SHIFT) as i32 - anchor[i] as i32) as f32 * d.voxel_size_m);
    let (mut z_near, mut z_far) = (1e30f32, -1e30f32);
    let (mut uv_min, mut uv_max) = ([1e30f32; 2], [-1e30f32; 2]);
    for corner in 0..8u32 {
        let offset = [(corner & 1) as f32, ((corner >> 1) & 1) as f32, (corner >> 2) as f32].map(|c| c * edge_m);
        let p = transform_point(&pose.camera_from_world, std::array::from_fn(|i| lo[i] + offset[i]));
        z_near = z_near.min(p[2]);
        z_far = z_far.max(p[2]);
        if p[2] > 0.0 {
            let uv = [k.fx_px * p[0] / p[2] + k.cx_px, k.fy_px * p[1] / p[2] + k.cy_px];
            for i in 0..2 {
                uv_min[i] = uv_min[i].min(uv[i]);
                uv_max[i] = uv_max[i].max(uv[i]);
            }
        }
    }
    if z_far <= 0.0 {
        return false;
    }
    if z_near > 0.0 {
        let size = [k.width_px as f32, k.height_px as f32];
        if (0..2).any(|i| uv_max[i] < -0.5 || uv_min[i] >= size[i] - 0.5) {
            return false;
        }
        let px_lo: [u32; 2] = std::array::from_fn(|i| (uv_min[i] + 0.5).floor().clamp(0.0, size[i] - 1.0) as u32);
        let px_hi: [u32; 2] = std::array::from_fn(|i| (uv_max[i] + 0.5).floor().clamp(0.0, size[i] - 1.0) as u32);
        let mut deepest = NO_DEPTH_TILE;
        for ty in px_lo[1] / params.tile_px..=px_hi[1] / params.tile_px {
            for tx in px_lo[0] / params.tile_px..=px_hi[0] / params.tile_px {
                deepest = deepest.max(tile_max_m[(ty * params.tiles_x + tx) as usize]);
            }
        }
        if deepest == NO_DEPTH_TILE || z_near > deepest + truncation_band_m(d, deepest) + OCCLUSION_SLACK_M {
            return false;
        }
    }
    true
}

/// Lists the visible blocks, as the kernel's invocations do.
pub fn block_visible(params: &BlockVisibleParams, pose: &CameraPose, block_coords: &[u32], map_counters: &mut [u32], visible_blocks: &mut [u32], tile_max_m: &[f32]) {
    if pose.enabled == 0 {
        return;
    }
    for block in 0..map_counters[MAP_COUNTER_BLOCKS_USED] {
        let key = block_coords[block as usize];
        if key != EMPTY_KEY && block_is_visible(params, pose, key, tile_max_m) {
            visible_blocks[map_counters[MAP_COUNTER_VISIBLE] as usize] = block;
            map_counters[MAP_COUNTER_VISIBLE] += 1;
        }
    }
}
