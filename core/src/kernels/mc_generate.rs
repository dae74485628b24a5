// SPDX-License-Identifier: MIT
//! Host side of `mc_generate`: writes the triangles of a range of global triangle indices,
//! one workgroup per block with triangles (pass 3 of 3).
//!
//! Kernel: `shaders/wgsl/mc_generate.wgsl`; CPU reference: [`fn@crate::cpu::mc_generate`].

use super::mc_count::McGrid;
use super::mc_scan::MC_GENERATE_DISPATCH_OFFSET_BYTES;
use crate::Gpu;
use crate::tsdf::VolumeDesc;

/// Mirror of WGSL `McGenerateParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct McGenerateParams {
    /// The TSDF volume.
    pub volume: VolumeDesc,
    /// Blocks along x.
    pub n_blocks_x: u32,
    /// Blocks along y.
    pub n_blocks_y: u32,
    /// First global triangle index this pass writes.
    pub first_triangle: u32,
    /// Triangles the `vertices` buffer holds (3 [`McVertex`] each).
    pub capacity_triangles: u32,
    /// 1 when `colors` holds one RGB8 word per voxel, else 0 (vertices are white).
    pub has_color: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Mirror of WGSL `McVertex`: one corner of an output triangle, 32 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct McVertex {
    /// World x, metres.
    pub x_m: f32,
    /// World y, metres.
    pub y_m: f32,
    /// World z, metres.
    pub z_m: f32,
    /// Voxel edge the vertex lies on: `voxel_index(lower voxel) * 3 + axis`; equal for every
    /// cell sharing the edge, so it welds triangles into an indexed mesh.
    pub edge_id: u32,
    /// Unit normal x (toward free space).
    pub normal_x: f32,
    /// Unit normal y.
    pub normal_y: f32,
    /// Unit normal z.
    pub normal_z: f32,
    /// Colour, `r | g << 8 | b << 16`.
    pub color_rgb8: u32,
}

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

/// Buffers of one `mc_generate` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct McGenerateBindings<'a> {
    /// Uniform [`McGenerateParams`].
    pub params: &'a wgpu::Buffer,
    /// Voxel words (TSDF + weight).
    pub tsdf_volume: &'a wgpu::Buffer,
    /// Colour words (RGB8), or a placeholder when `has_color` is 0.
    pub colors: &'a wgpu::Buffer,
    /// [`crate::mesh::mc_table::McTable::packed`].
    pub mc_table: &'a wgpu::Buffer,
    /// Blocks with triangles, padded (from `mc_scan`).
    pub active_blocks: &'a wgpu::Buffer,
    /// First triangle of each block (from `mc_scan`).
    pub block_offsets: &'a wgpu::Buffer,
    /// Out: `3 * capacity_triangles` [`McVertex`].
    pub vertices: &'a wgpu::Buffer,
}

impl McGenerateBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.mc_generate.bind_group(
            &gpu.device,
            &[self.params, self.tsdf_volume, self.colors, self.mc_table, self.active_blocks, self.block_offsets, self.vertices],
        )
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
