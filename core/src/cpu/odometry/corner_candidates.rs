// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/corner_candidates.wgsl`.

use super::keypoint_depth::{keypoint_depth_pixel, same_surface_step_m};
use crate::cpu::shared::is_valid_f32;
use crate::kernels::corner_candidates::CornerCandidatesParams;

fn is_local_max(params: &CornerCandidatesParams, score: &[f32], x: u32, y: u32, s: f32) -> bool {
    let w = params.width_px;
    let ix = y * w + x;
    for dy in -1i32..=1 {
        for dx in -1i32..=1 {
            let (u, v) = (x as i32 + dx, y as i32 + dy);
            if (dx == 0 && dy == 0) || u < 0 || v < 0 || u >= w as i32 || v >= params.height_px as i32 {
                continue;
            }
            let q = v as u32 * w + u as u32;
            let t = score[q as usize];
            if t > s || (t == s && q < ix) {
                return false;
            }
        }
    }
    true
}

fn depth_window_ok(params: &CornerCandidatesParams, depth_m: &[f32], x0: f32, y0: f32) -> bool {
    let (w, h) = (params.depth_width_px as i32, params.depth_height_px as i32);
    let (u, v) = keypoint_depth_pixel(x0, y0, w, h);
    let z = depth_m[(v * w + u) as usize];
    if !is_valid_f32(z) || !(z > 0.0) {
        return false;
    }
    let step = same_surface_step_m(z, params.fx_px);
    let mut missing = 0u32;
    for dy in -1..=1 {
        for dx in -1..=1 {
            let n = depth_m[((v + dy) * w + u + dx) as usize];
            if !is_valid_f32(n) || !(n > 0.0) {
                missing += 1;
            } else if (n - z).abs() > step {
                return false;
            }
        }
    }
    missing < 3
}

/// Marks every pixel's candidacy as one invocation of the kernel does.
pub fn corner_candidates(params: &CornerCandidatesParams, score: &[f32], depth_m: &[f32], candidate: &mut [f32]) {
    let scale = (1u32 << params.level) as f32;
    for y in 0..params.height_px {
        for x in 0..params.width_px {
            let ix = (y * params.width_px + x) as usize;
            let s = score[ix];
            let keep = s > 0.0 && is_local_max(params, score, x, y, s) && depth_window_ok(params, depth_m, (x as f32 + 0.5) * scale - 0.5, (y as f32 + 0.5) * scale - 0.5);
            candidate[ix] = if keep { s } else { 0.0 };
        }
    }
}
