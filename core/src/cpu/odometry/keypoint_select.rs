// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/keypoint_select.wgsl`.

use crate::cpu::shared::{INVALID_VEC4, is_valid_f32, kinect_sigma_m};
use crate::kernels::keypoint_select::KeypointSelectParams;

/// Twin of the kernel's `MAX_PER_CELL`.
pub const MAX_PER_CELL: u32 = 8;

fn is_local_max(params: &KeypointSelectParams, score: &[f32], x: u32, y: u32, s: f32) -> bool {
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

fn filtered_point(params: &KeypointSelectParams, depth_m: &[f32], x0: f32, y0: f32) -> [f32; 4] {
    let (w, h) = (params.depth_width_px as i32, params.depth_height_px as i32);
    let u = ((x0 + 0.5).floor() as i32).clamp(1, w - 2);
    let v = ((y0 + 0.5).floor() as i32).clamp(1, h - 2);
    let z = depth_m[(v * w + u) as usize];
    if !is_valid_f32(z) || !(z > 0.0) {
        return INVALID_VEC4;
    }
    let step = 4.0 * kinect_sigma_m(z) + 2.0 * z / params.fx_px;
    let mut missing = 0u32;
    for dy in -1..=1 {
        for dx in -1..=1 {
            let n = depth_m[((v + dy) * w + u + dx) as usize];
            if !is_valid_f32(n) || !(n > 0.0) {
                missing += 1;
            } else if (n - z).abs() > step {
                return INVALID_VEC4;
            }
        }
    }
    if missing >= 3 {
        return INVALID_VEC4;
    }
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

/// Selects every cell's keypoints as the kernel's invocations do.
pub fn keypoint_select(params: &KeypointSelectParams, score: &[f32], depth_m: &[f32], keypoints: &mut [[f32; 4]], points: &mut [[f32; 4]]) {
    let k = params.per_cell.min(MAX_PER_CELL);
    let scale = (1u32 << params.level) as f32;
    for cell in 0..params.cells_x * params.cells_y {
        let mut best_score = [0.0f32; MAX_PER_CELL as usize];
        let mut best_pixel = [0u32; MAX_PER_CELL as usize];
        let mut best_point = [[0.0f32; 4]; MAX_PER_CELL as usize];
        let mut kept = 0u32;
        let x_begin = (cell % params.cells_x) * params.cell_px;
        let y_begin = (cell / params.cells_x) * params.cell_px;
        let x_end = (x_begin + params.cell_px).min(params.width_px);
        let y_end = (y_begin + params.cell_px).min(params.height_px);
        for y in y_begin..y_end {
            for x in x_begin..x_end {
                let s = score[(y * params.width_px + x) as usize];
                if !(s > 0.0) || (kept == k && !(s > best_score[(k - 1) as usize])) || !is_local_max(params, score, x, y, s) {
                    continue;
                }
                let p = filtered_point(params, depth_m, (x as f32 + 0.5) * scale - 0.5, (y as f32 + 0.5) * scale - 0.5);
                if !is_valid_f32(p[2]) {
                    continue;
                }
                let mut at = kept.min(k - 1) as usize;
                if kept < k {
                    kept += 1;
                }
                while at > 0 && best_score[at - 1] < s {
                    best_score[at] = best_score[at - 1];
                    best_pixel[at] = best_pixel[at - 1];
                    best_point[at] = best_point[at - 1];
                    at -= 1;
                }
                best_score[at] = s;
                best_pixel[at] = y * params.width_px + x;
                best_point[at] = p;
            }
        }
        for i in 0..k {
            let slot = (params.slot_offset + cell * k + i) as usize;
            if i < kept {
                let px = best_pixel[i as usize];
                keypoints[slot] = [(px % params.width_px) as f32, (px / params.width_px) as f32, params.level as f32, best_score[i as usize]];
                points[slot] = best_point[i as usize];
            } else {
                keypoints[slot] = [0.0, 0.0, params.level as f32, 0.0];
                points[slot] = INVALID_VEC4;
            }
        }
    }
}
