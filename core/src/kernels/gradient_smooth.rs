// SPDX-License-Identifier: MIT
//! Host side of `gradient_smooth`: one separable Gaussian pass over both gradient images.
//!
//! Kernel: `shaders/wgsl/gradient_smooth.wgsl`; CPU reference: [`fn@crate::cpu::gradient_smooth`].

use crate::Gpu;

/// Mirror of WGSL `GradientSmoothParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GradientSmoothParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Taps on each side.
    pub radius_px: u32,
    /// 0 = along x, 1 = along y.
    pub axis: u32,
    /// Gaussian sigma, pixels.
    pub sigma_px: f32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Buffers of one `gradient_smooth` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct GradientSmoothBindings<'a> {
    /// Uniform `GradientSmoothParams`.
    pub params: &'a wgpu::Buffer,
    /// x gradients in.
    pub grad_x_in: &'a wgpu::Buffer,
    /// y gradients in.
    pub grad_y_in: &'a wgpu::Buffer,
    /// x gradients out.
    pub grad_x_out: &'a wgpu::Buffer,
    /// y gradients out.
    pub grad_y_out: &'a wgpu::Buffer,
}

impl GradientSmoothBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.gradient_smooth.bind_group(&gpu.device, &[self.params, self.grad_x_in, self.grad_y_in, self.grad_x_out, self.grad_y_out])
    }
}

/// Records one `gradient_smooth` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &GradientSmoothParams) {
    gpu.kernels.gradient_smooth.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
