// SPDX-License-Identifier: MIT
//! Host side of `depth_to_metres`: converts raw depth units to metres, NaN where invalid.
//!
//! Kernel: `shaders/wgsl/depth_to_metres.wgsl`; CPU reference: [`fn@crate::cpu::depth_to_metres`].

use crate::Gpu;

/// Mirror of WGSL `DepthToMetresParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct DepthToMetresParams {
    /// Image width, pixels.
    pub width_px: u32,
    /// Image height, pixels.
    pub height_px: u32,
    /// Metres per raw depth unit.
    pub metres_per_unit: f32,
    /// Nearest valid depth, metres.
    pub min_depth_m: f32,
    /// Farthest valid depth, metres.
    pub max_depth_m: f32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Buffers of one `depth_to_metres` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct DepthToMetresBindings<'a> {
    /// Uniform `DepthToMetresParams`.
    pub params: &'a wgpu::Buffer,
    /// Raw depth, two u16 per u32 word (low half first).
    pub depth_raw: &'a wgpu::Buffer,
    /// Output depth, metres (f32 per pixel).
    pub depth_m: &'a wgpu::Buffer,
}

impl DepthToMetresBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.depth_to_metres.bind_group(&gpu.device, &[self.params, self.depth_raw, self.depth_m])
    }
}

/// Records one `depth_to_metres` dispatch over the image described by `p`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &DepthToMetresParams) {
    gpu.kernels.depth_to_metres.dispatch(encoder, bind_group, [p.width_px, p.height_px, 1]);
}
