// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_label.wgsl`.

use crate::cpu::shared::{is_valid_f32, kinect_sigma_m};
use crate::kernels::plane_label::PlaneLabelParams;
use crate::planes::NO_LABEL;

/// Labels every pixel as the kernel's invocations do.
pub fn plane_label(params: &PlaneLabelParams, vertex_in_camera: &[[f32; 4]], normal_in_camera: &[[f32; 4]], planes: &[[f32; 4]], plane_count: &[u32], labels: &mut [u32]) {
    let dot = |a: [f32; 4], b: [f32; 4]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    for ix in 0..params.pixel_count as usize {
        labels[ix] = NO_LABEL;
        let (p, n) = (vertex_in_camera[ix], normal_in_camera[ix]);
        if !is_valid_f32(p[2]) || !(p[2] > 0.0) || !is_valid_f32(n[0]) {
            continue;
        }
        let tolerance = params.min_distance_m.max(3.0 * kinect_sigma_m(p[2]));
        let (mut best, mut best_r) = (NO_LABEL, tolerance);
        for k in 0..plane_count[0] as usize {
            let plane = planes[k];
            let r = (dot(plane, p) + plane[3]).abs();
            if dot(n, plane).abs() >= params.cos_label && r < best_r {
                (best, best_r) = (k as u32, r);
            }
        }
        labels[ix] = best;
    }
}
