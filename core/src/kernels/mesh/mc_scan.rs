// SPDX-License-Identifier: MIT
//! Host side of `mc_scan`: exclusive offsets of the per-block triangle counts, the list of
//! blocks with triangles, the grand total, the overflow flag and the size of the indirect
//! `mc_generate` dispatch (pass 2 of 3).
//!
//! Kernel: `shaders/wgsl/mesh/mc_scan.wgsl`; CPU reference: [`fn@crate::cpu::mc_scan`].

use super::McCounters;
use crate::Gpu;

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
