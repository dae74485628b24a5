// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/map/block_alloc.wgsl`. Pixels run one after another, so the
//! table's layout is one of the layouts the GPU may produce; compare tables by key set.

use crate::cpu::shared::{BRICK_SHIFT, MAP_COUNTER_HASH_FULL, MAP_COUNTER_OUT_OF_RANGE, MAP_COUNTER_SWAPPED_HITS, SWAPPED_BLOCK, back_project, block_key, is_valid_f32, probe_slot, transform_point, truncation_band_m, voxel_anchor};
use crate::kernels::block_alloc::{BlockAllocParams, CameraPose};
use crate::tsdf::VolumeDesc;

/// Twin of `MAP_MAX_BAND_BLOCKS`.
pub const MAP_MAX_BAND_BLOCKS: u32 = 32;

/// WGSL `sign`: -1, 0 or 1.
fn wgsl_sign(x: f32) -> f32 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Twin of `insert_block()` (invocations one after another: a compare-exchange never fails).
pub fn insert_block(d: &VolumeDesc, b: [u32; 3], block_table: &mut [u32], map_counters: &mut [u32]) {
    match probe_slot(block_table, d, b) {
        Some(s) if block_table[2 * s] == block_key(b) => {
            if block_table[2 * s + 1] == SWAPPED_BLOCK {
                map_counters[MAP_COUNTER_SWAPPED_HITS] += 1;
            }
        }
        Some(s) => block_table[2 * s] = block_key(b),
        None => map_counters[MAP_COUNTER_HASH_FULL] += 1,
    }
}

/// Inserts the blocks of every pixel's truncation band, as the kernel's invocations do.
pub fn block_alloc(params: &BlockAllocParams, pose: &CameraPose, depth_m: &[f32], block_table: &mut [u32], map_counters: &mut [u32]) {
    let k = &params.intrinsics;
    let d = &params.volume;
    if pose.enabled == 0 {
        return;
    }
    for gy in 0..k.height_px {
        for gx in 0..k.width_px {
            let z = depth_m[(gy * k.width_px + gx) as usize];
            if !is_valid_f32(z) {
                continue;
            }
            let ray = back_project(k, gx as f32, gy as f32, 1.0);
            let origin = [d.origin_x_m, d.origin_y_m, d.origin_z_m];
            let band = truncation_band_m(d, z);
            let near = transform_point(&pose.world_from_camera, ray.map(|c| c * (z - band).max(0.0)));
            let far = transform_point(&pose.world_from_camera, ray.map(|c| c * (z + band)));
            let block_m = (1u32 << BRICK_SHIFT) as f32 * d.voxel_size_m;
            let anchor_block = voxel_anchor(d).map(|v| (v >> BRICK_SHIFT) as f32);
            let a: [f32; 3] = std::array::from_fn(|i| (near[i] - origin[i]) / block_m);
            let b: [f32; 3] = std::array::from_fn(|i| (far[i] - origin[i]) / block_m);
            let dir: [f32; 3] = std::array::from_fn(|i| b[i] - a[i]);
            let mut cell = a.map(f32::floor);
            let last = b.map(f32::floor);
            let step = dir.map(wgsl_sign);
            let moving = dir.map(|c| c.abs() > 1e-12);
            let inv: [f32; 3] = std::array::from_fn(|i| 1.0 / if moving[i] { dir[i] } else { 1.0 });
            let mut t_next: [f32; 3] = std::array::from_fn(|i| if moving[i] { (cell[i] + step[i].max(0.0) - a[i]) * inv[i] } else { 1e30 });
            let t_delta: [f32; 3] = std::array::from_fn(|i| if moving[i] { inv[i].abs() } else { 1e30 });
            let n_blocks = [d.dim_x, d.dim_y, d.dim_z].map(|v| (v >> BRICK_SHIFT) as f32);
            let visits = ((last[0] - cell[0]).abs() + (last[1] - cell[1]).abs() + (last[2] - cell[2]).abs()) as u32 + 1;
            for _ in 0..visits.min(MAP_MAX_BAND_BLOCKS) {
                let in_box: [f32; 3] = std::array::from_fn(|i| cell[i] + anchor_block[i]);
                if (0..3).any(|i| in_box[i] < 0.0 || in_box[i] >= n_blocks[i]) {
                    map_counters[MAP_COUNTER_OUT_OF_RANGE] += 1;
                } else {
                    insert_block(d, in_box.map(|c| c as u32), block_table, map_counters);
                }
                let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] { 0 } else if t_next[1] <= t_next[2] { 1 } else { 2 };
                cell[axis] += step[axis];
                t_next[axis] += t_delta[axis];
            }
        }
    }
}
