// SPDX-License-Identifier: MIT
//! Host side of `block_integrate`: dispatched indirectly, one workgroup per visible block (the
//! size `block_list_args` writes into the map's counters).

/// Byte offset of `block_integrate`'s dispatch size in the map's counters
/// (`MAP_COUNTER_ARGS` words in).
pub const DISPATCH_OFFSET_BYTES: u64 = crate::cpu::shared::MAP_COUNTER_ARGS as u64 * 4;

/// Records the integration of the visible blocks into an open compute pass, sized by
/// `map_counters` (a buffer with `INDIRECT` usage).
pub fn dispatch_indirect_in(gpu: &crate::Gpu, pass: &mut wgpu::ComputePass<'_>, bind_group: &wgpu::BindGroup, map_counters: &wgpu::Buffer) {
    pass.set_pipeline(&gpu.kernels.block_integrate.pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups_indirect(map_counters, DISPATCH_OFFSET_BYTES);
}
