// SPDX-License-Identifier: MIT
//! Host side of `rgb_reduce`: photometric normal equations against the previous frame, one
//! partial sum per workgroup in `icp_reduce`'s layout.
//!
//! Kernel: `shaders/wgsl/rgb_reduce.wgsl`; CPU reference: [`fn@crate::cpu::rgb_reduce`].

use super::GpuIntrinsics;
use crate::Gpu;

/// Mirror of WGSL `RgbReduceParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RgbReduceParams {
    /// Intrinsics of this pyramid level (both frames).
    pub intrinsics: GpuIntrinsics,
    /// Current estimate of the frame's pose, column-major.
    pub world_from_camera: [[f32; 4]; 4],
    /// Inverse of the previous frame's pose, column-major.
    pub camera_prev_from_world: [[f32; 4]; 4],
    /// The previous frame's pose, column-major.
    pub world_from_camera_prev: [[f32; 4]; 4],
    /// Largest difference between the warped depth and the previous depth there, metres.
    pub max_depth_diff_m: f32,
    /// Largest accepted intensity residual (intensities in [0, 1]).
    pub max_residual: f32,
    /// Threads in the dispatch (the pixel stride).
    pub thread_count: u32,
    /// Padding.
    pub _pad0: u32,
}

/// Buffers of one `rgb_reduce` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct RgbReduceBindings<'a> {
    /// Uniform `RgbReduceParams`.
    pub params: &'a wgpu::Buffer,
    /// Current frame's vertices, camera frame.
    pub vertex_in_camera: &'a wgpu::Buffer,
    /// Current frame's intensity.
    pub intensity: &'a wgpu::Buffer,
    /// Previous frame's intensity.
    pub prev_intensity: &'a wgpu::Buffer,
    /// Previous frame's depth, metres.
    pub prev_depth_m: &'a wgpu::Buffer,
    /// `icp_reduce::WORKGROUPS` × `icp_reduce::SUM_FLOATS` partial sums.
    pub partial_sums: &'a wgpu::Buffer,
}

impl RgbReduceBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.rgb_reduce.bind_group(&gpu.device, &[self.params, self.vertex_in_camera, self.intensity, self.prev_intensity, self.prev_depth_m, self.partial_sums])
    }
}

/// Records one `rgb_reduce` dispatch of `p.thread_count` threads.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &RgbReduceParams) {
    gpu.kernels.rgb_reduce.dispatch(encoder, bind_group, [p.thread_count, 1, 1]);
}
