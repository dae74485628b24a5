// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/mc_count.wgsl`.

use crate::cpu::mesh::marching_cubes::{mc_block_origin, mc_case_from_flags, mc_case_triangle_count, mc_voxel_flags};
use crate::cpu::shared::{MapRef, map_word};
use crate::kernels::mc_count::{MC_BLOCK_CELLS_X, MC_BLOCK_CELLS_Y, MC_BLOCK_CELLS_Z, McCountParams};

/// Writes `block_counts[block]` for every block, as one invocation per block does (rows along
/// x, reusing each x face's voxel flags).
pub fn mc_count(params: &McCountParams, tsdf_volume: &[u32], mc_table: &[u32], block_counts: &mut [u32], block_table: &[u32], block_coords: &[u32]) {
    let d = &params.volume;
    let map = MapRef { tsdf_volume, block_table };
    let flags = |x: u32, y: u32, z: u32| mc_voxel_flags(map_word(map, d, x, y, z));
    for block_ix in 0..params.n_blocks {
        let origin = mc_block_origin(d, block_coords, block_ix, params.n_blocks_x, params.n_blocks_y);
        let end = [
            (origin[0] + MC_BLOCK_CELLS_X).min(d.dim_x - 1),
            (origin[1] + MC_BLOCK_CELLS_Y).min(d.dim_y - 1),
            (origin[2] + MC_BLOCK_CELLS_Z).min(d.dim_z - 1),
        ];
        let mut n_triangles = 0u32;
        for z in origin[2]..end[2] {
            for y in origin[1]..end[1] {
                let mut face = 0u32;
                for k in 0..4u32 {
                    face |= flags(origin[0], y + (k & 1), z + (k >> 1)) << (4 * k);
                }
                for x in origin[0]..end[0] {
                    let mut next = 0u32;
                    for k in 0..4u32 {
                        next |= flags(x + 1, y + (k & 1), z + (k >> 1)) << (4 * k);
                    }
                    let mut corner_flags = 0u32;
                    for k in 0..4u32 {
                        corner_flags |= ((face >> (4 * k)) & 15) << (8 * k);
                        corner_flags |= ((next >> (4 * k)) & 15) << (8 * k + 4);
                    }
                    n_triangles += mc_case_triangle_count(mc_table, mc_case_from_flags(corner_flags));
                    face = next;
                }
            }
        }
        block_counts[block_ix as usize] = n_triangles;
    }
}
