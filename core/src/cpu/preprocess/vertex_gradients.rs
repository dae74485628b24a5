// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/preprocess/vertex_gradients.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::vertex_gradients::VertexGradientsParams;

/// The central differences at pixel (x, y), as the kernel's `central_differences`.
pub(crate) fn central_differences(width_px: u32, height_px: u32, vertex_in_camera: &[[f32; 4]], x: i32, y: i32) -> Option<([f32; 3], [f32; 3])> {
    let (w, h) = (width_px as i32, height_px as i32);
    if x < 1 || y < 1 || x + 1 >= w || y + 1 >= h {
        return None;
    }
    let ix = (y * w + x) as usize;
    let [centre, left, right, up, down] = [ix, ix - 1, ix + 1, ix - w as usize, ix + w as usize].map(|i| vertex_in_camera[i]);
    if [centre, left, right, up, down].iter().any(|v| !is_valid_f32(v[2])) {
        return None;
    }
    Some(([right[0] - left[0], right[1] - left[1], right[2] - left[2]], [down[0] - up[0], down[1] - up[1], down[2] - up[2]]))
}

/// Differentiates and smooths along x every pixel as one invocation of the kernel does.
pub fn vertex_gradients(params: &VertexGradientsParams, vertex_in_camera: &[[f32; 4]], grad_x: &mut [[f32; 4]], grad_y: &mut [[f32; 4]]) {
    let (w, h) = (params.width_px, params.height_px);
    let r = params.radius_px as i32;
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let ix = (y * w as i32 + x) as usize;
            if central_differences(w, h, vertex_in_camera, x, y).is_none() {
                grad_x[ix] = INVALID_VEC4;
                grad_y[ix] = INVALID_VEC4;
                continue;
            }
            let mut sum_w = 0.0f32;
            let (mut sx, mut sy) = ([0.0f32; 3], [0.0f32; 3]);
            for i in -r..=r {
                let Some((gx, gy)) = central_differences(w, h, vertex_in_camera, x + i, y) else { continue };
                let wt = if i == 0 { 1.0 } else { ((i * i) as f32 * k).exp() };
                sum_w += wt;
                for c in 0..3 {
                    sx[c] += wt * gx[c];
                    sy[c] += wt * gy[c];
                }
            }
            grad_x[ix] = [sx[0] / sum_w, sx[1] / sum_w, sx[2] / sum_w, 0.0];
            grad_y[ix] = [sy[0] / sum_w, sy[1] / sum_w, sy[2] / sum_w, 0.0];
        }
    }
}
