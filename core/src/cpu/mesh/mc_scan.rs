// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/mc_scan.wgsl`.

use crate::cpu::mesh::marching_cubes::{SCAN_WG_SIZE, wg_exclusive_scan};
use crate::kernels::mc_scan::{MC_FAILED_OUTPUT, MC_NO_BLOCK, McCounters, McScanParams};

/// Writes `block_offsets`, `active_blocks` (with its padding) and `counters` as the single
/// workgroup does.
pub fn mc_scan(params: &McScanParams, block_counts: &[u32], block_offsets: &mut [u32], active_blocks: &mut [u32], counters: &mut McCounters) {
    let n = params.n_blocks;
    let n_wg = SCAN_WG_SIZE as u32;
    let seg = n.div_ceil(n_wg);
    let range = |local_ix: u32| {
        let begin = (local_ix * seg).min(n);
        begin..(begin + seg).min(n)
    };
    let mut n_triangles = [0u32; SCAN_WG_SIZE];
    let mut n_active = [0u32; SCAN_WG_SIZE];
    for local_ix in 0..n_wg {
        for i in range(local_ix) {
            let c = block_counts[i as usize];
            n_triangles[local_ix as usize] = n_triangles[local_ix as usize].wrapping_add(c);
            n_active[local_ix as usize] += u32::from(c != 0);
        }
    }
    let triangle_scan = wg_exclusive_scan(&n_triangles);
    let active_scan = wg_exclusive_scan(&n_active);
    for local_ix in 0..n_wg {
        let mut running = triangle_scan[local_ix as usize].exclusive;
        let mut slot = active_scan[local_ix as usize].exclusive;
        for i in range(local_ix) {
            let c = block_counts[i as usize];
            block_offsets[i as usize] = running;
            running = running.wrapping_add(c);
            if c != 0 {
                active_blocks[slot as usize] = i;
                slot += 1;
            }
        }
    }
    let (total, total_active) = (triangle_scan[0].total, active_scan[0].total);
    let wg_y = total_active.div_ceil(params.max_workgroups_per_dimension).max(1);
    let wg_x = total_active.div_ceil(wg_y);
    for i in total_active..wg_x * wg_y {
        active_blocks[i as usize] = MC_NO_BLOCK;
    }
    *counters = McCounters {
        n_triangles: total,
        capacity_triangles: params.capacity_triangles,
        failed: if total > params.capacity_triangles { MC_FAILED_OUTPUT } else { 0 },
        n_active_blocks: total_active,
        generate_workgroups_x: wg_x,
        generate_workgroups_y: wg_y,
        generate_workgroups_z: 1,
        _pad0: 0,
    };
}
