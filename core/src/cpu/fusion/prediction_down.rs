// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/prediction_down.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::prediction_down::PredictionDownParams;

/// Downsamples the predicted vertex and normal maps as the kernel's invocations do.
pub fn prediction_down(params: &PredictionDownParams, vertex_fine: &[[f32; 4]], normal_fine: &[[f32; 4]], vertex_coarse: &mut [[f32; 4]], normal_coarse: &mut [[f32; 4]]) {
    let w = params.src_width_px;
    for gy in 0..params.dst_height_px {
        for gx in 0..params.dst_width_px {
            let out = (gy * params.dst_width_px + gx) as usize;
            let x = (2 * gx).min(params.src_width_px - 2);
            let y = (2 * gy).min(params.src_height_px - 2);
            let mut v = [0.0f32; 3];
            let mut n = [0.0f32; 3];
            let mut valid = true;
            for i in 0..4u32 {
                let ix = ((y + (i >> 1)) * w + x + (i & 1)) as usize;
                let (vi, ni) = (vertex_fine[ix], normal_fine[ix]);
                if !is_valid_f32(vi[0]) || !is_valid_f32(ni[0]) {
                    valid = false;
                    break;
                }
                for c in 0..3 {
                    v[c] += vi[c];
                    n[c] += ni[c];
                }
            }
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if !valid || !(len > 1e-6) {
                vertex_coarse[out] = INVALID_VEC4;
                normal_coarse[out] = INVALID_VEC4;
                continue;
            }
            vertex_coarse[out] = [0.25 * v[0], 0.25 * v[1], 0.25 * v[2], 1.0];
            normal_coarse[out] = [n[0] / len, n[1] / len, n[2] / len, 0.0];
        }
    }
}
