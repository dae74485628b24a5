// SPDX-License-Identifier: MIT
//! Host side of `mc_generate`: writes the triangles of a range of global triangle indices,
//! one workgroup per block with triangles (pass 3 of 3).
//!
//! Kernel: `shaders/wgsl/mesh/mc_generate.wgsl`; CPU reference: [`fn@crate::cpu::mc_generate`].

use super::McGenerateParams;
use crate::kernels::mc_count::McGrid;
use crate::kernels::mc_scan::MC_GENERATE_DISPATCH_OFFSET_BYTES;
use crate::Gpu;
use crate::tsdf::VolumeDesc;

/// Colour of vertices of a store without colour, WGSL `MC_WHITE_RGB8`.
pub const MC_WHITE_RGB8: u32 = 0x00ff_ffff;
/// Squared gradient norms at or below this give the edge-direction fallback normal, WGSL
/// `MC_MIN_GRADIENT_SQ` (truncation units per voxel, squared).
pub const MC_MIN_GRADIENT_SQ: f32 = 1e-12;

impl McGenerateParams {
    /// Parameters for writing triangles `first_triangle..first_triangle + capacity_triangles`.
    pub fn new(volume: VolumeDesc, grid: McGrid, first_triangle: u32, capacity_triangles: u32, has_color: bool) -> Self {
        Self { volume, n_blocks_x: grid.n_blocks_x, n_blocks_y: grid.n_blocks_y, first_triangle, capacity_triangles, has_color: u32::from(has_color), ..Default::default() }
    }
}

/// Records one `mc_generate` dispatch sized by the `McCounters` that `mc_scan` wrote into
/// `counters` (one workgroup per block with triangles).
pub fn encode_indirect(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, counters: &wgpu::Buffer) {
    let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("core.mc_generate"), timestamp_writes: None });
    pass.set_pipeline(&gpu.kernels.mc_generate.pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups_indirect(counters, MC_GENERATE_DISPATCH_OFFSET_BYTES);
}
