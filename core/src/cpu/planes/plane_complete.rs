// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_complete.wgsl`.

use crate::cpu::shared::{is_valid_f32, kinect_sigma_m};
use crate::kernels::plane_complete::PlaneCompleteParams;
use crate::planes::NO_LABEL;

/// Completes every pixel's label as the kernel's invocations do.
pub fn plane_complete(params: &PlaneCompleteParams, depth_m: &[f32], labels_in: &[u32], planes: &[[f32; 4]], plane_count: &[u32], labels_out: &mut [u32]) {
    let (w, h) = (params.width_px as i64, params.height_px as i64);
    let r = i64::from(params.reach_px);
    let count = plane_count[0];
    for y in 0..h {
        for x in 0..w {
            let ix = (y * w + x) as usize;
            let own = labels_in[ix];
            labels_out[ix] = own;
            let z = depth_m[ix];
            if own != NO_LABEL || !is_valid_f32(z) || !(z > 0.0) {
                continue;
            }
            let p = [(x as f32 - params.cx_px) / params.fx_px * z, (y as f32 - params.cy_px) / params.fy_px * z, z];
            let tolerance = params.min_distance_m.max(3.0 * kinect_sigma_m(z));
            let (mut best, mut best_e) = (NO_LABEL, 0.0f32);
            for v in (y - r).max(0)..=(y + r).min(h - 1) {
                for u in (x - r).max(0)..=(x + r).min(w - 1) {
                    let m = labels_in[(v * w + u) as usize];
                    if m == NO_LABEL || m >= count {
                        continue;
                    }
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
