// SPDX-License-Identifier: MIT
//! One workgroup of 64 invocations turns RANSAC's hypotheses into the frame's estimate;
//! invocation i owns the pairs i, i + 64, ... (their residuals and inlier flags), and every
//! sum is a fixed tree, so the result does not depend on scheduling:
//! 1. the hypothesis of least MSAC cost (the lower index among equals);
//! 2. the frame's noise scale: the median squared Mahalanobis residual of the pairs within the
//!    loose bound χ²(3, 95 %) · max_noise_scale², found exactly by bisection on its f32 bit
//!    pattern (32 rounds of counting with a workgroup atomic), over χ²₃'s median, square-rooted,
//!    at least 1 (fast motion puts the colour and depth instants apart, so a frame may be
//!    noisier than the sensor model; never less);
//! 3. the inliers: pairs within χ²(3, 95 %) · s², s the scale capped at max_noise_scale;
//! 4. up to `refits` times: Gauss-Newton (`iterations` steps) on Σ ρ(rᵢᵀ Ωᵢ rᵢ) over the inliers
//!    (Ω the residual's information at the current estimate, ρ Huber at √χ² · s, the update
//!    exp(ξ) on the left, the 6 × 6 system Jacobi-scaled and Cholesky-factored by invocation 0,
//!    stopping once |ξ| < GN_CONVERGED_STEP), then the scale and the inliers again, until
//!    the inlier set no longer changes; if it still changes after `refits`, Gauss-Newton once
//!    more on the last classification, so the estimate is the optimum of the inliers it reports;
//! 5. accepted when at least `min_inliers` remain, no system was singular and the noise scale
//!    is within max_noise_scale (002's rejection of poor residuals: pairs noisier than that
//!    bound are not a motion the sensor model can vouch for); the inliers' RMS residual. The result goes into `estimate` (its pair count kept). Mirrors
//!    core/src/cpu/odometry/ransac_refine.rs.
#import linear_solve
#import rigid
#import rigid_estimate

const RANSAC_REFINE_WORKGROUP: u32 = 64u;
// Floats of one pair's normal equations: JᵀΩJ's upper triangle (21) and JᵀΩr (6), then 1 spare.
const GN_FLOATS: u32 = 28u;
// A Gauss-Newton step shorter than this (|ξ|, metres and radians at 1 m) has converged.
const GN_CONVERGED_STEP: f32 = 1e-7;
// The Jacobi-scaled system is singular when a Cholesky pivot falls below this.
const GN_MIN_PIVOT: f32 = 1e-7;
// `sh_state`.
const REFINE_RUNNING: u32 = 0u;
const REFINE_SETTLED: u32 = 1u;
const REFINE_REJECTED: u32 = 2u;

@group(0) @binding(0) var<uniform> params: RansacParams;
// ransac_hypotheses' poses and costs.
@group(0) @binding(1) var<storage, read> hypotheses: array<mat4x4<f32>>;
@group(0) @binding(2) var<storage, read> costs: array<f32>;
// match_select's pairs.
@group(0) @binding(3) var<storage, read> pairs: array<FeaturePair>;
// In: the pair count; out: the estimate.
@group(0) @binding(4) var<storage, read_write> estimate: RigidEstimate;
// Scratch: each pair's squared Mahalanobis residual at the current estimate.
@group(0) @binding(5) var<storage, read_write> residuals: array<f32>;
// Out: per pair 1 when it is an inlier of the final estimate.
@group(0) @binding(6) var<storage, read_write> inlier_flags: array<u32>;

var<workgroup> sh_pose: mat4x4<f32>;
var<workgroup> sh_best_cost: array<f32, RANSAC_REFINE_WORKGROUP>;
var<workgroup> sh_best_index: array<u32, RANSAC_REFINE_WORKGROUP>;
var<workgroup> sh_sums: array<array<f32, GN_FLOATS>, RANSAC_REFINE_WORKGROUP>;
var<workgroup> sh_count: atomic<u32>;
var<workgroup> sh_changed: atomic<u32>;
var<workgroup> sh_state: u32;
var<workgroup> sh_converged: u32;
var<workgroup> sh_scale: f32;
var<workgroup> sh_inliers: u32;
var<workgroup> sh_refits: u32;

