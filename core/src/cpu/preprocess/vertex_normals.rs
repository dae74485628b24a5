// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/preprocess/vertex_normals.wgsl`.

use super::vertex_gradients::central_differences;
use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::vertex_normals::VertexNormalsParams;

/// Computes every normal as one invocation of the kernel does (`grad_x` and `grad_y` are read
/// only when `params.radius_px > 0`).
pub fn vertex_normals(params: &VertexNormalsParams, vertex_in_camera: &[[f32; 4]], grad_x: &[[f32; 4]], grad_y: &[[f32; 4]], normal_in_camera: &mut [[f32; 4]]) {
    let (w, h) = (params.width_px, params.height_px);
    let r = params.radius_px as i32;
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let ix = (y * w as i32 + x) as usize;
            let v = vertex_in_camera[ix];
            let (a, b) = if r == 0 {
                match central_differences(w, h, vertex_in_camera, x, y) {
                    Some(pair) => pair,
                    None => {
                        normal_in_camera[ix] = INVALID_VEC4;
                        continue;
                    }
                }
            } else {
                if !is_valid_f32(v[2]) || !is_valid_f32(grad_x[ix][0]) {
                    normal_in_camera[ix] = INVALID_VEC4;
                    continue;
                }
                let mut sum_w = 0.0f32;
                let (mut a, mut b) = ([0.0f32; 3], [0.0f32; 3]);
                for j in -r..=r {
                    let ty = y + j;
                    if ty < 0 || ty >= h as i32 {
                        continue;
                    }
                    let tap = (ty * w as i32 + x) as usize;
                    let gx = grad_x[tap];
                    if !is_valid_f32(gx[0]) {
                        continue;
                    }
                    let gy = grad_y[tap];
                    let wt = if j == 0 { 1.0 } else { ((j * j) as f32 * k).exp() };
                    sum_w += wt;
                    for c in 0..3 {
                        a[c] += wt * gx[c];
                        b[c] += wt * gy[c];
                    }
                }
                (a.map(|s| s / sum_w), b.map(|s| s / sum_w))
            };
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
