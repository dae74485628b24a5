// SPDX-License-Identifier: MIT
//! One workgroup of 256 invocations keeps the matches worth estimating a motion from and lifts
//! them to 3D pairs, in current-slot order: invocation i looks at the current frame's slots
//! [i · per, (i + 1) · per) (per = ⌈slots / 256⌉). A slot is a candidate when it has a nearest
//! reference slot within `max_distance_bits`, passes Lowe's ratio (nearest < ratio · second),
//! 002's "outstanding" margin (second − nearest ≥ margin_bits), the mutual check (the
//! reference slot's nearest is this slot) when `mutual` is 1, and both points are valid. Of the
//! candidates, 002's keep-best keeps the ⌈n · keep_best_fraction⌉ nearest (ties by slot order;
//! 1 keeps all): a distance histogram in workgroup memory gives the threshold and how many
//! matches at it still fit, and two prefix sums place the ties and then the kept pairs. The
//! pair count goes into `estimate` (its other fields reset). Integer atomics only, so the
//! output does not depend on scheduling. Mirrors core/src/cpu/odometry/match_select.rs.
#import features
#import rigid_estimate
#import workgroup_scan

// Histogram bins: distances 0 ..= DESCRIPTOR_BITS.
const DISTANCE_BINS: u32 = 257u;

struct MatchSelectParams {
    // Keypoint slots per frame (current and reference).
    slots: u32,
    // 1: keep only pairs that are each other's nearest.
    mutual: u32,
    // Reject matches farther than this, bits.
    max_distance_bits: u32,
    // Keep when second − nearest ≥ this (0: off).
    margin_bits: u32,
    // Lowe's ratio.
    ratio: f32,
    // The fraction of the candidates kept, nearest first (1: all).
    keep_best_fraction: f32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> params: MatchSelectParams;
// Per current slot: (reference slot, nearest distance, second distance, 0) (hamming_match).
@group(0) @binding(1) var<storage, read> forward: array<vec4<u32>>;
// Per reference slot: (current slot, nearest distance, second distance, 0).
@group(0) @binding(2) var<storage, read> backward: array<vec4<u32>>;
// The current frame's keypoints (x, y, level, score) and points (x, y, z, 1).
@group(0) @binding(3) var<storage, read> current_keypoints: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> current_points: array<vec4<f32>>;
// The reference frame's keypoints and points.
@group(0) @binding(5) var<storage, read> reference_keypoints: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> reference_points: array<vec4<f32>>;
// Out: the kept pairs, in current-slot order (the first `estimate.pairs`).
@group(0) @binding(7) var<storage, read_write> pairs: array<FeaturePair>;
// Out: the pair count; the estimate's other fields reset.
@group(0) @binding(8) var<storage, read_write> estimate: RigidEstimate;

var<workgroup> sh_histogram: array<atomic<u32>, DISTANCE_BINS>;
// The keep-best threshold distance and how many matches at it are kept.
var<workgroup> sh_threshold: u32;
var<workgroup> sh_tie_quota: u32;

// Whether current slot `q` is a candidate (see above).
fn candidate(q: u32) -> bool {
    let m = forward[q];
    if m.x == NO_MATCH || m.x >= params.slots || m.y > params.max_distance_bits {
        return false;
    }
    if !(f32(m.y) < params.ratio * f32(m.z)) || m.z - m.y < params.margin_bits {
        return false;
    }
    if params.mutual == 1u && backward[m.x].x != q {
        return false;
    }
    return is_valid_f32(current_points[q].z) && is_valid_f32(reference_points[m.x].z);
}

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    let per = (params.slots + SCAN_WG_SIZE - 1u) / SCAN_WG_SIZE;
    let first = lid * per;
    let last = min(first + per, params.slots);
    for (var b = lid; b < DISTANCE_BINS; b += SCAN_WG_SIZE) {
        atomicStore(&sh_histogram[b], 0u);
    }
    workgroupBarrier();
    var candidates = 0u;
    for (var q = first; q < last; q++) {
        if candidate(q) {
            candidates += 1u;
            atomicAdd(&sh_histogram[forward[q].y], 1u);
        }
    }
    let n = wg_exclusive_scan(lid, candidates).total;
    if lid == 0u {
        let keep = min(u32(ceil(f32(n) * params.keep_best_fraction)), n);
        // The smallest distance d with at least `keep` candidates at or below it.
        var below = 0u;
        var threshold = DISTANCE_BINS;
        for (var d = 0u; d < DISTANCE_BINS && keep > 0u; d++) {
            let here = atomicLoad(&sh_histogram[d]);
            if below + here >= keep {
                threshold = d;
                break;
            }
            below += here;
        }
        sh_threshold = threshold;
        sh_tie_quota = keep - below;
    }
    workgroupBarrier();
    let threshold = sh_threshold;
    let quota = sh_tie_quota;
    var ties = 0u;
    for (var q = first; q < last; q++) {
        if candidate(q) && forward[q].y == threshold {
            ties += 1u;
        }
    }
    var tie_rank = wg_exclusive_scan(lid, ties).exclusive;
    var kept = 0u;
    for (var q = first; q < last; q++) {
        if candidate(q) {
            let d = forward[q].y;
            if d < threshold || (d == threshold && tie_rank < quota) {
                kept += 1u;
            }
            if d == threshold {
                tie_rank += 1u;
            }
        }
    }
    let placed = wg_exclusive_scan(lid, kept);
    var at = placed.exclusive;
    tie_rank = tie_rank - ties;
    for (var q = first; q < last; q++) {
        if candidate(q) {
            let m = forward[q];
            if m.y < threshold || (m.y == threshold && tie_rank < quota) {
                var pair: FeaturePair;
                pair.src = vec4<f32>(current_points[q].xyz, current_keypoints[q].z);
                pair.dst = vec4<f32>(reference_points[m.x].xyz, reference_keypoints[m.x].z);
                pair.slots = vec4<u32>(q, m.x, m.y, 0u);
                pairs[at] = pair;
                at += 1u;
            }
            if m.y == threshold {
                tie_rank += 1u;
            }
        }
    }
    if lid == 0u {
        var e: RigidEstimate;
        e.dst_from_src = mat4x4<f32>(vec4<f32>(1.0, 0.0, 0.0, 0.0), vec4<f32>(0.0, 1.0, 0.0, 0.0), vec4<f32>(0.0, 0.0, 1.0, 0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
        e.pairs = placed.total;
        e.best_hypothesis = RANSAC_MAX_HYPOTHESES;
        e.noise_scale = 1.0;
        e.cost = RANSAC_NO_COST;
        estimate = e;
    }
}
