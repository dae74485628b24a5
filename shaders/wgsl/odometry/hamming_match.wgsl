// SPDX-License-Identifier: MIT
//! Each invocation matches one query keypoint against every train keypoint by brute force:
//! the Hamming distance between their 256-bit descriptors, keeping the nearest (the lowest
//! train slot among equals) and the second-nearest distance, which the host's filters (Lowe's
//! ratio, seed 002's "outstanding" margin, the mutual check) need. An empty query slot, or no
//! train keypoint at all, gives (NO_MATCH, 257, 257). Mirrors
//! core/src/cpu/odometry/hamming_match.rs.
//!
//! A frame's slots are a third to a half empty (cells with fewer corners than slots), so the
//! workgroup packs its work: the workgroup's keypoint queries move to its first invocations,
//! and the train keypoints come through workgroup memory a tile of 64 slots at a time, keeping
//! only the keypoints. Lanes then idle only at the ends of those lists, which is what the
//! SIMD lanes of a CPU rasteriser (lavapipe) and a GPU's warps both pay for. The result does
//! not depend on the order the packing produces: ties go to the lowest train slot explicitly.
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

const MATCH_TILE: u32 = 64u;

// The workgroup's query slots that hold keypoints, packed, and their count.
var<workgroup> sh_queries: array<u32, MATCH_TILE>;
var<workgroup> sh_query_count: atomic<u32>;
// The current tile's train keypoints, packed: slot and descriptor (two words each).
var<workgroup> sh_train_slots: array<u32, MATCH_TILE>;
var<workgroup> sh_train_descriptors: array<vec4<u32>, 128>;
var<workgroup> sh_train_count: atomic<u32>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    if lid == 0u {
        atomicStore(&sh_query_count, 0u);
    }
    workgroupBarrier();
    let own = gid.x;
    if own < params.query_count {
        if query_keypoints[own].w > 0.0 {
            sh_queries[atomicAdd(&sh_query_count, 1u)] = own;
        } else {
            matches[own] = vec4<u32>(NO_MATCH, DESCRIPTOR_BITS + 1u, DESCRIPTOR_BITS + 1u, 0u);
        }
    }
    workgroupBarrier();
    // This invocation's query: the lid-th keypoint of the workgroup, if there are that many.
    let has_query = lid < atomicLoad(&sh_query_count);
    var q = 0u;
    var q0 = vec4<u32>(0u);
    var q1 = vec4<u32>(0u);
    if has_query {
        q = sh_queries[lid];
        // A descriptor is two vec4 words (DESCRIPTOR_WORDS = 8).
        q0 = query_descriptors[2u * q];
        q1 = query_descriptors[2u * q + 1u];
    }
    var best = NO_MATCH;
    var best_d = DESCRIPTOR_BITS + 1u;
    var second_d = DESCRIPTOR_BITS + 1u;
    for (var base = 0u; base < params.train_count; base += MATCH_TILE) {
        // Everyone has finished with the previous tile.
        workgroupBarrier();
        if lid == 0u {
            atomicStore(&sh_train_count, 0u);
        }
        workgroupBarrier();
        let t = base + lid;
        if t < params.train_count && train_keypoints[t].w > 0.0 {
            let i = atomicAdd(&sh_train_count, 1u);
            sh_train_slots[i] = t;
            sh_train_descriptors[2u * i] = train_descriptors[2u * t];
            sh_train_descriptors[2u * i + 1u] = train_descriptors[2u * t + 1u];
        }
        workgroupBarrier();
        // Inactive lanes loop zero times, so a SIMD group without a query skips the tile.
        let n = select(0u, atomicLoad(&sh_train_count), has_query);
        for (var i = 0u; i < n; i++) {
            let c = countOneBits(q0 ^ sh_train_descriptors[2u * i]) + countOneBits(q1 ^ sh_train_descriptors[2u * i + 1u]);
            let d = c.x + c.y + c.z + c.w;
            let slot = sh_train_slots[i];
            if d < best_d || (d == best_d && slot < best) {
                second_d = best_d;
                best_d = d;
                best = slot;
            } else if d < second_d {
                second_d = d;
            }
        }
    }
    if has_query {
        matches[q] = vec4<u32>(best, best_d, second_d, 0u);
    }
}
