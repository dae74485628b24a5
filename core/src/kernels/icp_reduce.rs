// SPDX-License-Identifier: MIT
//! Host side of `icp_reduce`: point-to-plane normal equations, one partial sum per workgroup.
//!
//! Kernel: `shaders/wgsl/icp_reduce.wgsl`; CPU reference: [`fn@crate::cpu::icp_reduce`].

use super::GpuIntrinsics;
use crate::Gpu;

/// Threads per workgroup (`NE_WORKGROUP_SIZE` in shared/normal_equations.wgsl).
pub const WORKGROUP_SIZE: u32 = crate::cpu::shared::NE_WORKGROUP_SIZE;
/// Workgroups per dispatch: each writes one partial sum; the host adds them in f64.
pub const WORKGROUPS: u32 = 64;
/// Floats per partial sum: JᵀJ upper triangle (21), Jᵀr (6), r², inlier count, 3 zeros.
pub const SUM_FLOATS: usize = crate::cpu::shared::NE_SUM_FLOATS;

/// Mirror of WGSL `IcpReduceParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct IcpReduceParams {
    /// Intrinsics of this pyramid level (current frame and prediction alike).
    pub intrinsics: GpuIntrinsics,
    /// Current estimate of the frame's pose, column-major.
    pub world_from_camera: [[f32; 4]; 4],
    /// Inverse of the pose the prediction was rendered from, column-major.
    pub camera_prev_from_world: [[f32; 4]; 4],
    /// Largest point distance of a correspondence, metres.
    pub dist_thresh_m: f32,
    /// Smallest cosine between the two normals of a correspondence.
    pub cos_angle_thresh: f32,
    /// Threads in the dispatch (the pixel stride).
    pub thread_count: u32,
    /// Huber threshold on the residual, metres (0: plain least squares).
    pub huber_delta_m: f32,
    /// Non-zero: weight pairs by the Kinect axial noise model at the vertex's depth.
    pub noise_weighting: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Twin of `kinect_sigma_m()`: Kinect v1 axial depth noise at `z_m` (Nguyen, Izadi and
/// Lovell 2012), metres.
pub fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    0.0012 + 0.0019 * d * d
}

/// Buffers of one `icp_reduce` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct IcpReduceBindings<'a> {
    /// Uniform `IcpReduceParams`.
    pub params: &'a wgpu::Buffer,
    /// Current frame's vertices, camera frame.
    pub vertex_in_camera: &'a wgpu::Buffer,
    /// Current frame's normals, camera frame.
    pub normal_in_camera: &'a wgpu::Buffer,
    /// Predicted vertices, world frame.
    pub predicted_vertex_in_world: &'a wgpu::Buffer,
    /// Predicted normals, world frame.
    pub predicted_normal_in_world: &'a wgpu::Buffer,
    /// [`WORKGROUPS`] × [`SUM_FLOATS`] partial sums.
    pub partial_sums: &'a wgpu::Buffer,
}

impl IcpReduceBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.icp_reduce.bind_group(
            &gpu.device,
            &[self.params, self.vertex_in_camera, self.normal_in_camera, self.predicted_vertex_in_world, self.predicted_normal_in_world, self.partial_sums],
        )
    }
}

/// Records one `icp_reduce` dispatch of `p.thread_count` threads.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &IcpReduceParams) {
    gpu.kernels.icp_reduce.dispatch(encoder, bind_group, [p.thread_count, 1, 1]);
}
