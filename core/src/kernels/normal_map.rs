// SPDX-License-Identifier: MIT
//! Host side of `normal_map`: unit normals from the gradient cross product, facing the camera.
//!
//! Kernel: `shaders/wgsl/normal_map.wgsl`; CPU reference: [`fn@crate::cpu::normal_map`].

use crate::Gpu;

/// Mirror of WGSL `NormalMapParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct NormalMapParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Cross products with a squared norm at or below this (m^4) give no normal.
    pub min_cross_norm_sq: f32,
    /// Padding.
    pub _pad0: u32,
}

/// Buffers of one `normal_map` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct NormalMapBindings<'a> {
    /// Uniform `NormalMapParams`.
    pub params: &'a wgpu::Buffer,
    /// Vertices, camera frame.
    pub vertex_in_camera: &'a wgpu::Buffer,
    /// x gradients.
    pub grad_x: &'a wgpu::Buffer,
    /// y gradients.
    pub grad_y: &'a wgpu::Buffer,
    /// Unit normals (nx, ny, nz, 0), camera frame.
    pub normal_in_camera: &'a wgpu::Buffer,
}

impl NormalMapBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.normal_map.bind_group(&gpu.device, &[self.params, self.vertex_in_camera, self.grad_x, self.grad_y, self.normal_in_camera])
    }
}

/// Records one `normal_map` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &NormalMapParams) {
    gpu.kernels.normal_map.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
