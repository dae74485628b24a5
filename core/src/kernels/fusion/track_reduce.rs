// SPDX-License-Identifier: MIT
//! Host side of `track_reduce`: its dispatch is indirect, sized per level by `track_begin` and
//! `track_solve` (0 workgroups once the level converged).
//!
//! Kernel: `shaders/wgsl/fusion/track_reduce.wgsl`; CPU reference: [`fn@crate::cpu::track_reduce`].

/// Threads per workgroup (`NE_WORKGROUP_SIZE` in shared/normal_equations.wgsl).
pub const WORKGROUP_THREADS: u32 = crate::cpu::shared::NE_WORKGROUP_SIZE;
/// Floats per workgroup's partial sum: JᵀJ upper triangle (21), Jᵀr (6), Σ r² and count of the
/// point-to-plane rows, Σ r² and count of the photometric rows, 0.
pub const SUM_FLOATS: usize = crate::cpu::shared::NE_SUM_FLOATS;
/// Default workgroups per dispatch (each writes one partial sum, which `track_solve` adds).
pub const DEFAULT_WORKGROUPS: u32 = 64;
/// Byte offset of level `level`'s dispatch arguments in a `TrackDispatch` buffer.
pub fn dispatch_offset_bytes(level: usize) -> u64 {
    16 * level as u64
}

/// Records one `track_reduce` dispatch of `level`, sized by `dispatch` (a `TrackDispatch`
/// buffer with `INDIRECT` usage), into an open compute pass.
pub fn dispatch_indirect(gpu: &crate::Gpu, pass: &mut wgpu::ComputePass<'_>, bind_group: &wgpu::BindGroup, dispatch: &wgpu::Buffer, level: usize) {
    pass.set_pipeline(&gpu.kernels.track_reduce.pipeline);
    pass.set_bind_group(0, bind_group, &[]);
    pass.dispatch_workgroups_indirect(dispatch, dispatch_offset_bytes(level));
}
