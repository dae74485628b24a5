// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/normal_histogram.wgsl`.

use crate::cpu::shared::is_valid_f32;
use crate::kernels::normal_histogram::NormalHistogramParams;
use crate::planes::{NO_LABEL, NORMAL_BINS};

/// `normal_bin_1d()`: the bin of one normal component on [-1, 1].
pub fn normal_bin_1d(c: f32) -> usize {
    ((c.clamp(-1.0, 1.0).acos() / std::f32::consts::PI * NORMAL_BINS as f32) as usize).min(NORMAL_BINS - 1)
}

/// `normal_bin()` (shared/planes.wgsl): the bin (x, y) of a unit normal on the hemisphere
/// n_z ≥ 0 (one with n_z < 0 is negated first).
pub fn normal_bin(n: [f32; 4]) -> (usize, usize) {
    let h = if n[2] < 0.0 { [-n[0], -n[1], -n[2]] } else { [n[0], n[1], n[2]] };
    (normal_bin_1d(h[0]), normal_bin_1d(h[1]))
}

/// Adds every counted pixel's normal to `histogram` as the kernel's invocations do.
pub fn normal_histogram(params: &NormalHistogramParams, normal_in_camera: &[[f32; 4]], labels: &[u32], histogram: &mut [u32]) {
    for ix in 0..params.pixel_count as usize {
        let n = normal_in_camera[ix];
        if !is_valid_f32(n[0]) || !is_valid_f32(n[1]) || !is_valid_f32(n[2]) {
            continue;
        }
        if params.use_labels != 0 && labels[ix] != NO_LABEL {
            continue;
        }
        let (bx, by) = normal_bin(n);
        histogram[by * NORMAL_BINS + bx] += 1;
    }
}
