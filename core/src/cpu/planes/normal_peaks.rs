// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/normal_peaks.wgsl` (the workgroup's reductions as one
//! sequential search with the same tie rule: the lowest index among equal counts).

use crate::cpu::planes::normal_histogram::normal_bin;
use crate::cpu::shared::INVALID_VEC4;
use crate::kernels::normal_peaks::NormalPeaksParams;
use crate::planes::{MAX_NORMAL_PEAKS, NORMAL_BINS};

/// `bin_normal()`: the unit normal (n_z ≥ 0) at continuous bin coordinates, bin i spanning
/// [i, i + 1).
pub fn bin_normal(bx: f32, by: f32) -> [f32; 3] {
    let step = std::f32::consts::PI / NORMAL_BINS as f32;
    let (x, y) = ((bx * step).cos(), (by * step).cos());
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    let len = (x * x + y * y + z * z).sqrt();
    [x / len, y / len, z / len]
}

fn clear_around(bins: &mut [u32], centre: [f32; 2], radius: f32) {
    for (b, v) in bins.iter_mut().enumerate() {
        let d = [(b % NORMAL_BINS) as f32 + 0.5 - centre[0], (b / NORMAL_BINS) as f32 + 0.5 - centre[1]];
        if d[0] * d[0] + d[1] * d[1] < radius * radius {
            *v = 0;
        }
    }
}

/// Finds the peaks as the kernel's workgroup does.
pub fn normal_peaks(params: &NormalPeaksParams, histogram: &[u32], known_normals: &[[f32; 4]], known_count: &[u32], peaks: &mut [[f32; 4]], peak_count: &mut [u32]) {
    let mut bins = histogram[..NORMAL_BINS * NORMAL_BINS].to_vec();
    for k in 0..known_count[0] as usize {
        let (bx, by) = normal_bin(known_normals[k]);
        clear_around(&mut bins, [bx as f32 + 0.5, by as f32 + 0.5], params.clear_bins);
    }
    let mut found = 0;
    for p in 0..MAX_NORMAL_PEAKS {
        let (mut top, mut at) = (0u32, bins.len());
        for (b, &c) in bins.iter().enumerate() {
            if c > top {
                (top, at) = (c, b);
            }
        }
        if top < params.min_count.max(1) {
            break;
        }
        let (px, py) = (at % NORMAL_BINS, at / NORMAL_BINS);
        let (mut sum, mut weight) = ([0.0f32; 2], 0.0f32);
        for by in py.saturating_sub(1)..=(py + 1).min(NORMAL_BINS - 1) {
            for bx in px.saturating_sub(1)..=(px + 1).min(NORMAL_BINS - 1) {
                let w = bins[by * NORMAL_BINS + bx] as f32;
                sum = [sum[0] + w * (bx as f32 + 0.5), sum[1] + w * (by as f32 + 0.5)];
                weight += w;
            }
        }
        let n = bin_normal(sum[0] / weight, sum[1] / weight);
        peaks[p] = [n[0], n[1], n[2], top as f32];
        clear_around(&mut bins, [px as f32 + 0.5, py as f32 + 0.5], params.exclusion_bins);
        found += 1;
    }
    peak_count[0] = found as u32;
    for p in &mut peaks[found..MAX_NORMAL_PEAKS] {
        *p = INVALID_VEC4;
    }
}
