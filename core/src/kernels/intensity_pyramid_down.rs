// SPDX-License-Identifier: MIT
//! Host side of `intensity_pyramid_down`: 2x2 mean of the intensity image.
//!
//! Kernel: `shaders/wgsl/intensity_pyramid_down.wgsl`; CPU reference:
//! [`fn@crate::cpu::intensity_pyramid_down`].

use crate::Gpu;

/// Mirror of WGSL `IntensityPyramidDownParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct IntensityPyramidDownParams {
    /// Finer level width, pixels.
    pub src_width_px: u32,
    /// Finer level height, pixels.
    pub src_height_px: u32,
    /// Coarser level width, pixels.
    pub dst_width_px: u32,
    /// Coarser level height, pixels.
    pub dst_height_px: u32,
}

/// Buffers of one `intensity_pyramid_down` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct IntensityPyramidDownBindings<'a> {
    /// Uniform `IntensityPyramidDownParams`.
    pub params: &'a wgpu::Buffer,
    /// Finer intensities.
    pub src: &'a wgpu::Buffer,
    /// Coarser intensities.
    pub dst: &'a wgpu::Buffer,
}

impl IntensityPyramidDownBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.intensity_pyramid_down.bind_group(&gpu.device, &[self.params, self.src, self.dst])
    }
}

/// Records one `intensity_pyramid_down` dispatch over the coarser level.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &IntensityPyramidDownParams) {
    gpu.kernels.intensity_pyramid_down.dispatch(encoder, bind_group, [p.dst_width_px, p.dst_height_px, 1]);
}
