// SPDX-License-Identifier: MIT
//! Host side of `raycast`: surface prediction (vertex, normal, depth, shaded and colour images)
//! from the TSDF at any pose and intrinsics; also the virtual depth sensor.
//!
//! Kernel: `shaders/wgsl/raycast.wgsl`; CPU reference: [`fn@crate::cpu::raycast`].

use super::GpuIntrinsics;
use crate::Gpu;
use crate::tsdf::VolumeDesc;

/// Default largest march step as a fraction of the truncation distance.
pub const DEFAULT_STEP_FACTOR: f32 = 0.8;
/// Default cap on march steps per ray.
pub const DEFAULT_MAX_STEPS: u32 = 2048;

/// Mirror of WGSL `RaycastParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct RaycastParams {
    /// The volume.
    pub volume: VolumeDesc,
    /// Intrinsics of the rendered images.
    pub intrinsics: GpuIntrinsics,
    /// Camera to world, column-major.
    pub world_from_camera: [[f32; 4]; 4],
    /// Nearest depth searched, metres.
    pub min_depth_m: f32,
    /// Farthest depth searched, metres.
    pub max_depth_m: f32,
    /// Largest step as a fraction of μ.
    pub step_factor: f32,
    /// Cap on march steps per ray.
    pub max_steps: u32,
}

/// Buffers of one `raycast` dispatch, in WGSL binding order.
#[derive(Clone, Copy, Debug)]
pub struct RaycastBindings<'a> {
    /// Uniform `RaycastParams`.
    pub params: &'a wgpu::Buffer,
    /// Voxel words.
    pub tsdf_volume: &'a wgpu::Buffer,
    /// Colour words (one placeholder word when colour is off).
    pub color_volume: &'a wgpu::Buffer,
    /// Surface points (x, y, z, 1), world frame.
    pub vertex_in_world: &'a wgpu::Buffer,
    /// Unit normals (nx, ny, nz, 0), world frame.
    pub normal_in_world: &'a wgpu::Buffer,
    /// Depth along the camera's z, metres.
    pub depth_m: &'a wgpu::Buffer,
    /// Headlight-shaded grey, RGBA8.
    pub shaded_rgba8: &'a wgpu::Buffer,
    /// Model colour, RGBA8.
    pub color_rgba8: &'a wgpu::Buffer,
}

impl RaycastBindings<'_> {
    /// Creates the bind group.
    pub fn bind_group(&self, gpu: &Gpu) -> wgpu::BindGroup {
        gpu.kernels.raycast.bind_group(
            &gpu.device,
            &[self.params, self.tsdf_volume, self.color_volume, self.vertex_in_world, self.normal_in_world, self.depth_m, self.shaded_rgba8, self.color_rgba8],
        )
    }
}

/// Records one `raycast` dispatch over the image described by `p.intrinsics`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &RaycastParams) {
    gpu.kernels.raycast.dispatch(encoder, bind_group, [p.intrinsics.width_px, p.intrinsics.height_px, 1]);
}
