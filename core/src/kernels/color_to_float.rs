// SPDX-License-Identifier: MIT
//! Host side of `color_to_float`: RGB8 to float colour and BT.601 intensity.
//!
//! Kernel: `shaders/wgsl/color_to_float.wgsl`; CPU reference: [`fn@crate::cpu::color_to_float`].

use crate::Gpu;

/// Mirror of WGSL `ColorToFloatParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ColorToFloatParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

/// Buffers of one `color_to_float` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct ColorToFloatBindings<'a> {
    /// Uniform `ColorToFloatParams`.
    pub params: &'a wgpu::Buffer,
    /// RGB8 bytes packed four per u32 word.
    pub rgb8: &'a wgpu::Buffer,
    /// Colour (r, g, b, 1) in [0, 1].
    pub color: &'a wgpu::Buffer,
    /// Intensity in [0, 1].
    pub intensity: &'a wgpu::Buffer,
}

impl ColorToFloatBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.color_to_float.bind_group(&gpu.device, &[self.params, self.rgb8, self.color, self.intensity])
    }
}

/// Records one `color_to_float` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &ColorToFloatParams) {
    gpu.kernels.color_to_float.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
