// SPDX-License-Identifier: MIT
//! Each invocation matches one query keypoint against every train keypoint by brute force:
//! the Hamming distance between their 256-bit descriptors, keeping the nearest (the first in
//! slot order among equals) and the second-nearest distance, which the host's filters (Lowe's
//! ratio, seed 002's "outstanding" margin, the mutual check) need. An empty query slot, or no
//! train keypoint at all, gives (NO_MATCH, 257, 257). Mirrors
//! core/src/cpu/odometry/hamming_match.rs.
#import features

struct HammingMatchParams {
    query_count: u32,
    train_count: u32,
}

@group(0) @binding(0) var<uniform> params: HammingMatchParams;
// Per query slot, (x, y, level, score): score 0 marks an empty slot.
@group(0) @binding(1) var<storage, read> query_keypoints: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> query_descriptors: array<vec4<u32>>;
@group(0) @binding(3) var<storage, read> train_keypoints: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read> train_descriptors: array<vec4<u32>>;
// Out: per query, (train slot of the nearest, its distance, the second-nearest distance, 0).
@group(0) @binding(5) var<storage, read_write> matches: array<vec4<u32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let q = gid.x;
    if q >= params.query_count {
        return;
    }
    var best = NO_MATCH;
    var best_d = DESCRIPTOR_BITS + 1u;
    var second_d = DESCRIPTOR_BITS + 1u;
    if query_keypoints[q].w > 0.0 {
        // A descriptor is two vec4 words (DESCRIPTOR_WORDS = 8).
        let q0 = query_descriptors[2u * q];
        let q1 = query_descriptors[2u * q + 1u];
        for (var t = 0u; t < params.train_count; t++) {
            if !(train_keypoints[t].w > 0.0) {
                continue;
            }
            let c = countOneBits(q0 ^ train_descriptors[2u * t]) + countOneBits(q1 ^ train_descriptors[2u * t + 1u]);
            let d = c.x + c.y + c.z + c.w;
            if d < best_d {
                second_d = best_d;
                best_d = d;
                best = t;
            } else if d < second_d {
                second_d = d;
            }
        }
    }
    matches[q] = vec4<u32>(best, best_d, second_d, 0u);
}
