// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/normal_map.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::normal_map::NormalMapParams;

/// Computes every normal as one invocation of the kernel does.
pub fn normal_map(params: &NormalMapParams, vertex_in_camera: &[[f32; 4]], grad_x: &[[f32; 4]], grad_y: &[[f32; 4]], normal_in_camera: &mut [[f32; 4]]) {
    for gy in 0..params.height_px {
        for gx in 0..params.width_px {
            let ix = (gy * params.width_px + gx) as usize;
            let v = vertex_in_camera[ix];
            let a = grad_x[ix];
            let b = grad_y[ix];
            if !is_valid_f32(v[2]) || !is_valid_f32(a[0]) || !is_valid_f32(b[0]) {
                normal_in_camera[ix] = INVALID_VEC4;
                continue;
            }
            let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            let norm_sq = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
            if !(norm_sq > params.min_cross_norm_sq) {
                normal_in_camera[ix] = INVALID_VEC4;
                continue;
            }
            let len = norm_sq.sqrt();
            let mut n = [c[0] / len, c[1] / len, c[2] / len];
            if n[0] * v[0] + n[1] * v[1] + n[2] * v[2] > 0.0 {
                n = [-n[0], -n[1], -n[2]];
            }
            normal_in_camera[ix] = [n[0], n[1], n[2], 0.0];
        }
    }
}
