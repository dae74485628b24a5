// SPDX-License-Identifier: MIT
//! Host side of `depth_pyramid_down`: edge-aware 2x2 block average to the next pyramid level.
//!
//! Kernel: `shaders/wgsl/depth_pyramid_down.wgsl`; CPU reference: [`fn@crate::cpu::depth_pyramid_down`].

use crate::Gpu;

/// Mirror of WGSL `DepthPyramidDownParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DepthPyramidDownParams {
    /// Fine level width, pixels.
    pub src_width_px: u32,
    /// Fine level height, pixels.
    pub src_height_px: u32,
    /// Coarse level width (fine / 2, rounded down).
    pub dst_width_px: u32,
    /// Coarse level height (fine / 2, rounded down).
    pub dst_height_px: u32,
    /// Block samples farther than this behind the block's nearest sample are left out, metres.
    pub max_depth_diff_m: f32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Buffers of one `depth_pyramid_down` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct DepthPyramidDownBindings<'a> {
    /// Uniform `DepthPyramidDownParams`.
    pub params: &'a wgpu::Buffer,
    /// Fine depth, metres.
    pub depth_fine_m: &'a wgpu::Buffer,
    /// Coarse depth, metres.
    pub depth_coarse_m: &'a wgpu::Buffer,
}

impl DepthPyramidDownBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.depth_pyramid_down.bind_group(&gpu.device, &[self.params, self.depth_fine_m, self.depth_coarse_m])
    }
}

/// Records one `depth_pyramid_down` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &DepthPyramidDownParams) {
    gpu.kernels.depth_pyramid_down.dispatch(encoder, bind_group, [p.dst_width_px, p.dst_height_px, 1]);
}