// Writes the squared Mahalanobis residuals of this invocation's pairs under `pose`.
fn compute_residuals(lid: u32, n: u32, pose: mat4x4<f32>) {
    for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
        residuals[p] = pair_normalised_residual(pose, pairs[p], params.f_px);
    }
}

// The workgroup's total of `value` (every invocation gets it; uniform control flow).
fn count_all(lid: u32, value: u32) -> u32 {
    workgroupBarrier();
    if lid == 0u {
        atomicStore(&sh_count, 0u);
    }
    workgroupBarrier();
    atomicAdd(&sh_count, value);
    workgroupBarrier();
    return atomicLoad(&sh_count);
}

// The noise scale of the residuals (see step 2).
fn noise_scale(lid: u32, n: u32, loose: f32) -> f32 {
    var within = 0u;
    for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
        within += select(0u, 1u, residuals[p] <= loose);
    }
    let m = count_all(lid, within);
    // The k-th smallest (k = m / 2, 0-based): the least bit pattern with more than k residuals
    // at or below it (non-negative f32s order like their bits).
    let k = m / 2u;
    var lo = 0u;
    var hi = bitcast<u32>(loose);
    for (var round = 0u; round < 32u; round++) {
        let mid = lo + (hi - lo) / 2u;
        var below = 0u;
        for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
            let e = residuals[p];
            below += select(0u, 1u, e <= loose && bitcast<u32>(e) <= mid);
        }
        if count_all(lid, below) > k {
            hi = mid;
        } else {
            lo = mid + 1u;
        }
    }
    if m == 0u {
        return 1.0;
    }
    return max(sqrt(bitcast<f32>(lo) / CHI2_3DOF_MEDIAN), 1.0);
}

// Flags this invocation's pairs within `bound` (when `write`) and returns (inliers, flags
// changed) over the workgroup.
fn classify(lid: u32, n: u32, bound: f32, write: bool) -> vec2<u32> {
    var inliers = 0u;
    var changed = 0u;
    for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
        let flag = select(0u, 1u, residuals[p] <= bound);
        inliers += flag;
        if write {
            changed += select(0u, 1u, flag != inlier_flags[p]);
            inlier_flags[p] = flag;
        }
    }
    let total = count_all(lid, inliers);
    return vec2<u32>(total, count_all(lid, changed));
}

// Sums sh_sums over the workgroup into sh_sums[0] (uniform control flow).
fn reduce_sums(lid: u32) {
    for (var stride = RANSAC_REFINE_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            for (var f = 0u; f < GN_FLOATS; f++) {
                sh_sums[lid][f] = sh_sums[lid][f] + sh_sums[lid + stride][f];
            }
        }
    }
    workgroupBarrier();
}

// This invocation's inliers' weighted normal equations under `pose` with Huber at `huber`.
fn accumulate(lid: u32, n: u32, pose: mat4x4<f32>, huber: f32) -> array<f32, GN_FLOATS> {
    var acc: array<f32, GN_FLOATS>;
    for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
        if inlier_flags[p] == 0u {
            continue;
        }
        let pair = pairs[p];
        let q = (pose * vec4<f32>(pair.src.xyz, 1.0)).xyz;
        let r = pair.dst.xyz - q;
        let omega = pair_information(pose, pair, params.f_px);
        let e = sqrt(max(dot(r, omega * r), 0.0));
        let w = select(huber / max(e, 1e-30), 1.0, e <= huber);
        // r(ξ) = dst − exp(ξ) q: ∂r/∂ω = [q]×, ∂r/∂t = −I (columns of J).
        var jc = array<vec3<f32>, 6>(
            vec3<f32>(0.0, q.z, -q.y), vec3<f32>(-q.z, 0.0, q.x), vec3<f32>(q.y, -q.x, 0.0),
            vec3<f32>(-1.0, 0.0, 0.0), vec3<f32>(0.0, -1.0, 0.0), vec3<f32>(0.0, 0.0, -1.0),
        );
        var oj: array<vec3<f32>, 6>;
        for (var i = 0u; i < 6u; i++) {
            oj[i] = omega * jc[i];
        }
        var f = 0u;
        for (var i = 0u; i < 6u; i++) {
            for (var j = i; j < 6u; j++) {
                acc[f] += w * dot(jc[i], oj[j]);
                f++;
            }
        }
        for (var i = 0u; i < 6u; i++) {
            acc[21u + i] += w * dot(oj[i], r);
        }
    }
    return acc;
}

