// SPDX-License-Identifier: MIT
//! Host side of `icp_reduce`: point-to-plane normal equations, one partial sum per workgroup.
//!
//! Kernel: `shaders/wgsl/fusion/icp_reduce.wgsl`; CPU reference: [`fn@crate::cpu::icp_reduce`].

use super::IcpReduceParams;
use crate::Gpu;

/// Threads per workgroup (`NE_WORKGROUP_SIZE` in shared/normal_equations.wgsl).
pub const WORKGROUP_THREADS: u32 = crate::cpu::shared::NE_WORKGROUP_SIZE;
/// Workgroups per dispatch: each writes one partial sum; the host adds them in f64.
pub const WORKGROUPS: u32 = 64;
/// Floats per partial sum: JᵀJ upper triangle (21), Jᵀr (6), r², inlier count, 3 zeros.
pub const SUM_FLOATS: usize = crate::cpu::shared::NE_SUM_FLOATS;

/// Twin of `kinect_sigma_m()`: Kinect v1 axial depth noise at `z_m` (Nguyen, Izadi and
/// Lovell 2012), metres.
pub fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    0.0012 + 0.0019 * d * d
}

/// Records one `icp_reduce` dispatch of `p.thread_count` threads.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &IcpReduceParams) {
    gpu.kernels.icp_reduce.dispatch(encoder, bind_group, [p.thread_count, 1, 1]);
}
