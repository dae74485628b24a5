// SPDX-License-Identifier: MIT
//! Host side of `vertex_map`: back-projection of depth to camera-frame vertices.
//!
//! Kernel: `shaders/wgsl/vertex_map.wgsl`; CPU reference: [`fn@crate::cpu::vertex_map`].

use super::GpuIntrinsics;
use crate::Gpu;

/// Mirror of WGSL `VertexMapParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VertexMapParams {
    /// Intrinsics of this pyramid level.
    pub intrinsics: GpuIntrinsics,
}

/// Buffers of one `vertex_map` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct VertexMapBindings<'a> {
    /// Uniform `VertexMapParams`.
    pub params: &'a wgpu::Buffer,
    /// Depth, metres.
    pub depth_m: &'a wgpu::Buffer,
    /// Vertices (x, y, z, 1), metres, camera frame.
    pub vertex_in_camera: &'a wgpu::Buffer,
}

impl VertexMapBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.vertex_map.bind_group(&gpu.device, &[self.params, self.depth_m, self.vertex_in_camera])
    }
}

/// Records one `vertex_map` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &VertexMapParams) {
    gpu.kernels.vertex_map.dispatch(encoder, bind_group, [p.intrinsics.width_px, p.intrinsics.height_px, 1]);
}
