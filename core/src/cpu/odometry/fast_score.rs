// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/fast_score.wgsl`.

use crate::cpu::shared::{FAST_ARC, fast_circle_offset};
use crate::kernels::fast_score::FastScoreParams;

/// Scores every pixel as the kernel's invocations do.
pub fn fast_score(params: &FastScoreParams, intensity: &[f32], score: &mut [f32]) {
    let (w, h, b) = (params.width_px, params.height_px, params.border_px);
    for y in 0..h {
        for x in 0..w {
            let ix = (y * w + x) as usize;
            if x < b || y < b || x + b >= w || y + b >= h {
                score[ix] = 0.0;
                continue;
            }
            let centre = intensity[ix];
            let (mut brighter_compass, mut darker_compass) = (0u32, 0u32);
            for k in (0..16).step_by(4) {
                let o = fast_circle_offset(k);
                let d = intensity[((y as i32 + o[1]) as u32 * w + (x as i32 + o[0]) as u32) as usize] - centre;
                brighter_compass += u32::from(d > params.threshold);
                darker_compass += u32::from(-d > params.threshold);
            }
            if brighter_compass < 2 && darker_compass < 2 {
                score[ix] = 0.0;
                continue;
            }
            let mut ring = [0.0f32; 16];
            for (k, r) in ring.iter_mut().enumerate() {
                let o = fast_circle_offset(k as u32);
                let q = ((y as i32 + o[1]) as u32 * w + (x as i32 + o[0]) as u32) as usize;
                *r = intensity[q] - centre;
            }
            // Every arc's minimum, arc by arc (the kernel gets the same minima by doubling:
            // min is exact, so the two agree bit for bit).
            let mut best = 0.0f32;
            for start in 0..16u32 {
                let (mut brighter, mut darker) = (1.0e9f32, 1.0e9f32);
                for j in 0..FAST_ARC {
                    let d = ring[((start + j) & 15) as usize];
                    brighter = brighter.min(d);
                    darker = darker.min(-d);
                }
                best = best.max(brighter.max(darker));
            }
            score[ix] = if best > params.threshold { best } else { 0.0 };
        }
    }
}