// `params.iterations` Gauss-Newton steps on the current inliers from `sh_pose` when `running`
// (stopping at convergence or a singular system), the Huber threshold from `sh_scale`; every
// invocation calls it (it holds barriers) with the same `running`.
fn gauss_newton(lid: u32, n: u32, running: bool) {
    let huber = sqrt(CHI2_3DOF_95) * min(sh_scale, params.max_noise_scale);
    if lid == 0u {
        sh_converged = 0u;
    }
    for (var it = 0u; it < params.iterations; it++) {
        workgroupBarrier();
        let stepping = running && sh_state == REFINE_RUNNING && sh_converged == 0u;
        let pose = sh_pose;
        var acc: array<f32, GN_FLOATS>;
        if stepping {
            acc = accumulate(lid, n, pose, huber);
        }
        sh_sums[lid] = acc;
        reduce_sums(lid);
        if lid == 0u && stepping {
            solve_step();
        }
    }
}

// Invocation 0: one Gauss-Newton step from the reduced sums; updates sh_pose, or rejects when
// the system is singular, and marks convergence.
fn solve_step() {
    var a: array<f32, 36>;
    var g: array<f32, 6>;
    var f = 0u;
    for (var i = 0u; i < 6u; i++) {
        for (var j = i; j < 6u; j++) {
            a[i * 6u + j] = sh_sums[0][f];
            a[j * 6u + i] = sh_sums[0][f];
            f++;
        }
        g[i] = sh_sums[0][21u + i];
    }
    // Jacobi scaling: s = D A D with D = diag(1 / √a_ii), y = −D g; ξ = D z with s z = y.
    var d: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        if !(a[i * 7u] > 0.0) {
            sh_state = REFINE_REJECTED;
            return;
        }
        d[i] = 1.0 / sqrt(a[i * 7u]);
    }
    var sc: array<f32, 36>;
    var y: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        for (var j = 0u; j < 6u; j++) {
            sc[i * 6u + j] = a[i * 6u + j] * d[i] * d[j];
        }
        y[i] = -d[i] * g[i];
    }
    let solved = cholesky_solve6(sc, y, GN_MIN_PIVOT);
    if !solved.ok {
        sh_state = REFINE_REJECTED;
        return;
    }
    var xi = solved.x;
    var norm2 = 0.0;
    for (var i = 0u; i < 6u; i++) {
        xi[i] *= d[i];
        norm2 += xi[i] * xi[i];
    }
    if !is_valid_f32(norm2) {
        sh_state = REFINE_REJECTED;
        return;
    }
    sh_pose = orthonormalised(twist_exp_mat(vec3<f32>(xi[0], xi[1], xi[2]), vec3<f32>(xi[3], xi[4], xi[5])) * sh_pose);
    if sqrt(norm2) < GN_CONVERGED_STEP {
        sh_converged = 1u;
    }
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    let n = estimate.pairs;
    let hypothesis_count = min(params.hypotheses, RANSAC_MAX_HYPOTHESES);
    // 1. The least cost, the lower index among equals.
    var best_cost = RANSAC_NO_COST;
    var best = RANSAC_MAX_HYPOTHESES;
    for (var h = lid; h < hypothesis_count; h += RANSAC_REFINE_WORKGROUP) {
        if costs[h] < best_cost {
            best_cost = costs[h];
            best = h;
        }
    }
    sh_best_cost[lid] = best_cost;
    sh_best_index[lid] = best;
    for (var stride = RANSAC_REFINE_WORKGROUP / 2u; stride > 0u; stride >>= 1u) {
        workgroupBarrier();
        if lid < stride {
            let c = sh_best_cost[lid + stride];
            let i = sh_best_index[lid + stride];
            if c < sh_best_cost[lid] || (c == sh_best_cost[lid] && i < sh_best_index[lid]) {
                sh_best_cost[lid] = c;
                sh_best_index[lid] = i;
            }
        }
    }
    workgroupBarrier();
    if lid == 0u {
        best = sh_best_index[0];
        sh_state = select(REFINE_REJECTED, REFINE_RUNNING, best < hypothesis_count);
        sh_pose = mat4x4<f32>(vec4<f32>(1.0, 0.0, 0.0, 0.0), vec4<f32>(0.0, 1.0, 0.0, 0.0), vec4<f32>(0.0, 0.0, 1.0, 0.0), vec4<f32>(0.0, 0.0, 0.0, 1.0));
        if best < hypothesis_count {
            sh_pose = hypotheses[best];
        }
        sh_refits = 0u;
    }
    workgroupBarrier();
    let loose = CHI2_3DOF_95 * params.max_noise_scale * params.max_noise_scale;
    // 2, 3. The scale and the inliers of the best hypothesis.
    compute_residuals(lid, n, sh_pose);
    var scale = noise_scale(lid, n, loose);
    var bound = min(scale, params.max_noise_scale);
    var counts = classify(lid, n, CHI2_3DOF_95 * bound * bound, true);
    if lid == 0u {
        sh_scale = scale;
        sh_inliers = counts.x;
    }
    // 4. Refits until the inliers settle.
    for (var refit = 0u; refit < params.refits; refit++) {
        workgroupBarrier();
        if lid == 0u && sh_state == REFINE_RUNNING && sh_inliers < params.min_inliers {
            sh_state = REFINE_REJECTED;
        }
        workgroupBarrier();
        let running = sh_state == REFINE_RUNNING;
        gauss_newton(lid, n, running);
        workgroupBarrier();
        let still = running && sh_state == REFINE_RUNNING;
        if still {
            compute_residuals(lid, n, sh_pose);
        }
        scale = noise_scale(lid, n, loose);
        bound = min(scale, params.max_noise_scale);
        counts = classify(lid, n, CHI2_3DOF_95 * bound * bound, still);
        workgroupBarrier();
        if lid == 0u && still {
            sh_scale = scale;
            sh_inliers = counts.x;
            sh_refits += 1u;
            if counts.y == 0u {
                sh_state = REFINE_SETTLED;
            }
        }
    }
    // 4b. Inliers still changing after `refits`: Gauss-Newton once more on the last
    // classification (none after it), so the estimate is the optimum of the inliers it reports.
    workgroupBarrier();
    if lid == 0u && sh_state == REFINE_RUNNING && sh_inliers < params.min_inliers {
        sh_state = REFINE_REJECTED;
    }
    workgroupBarrier();
    gauss_newton(lid, n, sh_state == REFINE_RUNNING);
    // 5. The verdict and the inliers' RMS residual.
    workgroupBarrier();
    let pose = sh_pose;
    var sq = 0.0;
    for (var p = lid; p < n; p += RANSAC_REFINE_WORKGROUP) {
        if inlier_flags[p] == 1u {
            let r = pair_residual(pose, pairs[p]);
            sq += dot(r, r);
        }
    }
    var acc: array<f32, GN_FLOATS>;
    acc[0] = sq;
    sh_sums[lid] = acc;
    reduce_sums(lid);
    if lid == 0u {
        let accepted = sh_state != REFINE_REJECTED && sh_inliers >= params.min_inliers && sh_scale <= params.max_noise_scale;
        if accepted {
            estimate.dst_from_src = pose;
        }
        estimate.inliers = sh_inliers;
        estimate.accepted = select(0u, 1u, accepted);
        estimate.best_hypothesis = sh_best_index[0];
        estimate.noise_scale = sh_scale;
        estimate.rmse_m = sqrt(sh_sums[0][0] / f32(max(sh_inliers, 1u)));
        estimate.cost = sh_best_cost[0];
        estimate.refits = sh_refits;
    }
}
