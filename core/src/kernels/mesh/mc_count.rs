// SPDX-License-Identifier: MIT
//! Host side of `mc_count`: triangles per block of marching-cubes cells (pass 1 of 3).
//!
//! Kernel: `shaders/wgsl/mesh/mc_count.wgsl`; CPU reference: [`fn@crate::cpu::mc_count`].
//! The driver is [`crate::mesh::extract_mesh`].

use super::McCountParams;
use crate::tsdf::VolumeDesc;
use crate::{Error, Gpu, Result};

/// Cells per block along x, WGSL `MC_BLOCK_CELLS_X`.
pub const MC_BLOCK_CELLS_X: u32 = 8;
/// Cells per block along y, WGSL `MC_BLOCK_CELLS_Y`.
pub const MC_BLOCK_CELLS_Y: u32 = 8;
/// Cells per block along z, WGSL `MC_BLOCK_CELLS_Z`.
pub const MC_BLOCK_CELLS_Z: u32 = 4;
/// Cells per block, WGSL `MC_CELLS_PER_BLOCK`; equals the reflected workgroup size of
/// `mc_generate` (one invocation per cell; checked by the kernel tests).
pub const MC_CELLS_PER_BLOCK: u32 = MC_BLOCK_CELLS_X * MC_BLOCK_CELLS_Y * MC_BLOCK_CELLS_Z;

impl McCountParams {
    /// Parameters for counting the cells of `grid` in `volume`.
    pub fn new(volume: VolumeDesc, grid: McGrid) -> Self {
        Self { volume, n_blocks_x: grid.n_blocks_x, n_blocks_y: grid.n_blocks_y, n_blocks: grid.n_blocks, _pad0: 0 }
    }
}

/// Cells and blocks of a volume: a cell is the cube between 8 voxel centres, a block a brick of
/// `MC_BLOCK_CELLS_X x MC_BLOCK_CELLS_Y x MC_BLOCK_CELLS_Z` cells (blocks at the far faces
/// overhang the volume).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct McGrid {
    /// Cells along x, y, z: `dim - 1`.
    pub cells: [u32; 3],
    /// Blocks along x.
    pub n_blocks_x: u32,
    /// Blocks along y.
    pub n_blocks_y: u32,
    /// Blocks along z.
    pub n_blocks_z: u32,
    /// All blocks.
    pub n_blocks: u32,
}

impl McGrid {
    /// The grid of `volume`, or an error when it has fewer than 2 voxels along an axis or so
    /// many cells that a triangle count (at most 5 per cell) could overflow a u32.
    pub fn new(volume: &VolumeDesc) -> Result<Self> {
        let dims = [volume.dim_x, volume.dim_y, volume.dim_z];
        if dims.iter().any(|&d| d < 2) {
            return Err(Error::InvalidConfig(format!("marching cubes needs at least 2 voxels per axis, volume is {dims:?}")));
        }
        let cells = dims.map(|d| d - 1);
        let (n_blocks_x, n_blocks_y, n_blocks_z) = (cells[0].div_ceil(MC_BLOCK_CELLS_X), cells[1].div_ceil(MC_BLOCK_CELLS_Y), cells[2].div_ceil(MC_BLOCK_CELLS_Z));
        let n_blocks = u64::from(n_blocks_x) * u64::from(n_blocks_y) * u64::from(n_blocks_z);
        // Triangle indices and counts are u32: bound the worst case of 5 per cell of every block.
        let max_blocks = u64::from(u32::MAX) / (crate::mesh::mc_table::MAX_TRIANGLES_PER_CELL as u64 * u64::from(MC_CELLS_PER_BLOCK));
        if n_blocks > max_blocks {
            return Err(Error::InvalidConfig(format!("marching cubes over {dims:?} voxels needs {n_blocks} blocks, at most {max_blocks} (triangle indices are u32)")));
        }
        Ok(Self { cells, n_blocks_x, n_blocks_y, n_blocks_z, n_blocks: n_blocks as u32 })
    }

    /// The grid marching cubes runs over in `volume`: the dense box's blocks of cells, or for a
    /// sparse map two blocks of 8 x 8 x 4 cells per pool block (an unused one is empty).
    pub fn for_volume(volume: &VolumeDesc) -> Result<Self> {
        if volume.kind != crate::cpu::shared::MAP_SPARSE {
            return Self::new(volume);
        }
        let n_blocks = 2 * volume.pool_blocks;
        Ok(Self { cells: [volume.dim_x - 1, volume.dim_y - 1, volume.dim_z - 1], n_blocks_x: 1, n_blocks_y: 1, n_blocks_z: n_blocks, n_blocks })
    }

        /// Cells, `(dim_x - 1) * (dim_y - 1) * (dim_z - 1)`.
    pub fn n_cells(&self) -> u64 {
        self.cells.iter().map(|&c| u64::from(c)).product()
    }

    /// Workgroups of `mc_count` (one invocation per block, `MC_COUNT_WG_SIZE` per workgroup).
    pub fn count_workgroups(&self, max_per_dimension: u32) -> [u32; 3] {
        workgroups_2d(self.n_blocks.div_ceil(MC_COUNT_WG_SIZE), max_per_dimension)
    }

    /// Length of the `active_blocks` list `mc_scan` writes: every block plus the padding of a
    /// 2D dispatch (fewer than its rows).
    pub fn active_blocks_len(&self, max_per_dimension: u32) -> usize {
        self.n_blocks as usize + self.n_blocks.div_ceil(max_per_dimension.max(1)) as usize
    }
}

/// Invocations per `mc_count` workgroup (its reflected workgroup size).
pub const MC_COUNT_WG_SIZE: u32 = super::WORKGROUP_SIZE[0];

/// `n_workgroups` laid out as `[x, y, 1]` with `x` at most `max_per_dimension` (WebGPU's
/// default 65535), `x * y >= n_workgroups` and fewer than `y` idle; the kernels number them
/// `wg.x + wg.y * num_workgroups.x`. `[0, 1, 1]` for none.
pub fn workgroups_2d(n_workgroups: u32, max_per_dimension: u32) -> [u32; 3] {
    let y = n_workgroups.div_ceil(max_per_dimension.max(1)).max(1);
    [n_workgroups.div_ceil(y), y, 1]
}

/// Records one `mc_count` dispatch: one invocation per block.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, grid: &McGrid) {
    let [x, y, z] = grid.count_workgroups(gpu.limits.max_compute_workgroups_per_dimension);
    gpu.kernels.mc_count.dispatch(encoder, bind_group, [x * MC_COUNT_WG_SIZE, y, z]);
}
