// SPDX-License-Identifier: MIT
//! Each workgroup finds the planes in one normal peak's distance histogram (the inner loop of
//! plane segmentation): the histogram smoothed by [1 2 1] / 4; local maxima (a plateau counts
//! once, at its middle) whose prominence is at least half their height (the line at a peak's
//! height is extended each way to strictly higher ground, an equal peak not stopping it; the
//! col is the higher of the lowest points passed on the sides that met higher ground, none for
//! the highest peak), so two surfaces a few bins apart with a valley between stay two where
//! seed 003's fixed exclusion radius merged them. Each peak owns the bins up to the lowest bin
//! between it and each neighbouring peak (the first of equals; the valley bin goes to the left
//! peak), at most `reach_bins` from it; peaks owning fewer than `min_mass` pixels are dropped;
//! the MAX_DISTANCE_PEAKS with the most pixels are kept, most first (the lower bin among
//! equals). The 256 invocations find and test the maxima of 4 bins each; the first turns them
//! into intervals. Mirrors core/src/cpu/planes/distance_peaks.rs.
#import planes

const WORKGROUP: u32 = 256u;

struct DistancePeaksParams {
    // A plane needs this many pixels in its bins.
    min_mass: u32,
    // A peak owns bins at most this far from it.
    reach_bins: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: DistancePeaksParams;
// Per normal peak DISTANCE_BINS counts (distance_histogram's output).
@group(0) @binding(1) var<storage, read> histogram: array<u32>;
// The number of normal peaks.
@group(0) @binding(2) var<storage, read> peak_count: array<u32>;
// Out: per normal peak MAX_DISTANCE_PEAKS intervals (first bin, last bin, pixels, 0), most
// pixels first; zeros past the last.
@group(0) @binding(3) var<storage, read_write> intervals: array<vec4<u32>>;
// Out: per normal peak the number of intervals.
@group(0) @binding(4) var<storage, read_write> interval_count: array<u32>;

var<workgroup> raw: array<u32, 1024>;
var<workgroup> smoothed: array<f32, 1024>;
var<workgroup> is_peak: array<u32, 1024>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = wid.x;
    if k >= peak_count[0] {
        return;
    }
    let base = k * DISTANCE_BINS;
    for (var r = 0u; r < 4u; r++) {
        raw[4u * lid + r] = histogram[base + 4u * lid + r];
        is_peak[4u * lid + r] = 0u;
    }
    workgroupBarrier();
    for (var r = 0u; r < 4u; r++) {
        let i = 4u * lid + r;
        var left = 0.0;
        if i > 0u {
            left = f32(raw[i - 1u]);
        }
        var right = 0.0;
        if i + 1u < DISTANCE_BINS {
            right = f32(raw[i + 1u]);
        }
        smoothed[i] = 0.25 * left + 0.5 * f32(raw[i]) + 0.25 * right;
    }
    workgroupBarrier();
    for (var r = 0u; r < 4u; r++) {
        let i = 4u * lid + r;
        let h = smoothed[i];
        if !(h > 0.0) || (i > 0u && smoothed[i - 1u] >= h) {
            continue;
        }
        var end = i + 1u;
        while end < DISTANCE_BINS && smoothed[end] == h {
            end++;
        }
        if end < DISTANCE_BINS && smoothed[end] > h {
            continue;
        }
        // The cols on each side (a negative col: the side met no higher ground).
        var col = -1.0;
        var low = h;
        for (var j = i; j > 0u; j--) {
            let v = smoothed[j - 1u];
            if v > h {
                col = max(col, low);
                break;
            }
            low = min(low, v);
        }
        low = h;
        for (var j = end; j < DISTANCE_BINS; j++) {
            let v = smoothed[j];
            if v > h {
                col = max(col, low);
                break;
            }
            low = min(low, v);
        }
        if h - max(col, 0.0) >= 0.5 * h {
            is_peak[(i + end - 1u) / 2u] = 1u;
        }
    }
    workgroupBarrier();
    if lid != 0u {
        return;
    }
    // The first invocation: the peaks in order, their valleys and intervals, the best kept.
    var best: array<vec4<u32>, 8>;
    var kept = 0u;
    var previous = DISTANCE_BINS;
    var previous_lo = 0u;
    var p = 0u;
    // Walk the peaks; an interval is complete once the next peak (or the end) is known.
    loop {
        while p < DISTANCE_BINS && is_peak[p] == 0u {
            p++;
        }
        if previous < DISTANCE_BINS {
            // Close the previous peak's interval at the valley towards p (or the last bin).
            var hi = DISTANCE_BINS - 1u;
            var next_lo = 0u;
            if p < DISTANCE_BINS {
                var valley = previous;
                var v_min = 3.0e38;
                for (var j = previous + 1u; j < p; j++) {
                    if smoothed[j] < v_min {
                        v_min = smoothed[j];
                        valley = j;
                    }
                }
                hi = valley;
                next_lo = valley + 1u;
            }
            let lo = max(previous_lo, select(0u, previous - params.reach_bins, previous >= params.reach_bins));
            hi = min(hi, previous + params.reach_bins);
            var mass = 0u;
            for (var j = lo; j <= hi; j++) {
                mass += raw[j];
            }
            if mass >= max(params.min_mass, 1u) {
                // Insert by (mass desc, lo asc) into the best MAX_DISTANCE_PEAKS.
                var at = kept;
                while at > 0u && (best[at - 1u].z < mass || (best[at - 1u].z == mass && best[at - 1u].x > lo)) {
                    if at < MAX_DISTANCE_PEAKS {
                        best[at] = best[at - 1u];
                    }
                    at--;
                }
                if at < MAX_DISTANCE_PEAKS {
                    best[at] = vec4<u32>(lo, hi, mass, 0u);
                    kept = min(kept + 1u, MAX_DISTANCE_PEAKS);
                }
            }
            previous_lo = next_lo;
        }
        if p >= DISTANCE_BINS {
            break;
        }
        previous = p;
        p++;
    }
    for (var j = 0u; j < MAX_DISTANCE_PEAKS; j++) {
        if j < kept {
            intervals[k * MAX_DISTANCE_PEAKS + j] = best[j];
        } else {
            intervals[k * MAX_DISTANCE_PEAKS + j] = vec4<u32>(0u);
        }
    }
    interval_count[k] = kept;
}
