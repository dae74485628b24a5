// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/distance_peaks.wgsl` (each workgroup's search as one
//! pass per normal peak).

use crate::kernels::distance_peaks::DistancePeaksParams;
use crate::planes::{DISTANCE_BINS, MAX_DISTANCE_PEAKS};

/// The smoothed histogram and the positions of its prominent peaks, in order.
pub fn prominent_peaks(raw: &[u32]) -> (Vec<f32>, Vec<usize>) {
    let n = raw.len();
    let at = |i: isize| if i < 0 || i as usize >= n { 0.0 } else { raw[i as usize] as f32 };
    let s: Vec<f32> = (0..n as isize).map(|i| 0.25 * at(i - 1) + 0.5 * at(i) + 0.25 * at(i + 1)).collect();
    let mut peaks = Vec::new();
    for i in 0..n {
        let h = s[i];
        if !(h > 0.0) || (i > 0 && s[i - 1] >= h) {
            continue;
        }
        let end = (i + 1..n).find(|&j| s[j] != h).unwrap_or(n);
        if end < n && s[end] > h {
            continue;
        }
        let mut col = -1.0f32;
        let mut low = h;
        for j in (0..i).rev() {
            if s[j] > h {
                col = col.max(low);
                break;
            }
            low = low.min(s[j]);
        }
        low = h;
        for &v in &s[end..] {
            if v > h {
                col = col.max(low);
                break;
            }
            low = low.min(v);
        }
        if h - col.max(0.0) >= 0.5 * h {
            peaks.push((i + end - 1) / 2);
        }
    }
    (s, peaks)
}

/// Finds each normal peak's intervals as the kernel's workgroups do.
pub fn distance_peaks(params: &DistancePeaksParams, histogram: &[u32], peak_count: &[u32], intervals: &mut [[u32; 4]], interval_count: &mut [u32]) {
    for k in 0..peak_count[0] as usize {
        let raw = &histogram[k * DISTANCE_BINS..(k + 1) * DISTANCE_BINS];
        let (s, peaks) = prominent_peaks(raw);
        let reach = params.reach_bins as usize;
        let mut best: Vec<[u32; 4]> = Vec::new();
        for (q, &p) in peaks.iter().enumerate() {
            // The lowest bin between two peaks, the first of equals (none between: the left one).
            let valley = |a: usize, b: usize| {
                let mut v = a;
                let mut v_min = f32::MAX;
                for j in a + 1..b {
                    if s[j] < v_min {
                        (v, v_min) = (j, s[j]);
                    }
                }
                v
            };
            let lo = if q == 0 { 0 } else { valley(peaks[q - 1], p) + 1 };
            let hi = if q + 1 == peaks.len() { DISTANCE_BINS - 1 } else { valley(p, peaks[q + 1]) };
            let (lo, hi) = (lo.max(p.saturating_sub(reach)), hi.min(p + reach));
            let mass: u32 = raw[lo..=hi].iter().sum();
            if mass >= params.min_mass.max(1) {
                let at = best.iter().position(|b| b[2] < mass || (b[2] == mass && b[0] as usize > lo)).unwrap_or(best.len());
                best.insert(at, [lo as u32, hi as u32, mass, 0]);
                best.truncate(MAX_DISTANCE_PEAKS);
            }
        }
        for j in 0..MAX_DISTANCE_PEAKS {
            intervals[k * MAX_DISTANCE_PEAKS + j] = best.get(j).copied().unwrap_or([0; 4]);
        }
        interval_count[k] = best.len() as u32;
    }
}
