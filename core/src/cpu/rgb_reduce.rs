// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/rgb_reduce.wgsl`: the same per-thread walk and tree
//! reduction as the kernel.

use super::shared::{cross3, is_valid_f32, transform_point, transform_vector};
use crate::kernels::icp_reduce::{SUM_FLOATS, WORKGROUP_SIZE};
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
    let workgroups = params.thread_count.div_ceil(WORKGROUP_SIZE);
    for wid in 0..workgroups {
        let mut scratch = vec![[0.0f32; SUM_FLOATS]; WORKGROUP_SIZE as usize];
        for lid in 0..WORKGROUP_SIZE {
            let acc = &mut scratch[lid as usize];
            let mut ix = wid * WORKGROUP_SIZE + lid;
            while ix < pixel_count {
                let row = rgb_row(params, ix as usize, vertex_in_camera, intensity, prev_intensity, prev_depth_m);
                ix += params.thread_count;
                let Some([j0, j1, j2, j3, j4, j5, r]) = row else { continue };
                let terms = [
                    j0 * j0, j0 * j1, j0 * j2, j0 * j3, j0 * j4, j0 * j5, j1 * j1, j1 * j2, j1 * j3, j1 * j4, j1 * j5, j2 * j2, j2 * j3, j2 * j4, j2 * j5, j3 * j3,
                    j3 * j4, j3 * j5, j4 * j4, j4 * j5, j5 * j5, j0 * r, j1 * r, j2 * r, j3 * r, j4 * r, j5 * r, r * r, 1.0,
                ];
                for (a, t) in acc.iter_mut().zip(terms) {
                    *a += t;
                }
            }
        }
        let mut stride = WORKGROUP_SIZE / 2;
        while stride > 0 {
            for lid in 0..stride as usize {
                for i in 0..SUM_FLOATS {
                    scratch[lid][i] += scratch[lid + stride as usize][i];
                }
            }
            stride >>= 1;
        }
        partial_sums[wid as usize * SUM_FLOATS..][..SUM_FLOATS].copy_from_slice(&scratch[0]);
    }
}
