// SPDX-License-Identifier: MIT
//! Workgroup h (of `hypotheses`) draws RANSAC's sample h and scores it. Invocation 0 draws
//! three distinct pairs from `match_select`'s n pairs with the counter-based stream
//! pcg_hash(pcg_hash(h) ^ seed) (a collision moves the second and third index on, as the
//! host's RANSAC did), skips samples whose current-frame triangle is too small, and fits
//! reference_from_current to them by Kabsch (shared/rigid_estimate.wgsl). Then each of the 64
//! invocations sums the MSAC cost (Torr and Zisserman 2000) of the pairs lid, lid + 64, ...:
//! the squared Mahalanobis residual, capped at the loose bound χ²(3, 95 %) · max_noise_scale²,
//! and the workgroup adds them in a fixed tree. A degenerate sample (or fewer pairs than
//! max(min_inliers, 3)) costs RANSAC_NO_COST. Mirrors
//! core/src/cpu/odometry/ransac_hypotheses.rs.
#import random
#import rigid_estimate

const RANSAC_HYPOTHESES_WORKGROUP: u32 = 64u;

@group(0) @binding(0) var<uniform> params: RansacParams;
// match_select's pairs and estimate (its pair count).
@group(0) @binding(1) var<storage, read> pairs: array<FeaturePair>;
@group(0) @binding(2) var<storage, read> estimate: RigidEstimate;
// Out: per hypothesis its reference_from_current (column-major).
@group(0) @binding(3) var<storage, read_write> hypotheses: array<mat4x4<f32>>;
// Out: per hypothesis its MSAC cost.
@group(0) @binding(4) var<storage, read_write> costs: array<f32>;

var<workgroup> sh_pose: mat4x4<f32>;
var<workgroup> sh_cost: array<f32, RANSAC_HYPOTHESES_WORKGROUP>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let h = wid.x;
    let n = estimate.pairs;
    if lid == 0u {
        var pose = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
        if n >= max(params.min_inliers, 3u) {
            var state = pcg_hash(pcg_hash(h) ^ params.seed);
            state = pcg_hash(state);
            let i = state % n;
            state = pcg_hash(state);
            var j = state % n;
            state = pcg_hash(state);
            var k = state % n;
            if j == i || k == i || k == j {
                j = (i + 1u + j % (n - 1u)) % n;
                k = (i + 2u + k % max(n - 2u, 1u)) % n;
            }
            let a = pairs[i];
            let b = pairs[j];
            let c = pairs[k];
            let area = length(cross(b.src.xyz - a.src.xyz, c.src.xyz - a.src.xyz));
            if j != i && k != i && k != j && area >= RANSAC_MIN_SAMPLE_AREA_M2 {
                pose = kabsch3(a.src.xyz, b.src.xyz, c.src.xyz, a.dst.xyz, b.dst.xyz, c.dst.xyz);
            }
        }
        sh_pose = pose;
    }
    workgroupBarrier();
    let pose = sh_pose;
    let usable = pose[3].w == 1.0;
    let loose = CHI2_3DOF_95 * params.max_noise_scale * params.max_noise_scale;
    var cost = 0.0;
    if usable {
        for (var p = lid; p < n; p += RANSAC_HYPOTHESES_WORKGROUP) {
            cost += min(pair_normalised_residual(pose, pairs[p], params.f_px), loose);
        }
    }
    sh_cost[lid] = cost;
    for (var stride = RANSAC_HYPOTHESES_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            sh_cost[lid] = sh_cost[lid] + sh_cost[lid + stride];
        }
    }
    workgroupBarrier();
    if lid == 0u {
        hypotheses[h] = pose;
        costs[h] = select(RANSAC_NO_COST, sh_cost[0], usable);
    }
}
