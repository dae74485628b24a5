// SPDX-License-Identifier: MIT
//! Each invocation moves one normal peak to the mean normal of the pixels distance_histogram
//! gave it (seed 003 §4.3.4's realignment, with the pixels' mean normal instead of 003's
//! largest plane's fitted normal, which a parallel plane beside it tilts): the normalised
//! fixed-point normal sum, or the peak itself where no pixel joined it; peaks past
//! `peak_count[0]` are copied. Mirrors core/src/cpu/planes/peak_realign.rs.
#import planes

struct PeakRealignParams {
    // Peak slots (MAX_NORMAL_PEAKS).
    peak_slots: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PeakRealignParams;
// The normal peaks (normal_peaks' output) and their number.
@group(0) @binding(1) var<storage, read> peaks: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> peak_count: array<u32>;
// Per peak the fixed-point sum of its pixels' normals (x, y, z, unused; distance_histogram's).
@group(0) @binding(3) var<storage, read> normal_sums: array<i32>;
// Out: the realigned peaks (unit normal, 0).
@group(0) @binding(4) var<storage, read_write> realigned: array<vec4<f32>>;

@compute @workgroup_size(8, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let k = gid.x;
    if k >= params.peak_slots {
        return;
    }
    if k >= peak_count[0] {
        realigned[k] = peaks[k];
        return;
    }
    let s = vec3<f32>(f32(normal_sums[4u * k]), f32(normal_sums[4u * k + 1u]), f32(normal_sums[4u * k + 2u]));
    let len = length(s);
    if len > 0.0 {
        realigned[k] = vec4<f32>(s / len, 0.0);
    } else {
        realigned[k] = vec4<f32>(peaks[k].xyz, 0.0);
    }
}
