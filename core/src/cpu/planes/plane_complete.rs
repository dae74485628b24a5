// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_complete.wgsl`.

use crate::cpu::shared::{is_valid_f32, kinect_sigma_m};
use crate::kernels::plane_complete::PlaneCompleteParams;
use crate::planes::NO_LABEL;

/// Completes every pixel's label as the kernel's invocations do.
pub fn plane_complete(params: &PlaneCompleteParams, depth_m: &[f32], labels_in: &[u32], window: &[[u32; 2]], planes: &[[f32; 4]], labels_out: &mut [u32]) {
    let (w, h) = (params.width_px as usize, params.height_px as usize);
    for y in 0..h {
        for x in 0..w {
            let ix = y * w + x;
            let own = labels_in[ix];
            labels_out[ix] = own;
            let z = depth_m[ix];
            let candidates = window[ix];
            if own != NO_LABEL || !is_valid_f32(z) || !(z > 0.0) || candidates == [0, 0] {
                continue;
            }
            let p = [(x as f32 - params.cx_px) / params.fx_px * z, (y as f32 - params.cy_px) / params.fy_px * z, z];
            let tolerance = params.min_distance_m.max(3.0 * kinect_sigma_m(z));
            let (mut best, mut best_e) = (NO_LABEL, 0.0f32);
            for word in 0..2u32 {
                let mut bits = candidates[word as usize];
                while bits != 0 {
                    let m = word * 32 + bits.trailing_zeros();
                    bits &= bits - 1;
                    let plane = planes[m as usize];
                    let np = plane[0] * p[0] + plane[1] * p[1] + plane[2] * p[2];
                    if !(np < 0.0) {
                        continue;
                    }
                    let e = (z * (np + plane[3]) / np).abs();
                    if e <= tolerance && (best == NO_LABEL || e < best_e) {
                        (best, best_e) = (m, e);
                    }
                }
            }
            labels_out[ix] = best;
        }
    }
}
