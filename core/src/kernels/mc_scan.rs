// SPDX-License-Identifier: MIT
//! Host side of `mc_scan`: exclusive offsets of the per-block triangle counts, the list of
//! blocks with triangles, the grand total, the overflow flag and the size of the indirect
//! `mc_generate` dispatch (pass 2 of 3).
//!
//! Kernel: `shaders/wgsl/mc_scan.wgsl`; CPU reference: [`fn@crate::cpu::mc_scan`].

use crate::Gpu;

/// Mirror of WGSL `McScanParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct McScanParams {
    /// Blocks of cells.
    pub n_blocks: u32,
    /// Triangles the output holds; a larger total sets [`MC_FAILED_OUTPUT`].
    pub capacity_triangles: u32,
    /// The device's `max_compute_workgroups_per_dimension`, for `mc_generate`'s dispatch.
    pub max_workgroups_per_dimension: u32,
    /// Padding.
    pub _pad0: u32,
}

/// Mirror of WGSL `McCounters` (`shaders/wgsl/shared/mc_counters.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct McCounters {
    /// Triangles the whole volume produces, counted past the capacity.
    pub n_triangles: u32,
    /// The capacity it was compared with.
    pub capacity_triangles: u32,
    /// Bitmask of `MC_FAILED_*` flags.
    pub failed: u32,
    /// Blocks with at least one triangle.
    pub n_active_blocks: u32,
    /// Workgroups of `mc_generate` along x (indirect dispatch arguments start here).
    pub generate_workgroups_x: u32,
    /// Workgroups of `mc_generate` along y.
    pub generate_workgroups_y: u32,
    /// Workgroups of `mc_generate` along z (1).
    pub generate_workgroups_z: u32,
    /// Padding.
    pub _pad0: u32,
}

impl McCounters {
    /// The `mc_generate` dispatch size.
    pub fn generate_workgroups(&self) -> [u32; 3] {
        [self.generate_workgroups_x, self.generate_workgroups_y, self.generate_workgroups_z]
    }
}

/// `failed` flag: more triangles than the output holds.
pub const MC_FAILED_OUTPUT: u32 = 1;
/// Padding entry of `active_blocks`, WGSL `MC_NO_BLOCK`.
pub const MC_NO_BLOCK: u32 = u32::MAX;
/// Byte offset in the counters buffer of `mc_generate`'s indirect dispatch arguments.
pub const MC_GENERATE_DISPATCH_OFFSET_BYTES: u64 = std::mem::offset_of!(McCounters, generate_workgroups_x) as u64;

/// Buffers of one `mc_scan` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct McScanBindings<'a> {
    /// Uniform [`McScanParams`].
    pub params: &'a wgpu::Buffer,
    /// Triangles per block (from `mc_count`).
    pub block_counts: &'a wgpu::Buffer,
    /// Out: first triangle of each block.
    pub block_offsets: &'a wgpu::Buffer,
    /// Out: the blocks with triangles, in order, padded with [`MC_NO_BLOCK`]
    /// ([`crate::kernels::mc_count::McGrid::active_blocks_len`] entries).
    pub active_blocks: &'a wgpu::Buffer,
    /// Out: [`McCounters`]; needs `INDIRECT` usage to drive `mc_generate`.
    pub counters: &'a wgpu::Buffer,
}

impl McScanBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.mc_scan.bind_group(&gpu.device, &[self.params, self.block_counts, self.block_offsets, self.active_blocks, self.counters])
    }
}

/// A counters buffer usable as storage, indirect dispatch arguments and copy source.
pub fn counters_buffer(gpu: &Gpu) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("core.mc.counters"),
        size: std::mem::size_of::<McCounters>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::INDIRECT | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// Records the single-workgroup `mc_scan` dispatch.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup) {
    let wg = gpu.kernels.mc_scan.kernel.workgroup_size;
    gpu.kernels.mc_scan.dispatch(encoder, bind_group, wg);
}
