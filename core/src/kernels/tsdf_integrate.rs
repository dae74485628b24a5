// SPDX-License-Identifier: MIT
//! Host side of `tsdf_integrate`: projective TSDF update of every voxel from one depth image.
//!
//! Kernel: `shaders/wgsl/tsdf_integrate.wgsl`; CPU reference: [`fn@crate::cpu::tsdf_integrate`].

use super::GpuIntrinsics;
use crate::Gpu;
use crate::tsdf::VolumeDesc;

/// Mirror of WGSL `TsdfIntegrateParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TsdfIntegrateParams {
    /// The volume.
    pub volume: VolumeDesc,
    /// Intrinsics of the depth image.
    pub intrinsics: GpuIntrinsics,
    /// World to camera, column-major.
    pub camera_from_world: [[f32; 4]; 4],
    /// Non-zero: also fuse colour.
    pub color_enabled: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
    /// Padding.
    pub _pad2: u32,
}

/// Buffers of one `tsdf_integrate` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct TsdfIntegrateBindings<'a> {
    /// Uniform `TsdfIntegrateParams`.
    pub params: &'a wgpu::Buffer,
    /// Depth, metres (NaN = none).
    pub depth_m: &'a wgpu::Buffer,
    /// Colour (r, g, b, 1), registered to depth.
    pub color: &'a wgpu::Buffer,
    /// Voxel words, updated in place.
    pub tsdf_volume: &'a wgpu::Buffer,
    /// Colour words, updated in place.
    pub color_volume: &'a wgpu::Buffer,
}

impl TsdfIntegrateBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.tsdf_integrate.bind_group(&gpu.device, &[self.params, self.depth_m, self.color, self.tsdf_volume, self.color_volume])
    }
}

/// Records one `tsdf_integrate` dispatch: one invocation per voxel column of `p.volume`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &TsdfIntegrateParams) {
    gpu.kernels.tsdf_integrate.dispatch(encoder, bind_group, [p.volume.dim_x, p.volume.dim_y, 1]);
}
