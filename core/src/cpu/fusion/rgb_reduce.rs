// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/rgb_reduce.wgsl`: the same per-thread walk and tree
//! reduction as the kernel.

use crate::cpu::shared::{cross3, is_valid_f32, reduce_normal_equations, transform_point, transform_vector};
use crate::kernels::rgb_reduce::RgbReduceParams;

fn prev_bilinear(params: &RgbReduceParams, prev_intensity: &[f32], x: f32, y: f32) -> f32 {
    let w = params.intrinsics.width_px as usize;
    let (x0, y0) = (x as u32 as usize, y as u32 as usize);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let i = y0 * w + x0;
    let top = prev_intensity[i] * (1.0 - fx) + prev_intensity[i + 1] * fx;
    let bottom = prev_intensity[i + w] * (1.0 - fx) + prev_intensity[i + w + 1] * fx;
    top * (1.0 - fy) + bottom * fy
}

/// One pixel's photometric row `[J (6), r]` (the kernel's loop body), `None` when rejected.
pub fn rgb_row(params: &RgbReduceParams, ix: usize, vertex_in_camera: &[[f32; 4]], intensity: &[f32], prev_intensity: &[f32], prev_depth_m: &[f32]) -> Option<[f32; 7]> {
    let k = &params.intrinsics;
    let v_cam = vertex_in_camera[ix];
    if !is_valid_f32(v_cam[2]) {
        return None;
    }
    let p = transform_point(&params.world_from_camera, [v_cam[0], v_cam[1], v_cam[2]]);
    let q = transform_point(&params.camera_prev_from_world, p);
    if !(q[2] > 0.0) {
        return None;
    }
    let u = k.fx_px * q[0] / q[2] + k.cx_px;
    let w = k.fy_px * q[1] / q[2] + k.cy_px;
    if !(u >= 1.0 && w >= 1.0 && u < k.width_px as f32 - 2.0 && w < k.height_px as f32 - 2.0) {
        return None;
    }
    let nearest = ((w + 0.5) as u32 * k.width_px + (u + 0.5) as u32) as usize;
    let z_prev = prev_depth_m[nearest];
    if !is_valid_f32(z_prev) || !((z_prev - q[2]).abs() <= params.max_depth_diff_m) {
        return None;
    }
    let r = prev_bilinear(params, prev_intensity, u, w) - intensity[ix];
    if !(r.abs() <= params.max_residual) {
        return None;
    }
    let gx = 0.5 * (prev_bilinear(params, prev_intensity, u + 1.0, w) - prev_bilinear(params, prev_intensity, u - 1.0, w));
    let gy = 0.5 * (prev_bilinear(params, prev_intensity, u, w + 1.0) - prev_bilinear(params, prev_intensity, u, w - 1.0));
    let inv_z = 1.0 / q[2];
    let gp = [gx * k.fx_px * inv_z, gy * k.fy_px * inv_z, -(gx * k.fx_px * q[0] + gy * k.fy_px * q[1]) * inv_z * inv_z];
    let gw = transform_vector(&params.world_from_camera_prev, gp);
    let a = cross3(p, gw);
    Some([a[0], a[1], a[2], gw[0], gw[1], gw[2], r])
}

/// Fills `partial_sums` (one block of `SUM_FLOATS` per workgroup) as the kernel does.
pub fn rgb_reduce(params: &RgbReduceParams, vertex_in_camera: &[[f32; 4]], intensity: &[f32], prev_intensity: &[f32], prev_depth_m: &[f32], partial_sums: &mut [f32]) {
    let pixel_count = params.intrinsics.width_px * params.intrinsics.height_px;
    reduce_normal_equations(params.thread_count, pixel_count, partial_sums, |ix| rgb_row(params, ix, vertex_in_camera, intensity, prev_intensity, prev_depth_m));
}
