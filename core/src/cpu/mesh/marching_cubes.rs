// SPDX-License-Identifier: MIT
//! Twins of `shaders/wgsl/shared/marching_cubes.wgsl` and `shaders/wgsl/shared/workgroup_scan.wgsl`,
//! same names and argument order (the WGSL's module-scope `tsdf_volume` and `mc_table` come
//! first here).

use crate::cpu::shared::{BRICK_SHIFT, MAP_SPARSE, MapRef, block_of_key, map_word, voxel_tsdf, voxel_weight};
use crate::kernels::mc_count::{MC_BLOCK_CELLS_X, MC_BLOCK_CELLS_Y, MC_BLOCK_CELLS_Z};
use crate::tsdf::VolumeDesc;

/// Twin of `SCAN_WG_SIZE`.
pub const SCAN_WG_SIZE: usize = 256;

/// Twin of `WgScan`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WgScan {
    /// Sum of the values of invocations `0..local_ix`.
    pub exclusive: u32,
    /// Sum over the whole workgroup.
    pub total: u32,
}

/// Twin of `wg_exclusive_scan()` for a whole workgroup at once: element `i` is what invocation
/// `i` gets back. The GPU sums in two levels, this serially; integer (wrapping u32) sums are
/// the same in any order.
pub fn wg_exclusive_scan(values: &[u32; SCAN_WG_SIZE]) -> [WgScan; SCAN_WG_SIZE] {
    let total = values.iter().fold(0u32, |a, &v| a.wrapping_add(v));
    let mut out = [WgScan::default(); SCAN_WG_SIZE];
    let mut running = 0u32;
    for i in 0..SCAN_WG_SIZE {
        out[i] = WgScan { exclusive: running, total };
        running = running.wrapping_add(values[i]);
    }
    out
}

/// Twin of `unit_u32()`.
pub fn unit_u32(axis: u32) -> [u32; 3] {
    [u32::from(axis == 0), u32::from(axis == 1), u32::from(axis == 2)]
}

/// Twin of `mc_block_origin()` (`block_coords`: a sparse map's key per pool block).
pub fn mc_block_origin(d: &VolumeDesc, block_coords: &[u32], block_ix: u32, n_blocks_x: u32, n_blocks_y: u32) -> [u32; 3] {
    if d.kind == MAP_SPARSE {
        let b = block_of_key(block_coords[(block_ix / 2) as usize]).map(|v| v << BRICK_SHIFT);
        return [b[0], b[1], b[2] + (block_ix % 2) * MC_BLOCK_CELLS_Z];
    }
    [block_ix % n_blocks_x * MC_BLOCK_CELLS_X, (block_ix / n_blocks_x) % n_blocks_y * MC_BLOCK_CELLS_Y, block_ix / (n_blocks_x * n_blocks_y) * MC_BLOCK_CELLS_Z]
}

/// Twin of `mc_local_cell()`.
pub fn mc_local_cell(local_ix: u32) -> [u32; 3] {
    [local_ix % MC_BLOCK_CELLS_X, (local_ix / MC_BLOCK_CELLS_X) % MC_BLOCK_CELLS_Y, local_ix / (MC_BLOCK_CELLS_X * MC_BLOCK_CELLS_Y)]
}

/// `a + b`, component-wise.
pub fn add3(a: [u32; 3], b: [u32; 3]) -> [u32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// Twin of `mc_cell_in_volume()`.
pub fn mc_cell_in_volume(d: &VolumeDesc, cell: [u32; 3]) -> bool {
    cell[0] + 1 < d.dim_x && cell[1] + 1 < d.dim_y && cell[2] + 1 < d.dim_z
}

/// Twin of `MC_NEGATIVE`.
pub const MC_NEGATIVE: u32 = 1;
/// Twin of `MC_UNOBSERVED`.
pub const MC_UNOBSERVED: u32 = 2;
/// Twin of `MC_NEAR`.
pub const MC_NEAR: u32 = 4;

/// Twin of `mc_voxel_flags()`.
pub fn mc_voxel_flags(word: u32) -> u32 {
    let t = voxel_tsdf(word);
    (if t < 0.0 { MC_NEGATIVE } else { 0 }) | (if voxel_weight(word) == 0 { MC_UNOBSERVED } else { 0 }) | (if t.abs() < 1.0 { MC_NEAR } else { 0 })
}

/// Twin of `mc_case_from_flags()`.
pub fn mc_case_from_flags(corner_flags: u32) -> u32 {
    if (corner_flags & 0x2222_2222) != 0 || (corner_flags & 0x4444_4444) == 0 {
        return 0;
    }
    let mut case_ix = 0;
    for corner in 0..8 {
        case_ix |= ((corner_flags >> (4 * corner)) & MC_NEGATIVE) << corner;
    }
    case_ix
}

/// Twin of `mc_cell_case()`.
pub fn mc_cell_case(map: MapRef<'_>, d: &VolumeDesc, cell: [u32; 3]) -> u32 {
    let mut corner_flags = 0;
    for corner in 0..8u32 {
        let word = map_word(map, d, cell[0] + (corner & 1), cell[1] + ((corner >> 1) & 1), cell[2] + ((corner >> 2) & 1));
        corner_flags |= mc_voxel_flags(word) << (4 * corner);
    }
    mc_case_from_flags(corner_flags)
}

/// Twin of `mc_case_triangle_count()`.
pub fn mc_case_triangle_count(mc_table: &[u32], case_ix: u32) -> u32 {
    (mc_table[(case_ix * 4) as usize] >> 12) & 7
}

/// Twin of `mc_case_edge()`.
pub fn mc_case_edge(mc_table: &[u32], case_ix: u32, slot: u32) -> u32 {
    (mc_table[(case_ix * 4 + 1 + slot / 8) as usize] >> (4 * (slot % 8))) & 15
}

/// Twin of `mc_edge_start_offset()`.
pub fn mc_edge_start_offset(edge: u32) -> [u32; 3] {
    let axis = edge / 4;
    let k = edge % 4;
    let a = unit_u32((axis + 1) % 3);
    let b = unit_u32((axis + 2) % 3);
    std::array::from_fn(|i| a[i] * (k & 1) + b[i] * (k >> 1))
}
