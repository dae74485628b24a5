// SPDX-License-Identifier: MIT
//! Host side of `bilateral_filter`: edge-preserving bilateral filter of a metric depth image.
//!
//! Kernel: `shaders/wgsl/bilateral_filter.wgsl`; CPU reference: [`fn@crate::cpu::bilateral_filter`].

use crate::Gpu;

/// Mirror of WGSL `BilateralFilterParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct BilateralFilterParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Window radius r: (2r+1)^2 taps.
    pub radius_px: u32,
    /// Padding.
    pub _pad0: u32,
    /// Spatial Gaussian sigma, pixels.
    pub sigma_space_px: f32,
    /// Range (depth difference) Gaussian sigma, metres.
    pub sigma_range_m: f32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Buffers of one `bilateral_filter` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct BilateralFilterBindings<'a> {
    /// Uniform `BilateralFilterParams`.
    pub params: &'a wgpu::Buffer,
    /// Input depth, metres.
    pub depth_in_m: &'a wgpu::Buffer,
    /// Filtered depth, metres.
    pub depth_out_m: &'a wgpu::Buffer,
}

impl BilateralFilterBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.bilateral_filter.bind_group(&gpu.device, &[self.params, self.depth_in_m, self.depth_out_m])
    }
}

/// Records one `bilateral_filter` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &BilateralFilterParams) {
    gpu.kernels.bilateral_filter.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
