// SPDX-License-Identifier: MIT
//! Host side of `raycast`: surface prediction (vertex, normal, depth, shaded and colour images)
//! from the TSDF at any pose and intrinsics; also the virtual depth sensor.
//!
//! Kernel: `shaders/wgsl/fusion/raycast.wgsl`; CPU reference: [`fn@crate::cpu::raycast`].

use super::RaycastParams;
use crate::Gpu;

/// Default largest march step as a fraction of the truncation distance.
pub const DEFAULT_STEP_FACTOR: f32 = 0.8;
/// Default cap on march steps per ray.
pub const DEFAULT_MAX_STEPS: u32 = 2048;

/// Records one `raycast` dispatch over the image described by `p.intrinsics`.
pub fn encode(gpu: &Gpu, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, p: &RaycastParams) {
    gpu.kernels.raycast.dispatch(encoder, bind_group, [p.intrinsics.width_px, p.intrinsics.height_px, 1]);
}
