// SPDX-License-Identifier: MIT
//! One workgroup finds the peaks of the normal histogram (seed 003 §4.3.1): up to
//! MAX_NORMAL_PEAKS times, the bin with the highest count (the lowest index among equals) by a
//! tree reduction; it stops at a count below `min_count`; the peak's normal is that of the
//! count-weighted centroid of its 3 x 3 neighbourhood (bin i spans [i, i + 1)), and every bin
//! whose centre lies within `exclusion_bins` of the peak's bin centre is cleared before the next
//! search. Bins within `clear_bins` of each of the `known_count[0]` normals of earlier rounds'
//! planes are cleared first. Each of the 256 invocations owns 4 bins. Mirrors
//! core/src/cpu/planes/normal_peaks.rs.
#import invalid
#import planes

const BIN_COUNT: u32 = 1024u;
const WORKGROUP: u32 = 256u;

struct NormalPeaksParams {
    // The smallest count a peak's bin may have.
    min_count: u32,
    // Radius cleared around each peak, bins.
    exclusion_bins: f32,
    // Radius cleared around each known normal, bins.
    clear_bins: f32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: NormalPeaksParams;
// The normal histogram, NORMAL_BINS² counts, row-major (y, x).
@group(0) @binding(1) var<storage, read> histogram: array<u32>;
// Normals (xyz) of the planes earlier rounds found; `known_count[0]` of them are read (a
// buffer, so the plane list on the GPU can set it).
@group(0) @binding(2) var<storage, read> known_normals: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read> known_count: array<u32>;
// Out: MAX_NORMAL_PEAKS entries, highest first: unit normal (n_z ≥ 0) and its bin's count in
// w; NaN past the last peak.
@group(0) @binding(4) var<storage, read_write> peaks: array<vec4<f32>>;
// Out: [0] = the number of peaks.
@group(0) @binding(5) var<storage, read_write> peak_count: array<u32>;

var<workgroup> bins: array<u32, 1024>;
var<workgroup> best_count: array<u32, 256>;
var<workgroup> best_index: array<u32, 256>;

// Clears this invocation's bins whose centres lie within `radius` of `centre` (bin coordinates).
fn clear_around(lid: u32, centre: vec2<f32>, radius: f32) {
    for (var i = 0u; i < BIN_COUNT / WORKGROUP; i++) {
        let b = lid + i * WORKGROUP;
        let d = vec2<f32>(f32(b % NORMAL_BINS) + 0.5, f32(b / NORMAL_BINS) + 0.5) - centre;
        if d.x * d.x + d.y * d.y < radius * radius {
            bins[b] = 0u;
        }
    }
}

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    for (var i = 0u; i < BIN_COUNT / WORKGROUP; i++) {
        bins[lid + i * WORKGROUP] = histogram[lid + i * WORKGROUP];
    }
    workgroupBarrier();
    for (var k = 0u; k < known_count[0]; k++) {
        clear_around(lid, vec2<f32>(normal_bin(known_normals[k].xyz)) + vec2<f32>(0.5), params.clear_bins);
    }
    workgroupBarrier();
    var found = 0u;
    for (var p = 0u; p < MAX_NORMAL_PEAKS; p++) {
        // This invocation's best bin, then the workgroup's by a tree reduction.
        var count = 0u;
        var index = 0u;
        for (var i = 0u; i < BIN_COUNT / WORKGROUP; i++) {
            let b = lid + i * WORKGROUP;
            if bins[b] > count {
                count = bins[b];
                index = b;
            }
        }
        if count == 0u {
            index = BIN_COUNT;
        }
        best_count[lid] = count;
        best_index[lid] = index;
        workgroupBarrier();
        for (var stride = WORKGROUP / 2u; stride > 0u; stride /= 2u) {
            if lid < stride {
                let c = best_count[lid + stride];
                let j = best_index[lid + stride];
                if c > best_count[lid] || (c == best_count[lid] && j < best_index[lid]) {
                    best_count[lid] = c;
                    best_index[lid] = j;
                }
            }
            workgroupBarrier();
        }
        let top = workgroupUniformLoad(&best_count[0]);
        if top < max(params.min_count, 1u) {
            break;
        }
        let at = best_index[0];
        let px = at % NORMAL_BINS;
        let py = at / NORMAL_BINS;
        if lid == 0u {
            var sum = vec2<f32>(0.0);
            var weight = 0.0;
            for (var by = max(py, 1u) - 1u; by <= min(py + 1u, NORMAL_BINS - 1u); by++) {
                for (var bx = max(px, 1u) - 1u; bx <= min(px + 1u, NORMAL_BINS - 1u); bx++) {
                    let w = f32(bins[by * NORMAL_BINS + bx]);
                    sum += w * vec2<f32>(f32(bx) + 0.5, f32(by) + 0.5);
                    weight += w;
                }
            }
            peaks[p] = vec4<f32>(bin_normal(sum / weight), f32(top));
        }
        workgroupBarrier();
        clear_around(lid, vec2<f32>(f32(px) + 0.5, f32(py) + 0.5), params.exclusion_bins);
        workgroupBarrier();
        found += 1u;
    }
    if lid == 0u {
        peak_count[0] = found;
        for (var p = found; p < MAX_NORMAL_PEAKS; p++) {
            peaks[p] = invalid_vec4();
        }
    }
}
