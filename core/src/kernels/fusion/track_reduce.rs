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
/// Most workgroups of one dispatch (each writes one partial sum, which `track_solve` adds).
pub const MAX_WORKGROUPS: u32 = 64;
/// Fewest pixels each thread takes on a GPU: a thread's fixed work (zeroing its 32 sums,
/// its share of the workgroup reduction) is about that of four pixels, so sixteen keep it
/// under a fifth.
pub const MIN_PIXELS_PER_THREAD_GPU: u32 = 16;
/// Fewest pixels each thread takes on a CPU adapter (lavapipe, SwiftShader): there every
/// invocation of this kernel also pays a large fixed cost (measured on SwiftShader in
/// Chromium: about 8 µs per invocation against 0.2 µs per pixel, some 40 pixels' worth), so
/// threads take 128 pixels to keep it near a quarter. (On SwiftShader, one ICP iteration at
/// 640x480 went from 133 to ~90 ms, at 160x120 from 68 to ~11 ms.)
pub const MIN_PIXELS_PER_THREAD_CPU: u32 = 128;

/// Fewest pixels per thread on an adapter of `device_type`.
pub fn min_pixels_per_thread(device_type: wgpu::DeviceType) -> u32 {
    if device_type == wgpu::DeviceType::Cpu { MIN_PIXELS_PER_THREAD_CPU } else { MIN_PIXELS_PER_THREAD_GPU }
}

/// Workgroups of a level with `pixel_count` pixels: enough that no thread takes fewer than
/// `min_pixels_per_thread` pixels, at least 1 and at most [`MAX_WORKGROUPS`].
pub fn reduce_workgroups(pixel_count: usize, min_pixels_per_thread: u32) -> u32 {
    let per_workgroup = (WORKGROUP_THREADS * min_pixels_per_thread.max(1)) as usize;
    (pixel_count.div_ceil(per_workgroup)).clamp(1, MAX_WORKGROUPS as usize) as u32
}
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
