// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/distance_histogram.wgsl`.

use crate::cpu::shared::is_valid_f32;
use crate::kernels::distance_histogram::DistanceHistogramParams;
use crate::planes::{DISTANCE_BINS, NO_LABEL};

/// Per pixel of `assignment`: no peak within the angle (or not free, or out of range).
pub const NO_ASSIGNMENT: u32 = u32::MAX;
/// Fixed-point scale of the normal sums.
pub const NORMAL_SUM_SCALE: f32 = 16384.0;

/// Assigns and counts every pixel as the kernel's invocations do.
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order")]
pub fn distance_histogram(
    params: &DistanceHistogramParams,
    vertex_in_camera: &[[f32; 4]],
    normal_in_camera: &[[f32; 4]],
    labels: &[u32],
    peaks: &[[f32; 4]],
    peak_count: &[u32],
    assignment: &mut [u32],
    histogram: &mut [u32],
    normal_sums: &mut [i32],
) {
    let dot = |a: [f32; 4], b: [f32; 4]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    for y in 0..params.height_px {
        for x in 0..params.width_px {
            let ix = (y * params.width_px + x) as usize;
            assignment[ix] = NO_ASSIGNMENT;
            let (p, n) = (vertex_in_camera[ix], normal_in_camera[ix]);
            if !is_valid_f32(p[2]) || !(p[2] > 0.0) || !is_valid_f32(n[0]) {
                continue;
            }
            if params.use_labels != 0 && labels[((y << params.level_shift) * params.full_width_px + (x << params.level_shift)) as usize] != NO_LABEL {
                continue;
            }
            let (mut best, mut best_cos) = (0usize, -1.0f32);
            for k in 0..peak_count[0] as usize {
                let c = dot(n, peaks[k]).abs();
                if c > best_cos {
                    (best, best_cos) = (k, c);
                }
            }
            if best_cos < params.cos_segment {
                continue;
            }
            let pk = peaks[best];
            let bin = (dot(pk, p).abs() / params.bin_m) as usize;
            if bin >= DISTANCE_BINS {
                continue;
            }
            histogram[best * DISTANCE_BINS + bin] += 1;
            let side = if dot(n, pk) < 0.0 { -1.0 } else { 1.0 };
            for i in 0..3 {
                normal_sums[4 * best + i] += (side * n[i] * NORMAL_SUM_SCALE).round_ties_even() as i32;
            }
            assignment[ix] = ((best as u32) << 16) | bin as u32;
        }
    }
}
