// SPDX-License-Identifier: MIT
//! Host side of `vertex_gradients`: central differences of the vertex map.
//!
//! Kernel: `shaders/wgsl/vertex_gradients.wgsl`; CPU reference: [`fn@crate::cpu::vertex_gradients`].

use crate::Gpu;

/// Mirror of WGSL `VertexGradientsParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct VertexGradientsParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

/// Buffers of one `vertex_gradients` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct VertexGradientsBindings<'a> {
    /// Uniform `VertexGradientsParams`.
    pub params: &'a wgpu::Buffer,
    /// Vertices, camera frame.
    pub vertex_in_camera: &'a wgpu::Buffer,
    /// V(x+1) - V(x-1), metres.
    pub grad_x: &'a wgpu::Buffer,
    /// V(y+1) - V(y-1), metres.
    pub grad_y: &'a wgpu::Buffer,
}

impl VertexGradientsBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.vertex_gradients.bind_group(&gpu.device, &[self.params, self.vertex_in_camera, self.grad_x, self.grad_y])
    }
}

/// Records one `vertex_gradients` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &VertexGradientsParams) {
    gpu.kernels.vertex_gradients.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
