// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/gradient_smooth.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::gradient_smooth::GradientSmoothParams;

/// Smooths every pixel as one invocation of the kernel does.
pub fn gradient_smooth(
    params: &GradientSmoothParams,
    grad_x_in: &[[f32; 4]],
    grad_y_in: &[[f32; 4]],
    grad_x_out: &mut [[f32; 4]],
    grad_y_out: &mut [[f32; 4]],
) {
    let w = params.width_px;
    let h = params.height_px;
    let radius = params.radius_px as i32;
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    for gy in 0..h {
        for gx in 0..w {
            let ix = (gy * w + gx) as usize;
            if !is_valid_f32(grad_x_in[ix][0]) {
                grad_x_out[ix] = INVALID_VEC4;
                grad_y_out[ix] = INVALID_VEC4;
                continue;
            }
            let along = if params.axis == 1 { gy } else { gx } as i32;
            let extent = if params.axis == 1 { h } else { w } as i32;
            let mut sum_w = 0.0f32;
            let mut sum_x = [0.0f32; 3];
            let mut sum_y = [0.0f32; 3];
            for i in -radius..=radius {
                let p = along + i;
                if p < 0 || p >= extent {
                    continue;
                }
                let tap_ix = if params.axis == 0 { gy * w + p as u32 } else { p as u32 * w + gx } as usize;
                let tx = grad_x_in[tap_ix];
                if !is_valid_f32(tx[0]) {
                    continue;
                }
                let ty = grad_y_in[tap_ix];
                let wt = ((i * i) as f32 * k).exp();
                sum_w += wt;
                for c in 0..3 {
                    sum_x[c] += wt * tx[c];
                    sum_y[c] += wt * ty[c];
                }
            }
            grad_x_out[ix] = [sum_x[0] / sum_w, sum_x[1] / sum_w, sum_x[2] / sum_w, 0.0];
            grad_y_out[ix] = [sum_y[0] / sum_w, sum_y[1] / sum_w, sum_y[2] / sum_w, 0.0];
        }
    }
}
