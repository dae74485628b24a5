// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/tsdf_integrate.wgsl`.

use crate::cpu::shared::{FAR_TSDF, brick_index, is_valid_f32, pack_rgb8, pack_voxel, transform_point, transform_vector, truncation_band_m, unpack_rgb8, voxel_centre_in_world, voxel_index, voxel_tsdf, voxel_weight};
use crate::kernels::GpuIntrinsics;
use crate::kernels::tsdf_integrate::{CameraPose, TsdfIntegrateParams};
use crate::tsdf::VolumeDesc;

/// Twin of `frustum_interval()`: the z-index interval `[lo, hi]` of the column points `a + k b`
/// (camera frame) inside the frustum; empty when `lo > hi`.
pub fn frustum_interval(params: &TsdfIntegrateParams, a: [f32; 3], b: [f32; 3], far_m: f32) -> [f32; 2] {
    let k = &params.intrinsics;
    let (w, h) = (k.width_px as f32, k.height_px as f32);
    let cs = [
        [a[2], b[2]],
        [far_m - a[2], -b[2]],
        [k.fx_px * a[0] + (k.cx_px + 0.5) * a[2], k.fx_px * b[0] + (k.cx_px + 0.5) * b[2]],
        [-(k.fx_px * a[0] + (k.cx_px + 0.5 - w) * a[2]), -(k.fx_px * b[0] + (k.cx_px + 0.5 - w) * b[2])],
        [k.fy_px * a[1] + (k.cy_px + 0.5) * a[2], k.fy_px * b[1] + (k.cy_px + 0.5) * b[2]],
        [-(k.fy_px * a[1] + (k.cy_px + 0.5 - h) * a[2]), -(k.fy_px * b[1] + (k.cy_px + 0.5 - h) * b[2])],
    ];
    let (mut lo, mut hi) = (-1e30f32, 1e30f32);
    for c in cs {
        if c[1] > 0.0 {
            lo = lo.max(-c[0] / c[1]);
        } else if c[1] < 0.0 {
            hi = hi.min(-c[0] / c[1]);
        } else if c[0] < 0.0 {
            return [1.0, 0.0];
        }
    }
    [lo, hi]
}

/// Updates every voxel as the kernel's invocations (one per column, frustum stretch only) do.
pub fn tsdf_integrate(params: &TsdfIntegrateParams, pose: &CameraPose, depth_m: &[f32], color: &[[f32; 4]], tsdf_volume: &mut [u32], color_volume: &mut [u32], surface_bricks: &mut [u32]) {
    let d = &params.volume;
    if pose.enabled == 0 {
        return;
    }
    for gy in 0..d.dim_y {
        for gx in 0..d.dim_x {
            let a = transform_point(&pose.camera_from_world, voxel_centre_in_world(d, gx, gy, 0));
            let b = transform_vector(&pose.camera_from_world, [0.0, 0.0, d.voxel_size_m]);
            let range = frustum_interval(params, a, b, params.max_depth_m + truncation_band_m(d, params.max_depth_m));
            if !(range[0] <= range[1]) || range[1] < -1.0 || range[0] > d.dim_z as f32 {
                continue;
            }
            let z0 = (range[0].floor() - 1.0).max(0.0) as u32;
            let z1 = (range[1].ceil() + 1.0).min((d.dim_z - 1) as f32) as u32;
            for gz in z0..=z1 {
                integrate_voxel(&params.intrinsics, params.color_enabled, d, pose, depth_m, color, tsdf_volume, color_volume, surface_bricks, voxel_centre_in_world(d, gx, gy, gz), voxel_index(d, gx, gy, gz), brick_index(d, gx, gy, gz));
            }
        }
    }
}

/// Twin of `integrate_voxel()` (shared/tsdf_update.wgsl): updates the voxel centred at
/// `p_world`, stored at `ix`, whose brick word is `brick`.
#[expect(clippy::too_many_arguments, reason = "the globals the WGSL function reads, then its arguments")]
pub fn integrate_voxel(k: &GpuIntrinsics, color_enabled: u32, d: &VolumeDesc, pose: &CameraPose, depth_m: &[f32], color: &[[f32; 4]], tsdf_volume: &mut [u32], color_volume: &mut [u32], surface_bricks: &mut [u32], p_world: [f32; 3], ix: u32, brick: u32) {
    let p_cam = transform_point(&pose.camera_from_world, p_world);
    if !(p_cam[2] > 0.0) {
        return;
    }
    let u = (k.fx_px * p_cam[0] / p_cam[2] + k.cx_px + 0.5).floor();
    let v = (k.fy_px * p_cam[1] / p_cam[2] + k.cy_px + 0.5).floor();
    if !(u >= 0.0 && v >= 0.0 && u < k.width_px as f32 && v < k.height_px as f32) {
        return;
    }
    let pixel = (v as u32 * k.width_px + u as u32) as usize;
    let depth = depth_m[pixel];
    if !is_valid_f32(depth) {
        return;
    }
    let sdf = depth - p_cam[2];
    let band = truncation_band_m(d, depth);
    if sdf < -band {
        return;
    }
    let tsdf = (sdf / band).min(1.0);
    let ix = ix as usize;
    let word = tsdf_volume[ix];
    let w = voxel_weight(word);
    let updated = (voxel_tsdf(word) * w as f32 + tsdf) / (w + 1) as f32;
    tsdf_volume[ix] = pack_voxel(updated, (w + 1).min(d.max_weight));
    if voxel_tsdf(pack_voxel(updated, 1)) < FAR_TSDF {
        surface_bricks[brick as usize] = 1;
    }
    if color_enabled != 0 && tsdf < 1.0 {
        let c_old = unpack_rgb8(color_volume[ix]);
        let c = color[pixel];
        let c_new: [f32; 3] = std::array::from_fn(|i| (c_old[i] * w as f32 + c[i]) / (w + 1) as f32);
        color_volume[ix] = pack_rgb8(c_new);
    }
}
