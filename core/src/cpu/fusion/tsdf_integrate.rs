// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/tsdf_integrate.wgsl`.

use crate::cpu::shared::{is_valid_f32, pack_rgb8, pack_voxel, transform_point, unpack_rgb8, voxel_centre_in_world, voxel_index, voxel_tsdf, voxel_weight};
use crate::kernels::tsdf_integrate::TsdfIntegrateParams;

/// Updates every voxel as one invocation of the kernel does.
pub fn tsdf_integrate(params: &TsdfIntegrateParams, depth_m: &[f32], color: &[[f32; 4]], tsdf_volume: &mut [u32], color_volume: &mut [u32]) {
    let d = &params.volume;
    for gz in 0..d.dim_z {
        for gy in 0..d.dim_y {
            for gx in 0..d.dim_x {
                let p_world = voxel_centre_in_world(d, gx, gy, gz);
                let p_cam = transform_point(&params.camera_from_world, p_world);
                if !(p_cam[2] > 0.0) {
                    continue;
                }
                let k = &params.intrinsics;
                let u = (k.fx_px * p_cam[0] / p_cam[2] + k.cx_px + 0.5).floor();
                let v = (k.fy_px * p_cam[1] / p_cam[2] + k.cy_px + 0.5).floor();
                if !(u >= 0.0 && v >= 0.0 && u < k.width_px as f32 && v < k.height_px as f32) {
                    continue;
                }
                let pixel = (v as u32 * k.width_px + u as u32) as usize;
                let depth = depth_m[pixel];
                if !is_valid_f32(depth) {
                    continue;
                }
                let sdf = depth - p_cam[2];
                if sdf < -d.truncation_m {
                    continue;
                }
                let tsdf = (sdf / d.truncation_m).min(1.0);
                let ix = voxel_index(d, gx, gy, gz) as usize;
                let word = tsdf_volume[ix];
                let w = voxel_weight(word);
                let updated = (voxel_tsdf(word) * w as f32 + tsdf) / (w + 1) as f32;
                tsdf_volume[ix] = pack_voxel(updated, (w + 1).min(d.max_weight));
                if params.color_enabled != 0 && tsdf < 1.0 {
                    let c_old = unpack_rgb8(color_volume[ix]);
                    let c = color[pixel];
                    let c_new: [f32; 3] = std::array::from_fn(|i| (c_old[i] * w as f32 + c[i]) / (w + 1) as f32);
                    color_volume[ix] = pack_rgb8(c_new);
                }
            }
        }
    }
}
