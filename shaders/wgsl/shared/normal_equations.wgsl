// SPDX-License-Identifier: MIT
// 6-DOF normal equations of the tracker: per-thread accumulation of rows J = [a, b] (a: rotation
// part, b: translation part) with residual r, then a workgroup tree reduction in workgroup
// memory (no atomics), a vec4 at a time, writing 8 vec4 per workgroup:
// [JᵀJ upper triangle row-major (21), Jᵀr (6), Σ r² of the point-to-plane rows, their count,
//  Σ r² of the photometric rows, their count, 0]. The importing kernel declares
// `partial_sums: array<vec4<f32>>` and runs NE_WORKGROUP_SIZE threads per workgroup.
// Mirrors core/src/cpu/shared.rs::{ne_add_jacobian, ne_add_icp_stats, ne_add_rgb_stats,
// reduce_normal_equations}.

const NE_WORKGROUP_SIZE: u32 = 128u;
const NE_SUM_VEC4S: u32 = 8u;

var<workgroup> ne_scratch: array<vec4<f32>, NE_WORKGROUP_SIZE>;

fn ne_zero() -> array<vec4<f32>, NE_SUM_VEC4S> {
    var acc: array<vec4<f32>, NE_SUM_VEC4S>;
    for (var i = 0u; i < NE_SUM_VEC4S; i++) {
        acc[i] = vec4<f32>(0.0);
    }
    return acc;
}

// Adds JᵀJ and Jᵀr of the row J = [a, b] with residual r.
fn ne_add_jacobian(acc: ptr<function, array<vec4<f32>, NE_SUM_VEC4S>>, a: vec3<f32>, b: vec3<f32>, r: f32) {
    let j0 = a.x;
    let j1 = a.y;
    let j2 = a.z;
    let j3 = b.x;
    let j4 = b.y;
    let j5 = b.z;
    (*acc)[0] += vec4<f32>(j0 * j0, j0 * j1, j0 * j2, j0 * j3);
    (*acc)[1] += vec4<f32>(j0 * j4, j0 * j5, j1 * j1, j1 * j2);
    (*acc)[2] += vec4<f32>(j1 * j3, j1 * j4, j1 * j5, j2 * j2);
    (*acc)[3] += vec4<f32>(j2 * j3, j2 * j4, j2 * j5, j3 * j3);
    (*acc)[4] += vec4<f32>(j3 * j4, j3 * j5, j4 * j4, j4 * j5);
    (*acc)[5] += vec4<f32>(j5 * j5, j0 * r, j1 * r, j2 * r);
    (*acc)[6] += vec4<f32>(j3 * r, j4 * r, j5 * r, 0.0);
}

// Counts a point-to-plane row with (weighted) residual r.
fn ne_add_icp_stats(acc: ptr<function, array<vec4<f32>, NE_SUM_VEC4S>>, r: f32) {
    (*acc)[6].w += r * r;
    (*acc)[7].x += 1.0;
}

// Counts a photometric row with residual r.
fn ne_add_rgb_stats(acc: ptr<function, array<vec4<f32>, NE_SUM_VEC4S>>, r: f32) {
    (*acc)[7].y += r * r;
    (*acc)[7].z += 1.0;
}

// Tree-reduces every thread's `acc` and writes the workgroup's sum, one vec4 of the sums at a
// time through a 128-entry scratch (2 KiB): per float the same tree as reducing the whole
// array at once, with an eighth of the workgroup memory. (SwiftShader, the browser's CPU
// WebGPU, compiled the kernel with a 16 KiB scratch in 2.3 s, half the app's start-up; with
// this one in 0.6 s, and runs it no slower.) Call from uniform control flow (it contains
// barriers).
fn ne_reduce_and_store(acc: array<vec4<f32>, NE_SUM_VEC4S>, lid: u32, wid: u32) {
    for (var i = 0u; i < NE_SUM_VEC4S; i++) {
        workgroupBarrier();
        ne_scratch[lid] = acc[i];
        for (var stride = NE_WORKGROUP_SIZE / 2u; stride > 0u; stride >>= 1u) {
            workgroupBarrier();
            if lid < stride {
                ne_scratch[lid] += ne_scratch[lid + stride];
            }
        }
        workgroupBarrier();
        if lid == 0u {
            partial_sums[wid * NE_SUM_VEC4S + i] = ne_scratch[0];
        }
    }
}
