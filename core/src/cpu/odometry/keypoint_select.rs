// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/keypoint_select.wgsl`.

use super::keypoint_depth::{keypoint_depth_pixel, same_surface_step_m};
use crate::cpu::shared::{INVALID_VEC4, is_valid_f32};
use crate::kernels::keypoint_select::KeypointSelectParams;

/// Twin of the kernel's `MAX_PER_CELL`.
pub const MAX_PER_CELL: u32 = 8;

/// The point at level-0 position (x0, y0) of a candidate (its centre depth valid).
fn keypoint_point(params: &KeypointSelectParams, depth_m: &[f32], x0: f32, y0: f32) -> [f32; 4] {
    let (w, h) = (params.depth_width_px as i32, params.depth_height_px as i32);
    let (u, v) = keypoint_depth_pixel(x0, y0, w, h);
    let z = depth_m[(v * w + u) as usize];
    let step = same_surface_step_m(z, params.fx_px);
    // The depth along the ray: the tent filter of radius 2 px about (x0, y0).
    let (bx, by) = (x0.floor() as i32 - 1, y0.floor() as i32 - 1);
    let (mut sum, mut weight) = (0.0f32, 0.0f32);
    for j in 0..4 {
        for i in 0..4 {
            let (px, py) = ((bx + i).clamp(0, w - 1), (by + j).clamp(0, h - 1));
            let wt = (2.0 - ((bx + i) as f32 - x0).abs()).max(0.0) * (2.0 - ((by + j) as f32 - y0).abs()).max(0.0);
            let n = depth_m[(py * w + px) as usize];
            if wt > 0.0 && is_valid_f32(n) && n > 0.0 && (n - z).abs() <= step {
                sum += wt * n;
                weight += wt;
            }
        }
    }
    let zm = sum / weight;
    [(x0 - params.cx_px) / params.fx_px * zm, (y0 - params.cy_px) / params.fy_px * zm, zm, 1.0]
}

/// Selects every cell's keypoints among the candidates `score` (`corner_candidates`) as the
/// kernel's invocations do.
pub fn keypoint_select(params: &KeypointSelectParams, score: &[f32], depth_m: &[f32], keypoints: &mut [[f32; 4]], points: &mut [[f32; 4]]) {
    let k = params.per_cell.min(MAX_PER_CELL);
    let scale = (1u32 << params.level) as f32;
    for cell in 0..params.cells_x * params.cells_y {
        let mut best_score = [0.0f32; MAX_PER_CELL as usize];
        let mut best_pixel = [0u32; MAX_PER_CELL as usize];
        let mut kept = 0u32;
        let x_begin = (cell % params.cells_x) * params.cell_px;
        let y_begin = (cell / params.cells_x) * params.cell_px;
        let x_end = (x_begin + params.cell_px).min(params.width_px);
        let y_end = (y_begin + params.cell_px).min(params.height_px);
        for y in y_begin..y_end {
            for x in x_begin..x_end {
                let s = score[(y * params.width_px + x) as usize];
                if !(s > 0.0) || (kept == k && !(s > best_score[(k - 1) as usize])) {
                    continue;
                }
                let mut at = kept.min(k - 1) as usize;
                if kept < k {
                    kept += 1;
                }
                while at > 0 && best_score[at - 1] < s {
                    best_score[at] = best_score[at - 1];
                    best_pixel[at] = best_pixel[at - 1];
                    at -= 1;
                }
                best_score[at] = s;
                best_pixel[at] = y * params.width_px + x;
            }
        }
        for i in 0..k {
            let slot = (params.slot_offset + cell * k + i) as usize;
            if i < kept {
                let px = best_pixel[i as usize];
                let (x, y) = (px % params.width_px, px / params.width_px);
                keypoints[slot] = [x as f32, y as f32, params.level as f32, best_score[i as usize]];
                points[slot] = keypoint_point(params, depth_m, (x as f32 + 0.5) * scale - 0.5, (y as f32 + 0.5) * scale - 0.5);
            } else {
                keypoints[slot] = [0.0, 0.0, params.level as f32, 0.0];
                points[slot] = INVALID_VEC4;
            }
        }
    }
}
