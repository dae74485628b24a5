// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/vertex_gradients.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::vertex_gradients::VertexGradientsParams;

/// Differentiates every pixel as one invocation of the kernel does.
pub fn vertex_gradients(params: &VertexGradientsParams, vertex_in_camera: &[[f32; 4]], grad_x: &mut [[f32; 4]], grad_y: &mut [[f32; 4]]) {
    let w = params.width_px;
    let h = params.height_px;
    for gy in 0..h {
        for gx in 0..w {
            let ix = (gy * w + gx) as usize;
            if gx == 0 || gy == 0 || gx + 1 == w || gy + 1 == h {
                grad_x[ix] = INVALID_VEC4;
                grad_y[ix] = INVALID_VEC4;
                continue;
            }
            let centre = vertex_in_camera[ix];
            let left = vertex_in_camera[ix - 1];
            let right = vertex_in_camera[ix + 1];
            let up = vertex_in_camera[ix - w as usize];
            let down = vertex_in_camera[ix + w as usize];
            if !is_valid_f32(centre[2]) || !is_valid_f32(left[2]) || !is_valid_f32(right[2]) || !is_valid_f32(up[2]) || !is_valid_f32(down[2]) {
                grad_x[ix] = INVALID_VEC4;
                grad_y[ix] = INVALID_VEC4;
                continue;
            }
            grad_x[ix] = [right[0] - left[0], right[1] - left[1], right[2] - left[2], 0.0];
            grad_y[ix] = [down[0] - up[0], down[1] - up[1], down[2] - up[2], 0.0];
        }
    }
}
