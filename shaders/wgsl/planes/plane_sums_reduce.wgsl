// SPDX-License-Identifier: MIT
//! Each workgroup combines the chunk partials of one plane (workgroup k: plane_sums' partials
//! (k, 0 .. chunks)) into its moments: each of the 64 invocations folds chunks lid, lid + 64,
//! ... in order, then the workgroup tree-combines them (shared/plane_moments.wgsl). Mirrors
//! core/src/cpu/planes/plane_sums_reduce.rs.
#import plane_moments

const PLANE_SUMS_REDUCE_WORKGROUP: u32 = 64u;

struct PlaneSumsReduceParams {
    // Chunks per plane in `partials`.
    chunks: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneSumsReduceParams;
// Per plane k and chunk c, PLANE_MOMENT_VEC4S vec4 at (k · chunks + c) (plane_sums' output).
@group(0) @binding(1) var<storage, read> partials: array<vec4<f32>>;
// Out: per plane its moments, PLANE_MOMENT_VEC4S vec4.
@group(0) @binding(2) var<storage, read_write> moments: array<vec4<f32>>;

var<workgroup> scratch: array<array<vec4<f32>, 10>, 64>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let k = wid.x;
    var acc = plane_moments_zero();
    for (var c = lid; c < params.chunks; c += PLANE_SUMS_REDUCE_WORKGROUP) {
        let base = (k * params.chunks + c) * PLANE_MOMENT_VEC4S;
        var m = plane_moments_zero();
        for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
            m[j] = partials[base + j];
        }
        acc = plane_moments_combine(acc, m);
    }
    scratch[lid] = acc;
    for (var stride = PLANE_SUMS_REDUCE_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            scratch[lid] = plane_moments_combine(scratch[lid], scratch[lid + stride]);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
            moments[k * PLANE_MOMENT_VEC4S + j] = scratch[0][j];
        }
    }
}
