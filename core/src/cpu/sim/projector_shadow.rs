// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/sim/projector_shadow.wgsl`.

use crate::cpu::shared::is_valid_f32;
use crate::kernels::projector_shadow::ProjectorShadowParams;

/// Per pixel of `depth_m`, 1 where the projector's light is blocked, else 0.
pub fn projector_shadow(params: &ProjectorShadowParams, depth_m: &[f32]) -> Vec<u32> {
    let k = &params.intrinsics;
    let (w, h) = (k.width_px, k.height_px);
    let mut shadow = vec![0u32; (w * h) as usize];
    let bf = params.baseline_m * k.fx_px;
    let towards_positive = params.baseline_m > 0.0;
    for row in 0..h {
        let mut extreme = if towards_positive { 3.0e38f32 } else { -3.0e38f32 };
        for i in 0..w {
            let u = if towards_positive { w - 1 - i } else { i };
            let ix = (row * w + u) as usize;
            let z = depth_m[ix];
            if !is_valid_f32(z) {
                shadow[ix] = 0;
                continue;
            }
            let p = u as f32 - bf / z;
            let dark = if towards_positive {
                let d = p - extreme > params.edge_disparity_px;
                extreme = extreme.min(p);
                d
            } else {
                let d = extreme - p > params.edge_disparity_px;
                extreme = extreme.max(p);
                d
            };
            shadow[ix] = u32::from(dark);
        }
    }
    shadow
}
