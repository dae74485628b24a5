// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/ransac_refine.wgsl`: the workgroup's steps in order,
//! each invocation's share of the pairs (lid, lid + 64, ...) summed as it does and the sums
//! combined in its tree.

use crate::cpu::odometry::estimate::{CHI2_3DOF_95, CHI2_3DOF_MEDIAN, IDENTITY, RANSAC_MAX_HYPOTHESES, RANSAC_NO_COST, m3_mul_vec, pair_information, pair_normalised_residual, pair_residual};
use crate::cpu::shared::{Mat4, cholesky_solve6, dot3, is_valid_f32, mat4_mul, orthonormalised, transform_point, twist_exp_mat};
use crate::kernels::gpu_data::{FeaturePair, RansacParams, RigidEstimate};

/// Twin of `RANSAC_REFINE_WORKGROUP`.
pub const RANSAC_REFINE_WORKGROUP: usize = 64;
/// Twin of `GN_FLOATS`.
pub const GN_FLOATS: usize = 28;
/// Twin of `GN_CONVERGED_STEP`.
pub const GN_CONVERGED_STEP: f32 = 1e-7;
/// Twin of `GN_MIN_PIVOT`.
pub const GN_MIN_PIVOT: f32 = 1e-7;

#[derive(Clone, Copy, PartialEq, Eq)]
enum State {
    Running,
    Settled,
    Rejected,
}

/// The pairs of invocation `lid` among `n`.
fn owned(lid: usize, n: usize) -> impl Iterator<Item = usize> {
    (lid..n).step_by(RANSAC_REFINE_WORKGROUP)
}

/// Twin of `noise_scale()`: from the exact k-th smallest residual within `loose` (the bisection
/// on bit patterns finds exactly this value), at least 1.
fn noise_scale(residuals: &[f32], n: usize, loose: f32) -> f32 {
    let mut within: Vec<f32> = residuals[..n].iter().copied().filter(|&e| e <= loose).collect();
    if within.is_empty() {
        return 1.0;
    }
    let k = within.len() / 2;
    let (_, median, _) = within.select_nth_unstable_by(k, f32::total_cmp);
    (*median / CHI2_3DOF_MEDIAN).sqrt().max(1.0)
}

/// Twin of `classify()`: (inliers, flags changed).
fn classify(residuals: &[f32], flags: &mut [u32], n: usize, bound: f32, write: bool) -> (u32, u32) {
    let (mut inliers, mut changed) = (0, 0);
    for p in 0..n {
        let flag = u32::from(residuals[p] <= bound);
        inliers += flag;
        if write {
            changed += u32::from(flag != flags[p]);
            flags[p] = flag;
        }
    }
    (inliers, changed)
}

/// Twin of `reduce_sums()` over per-invocation sums.
fn reduce_sums(sums: &mut [[f32; GN_FLOATS]]) -> [f32; GN_FLOATS] {
    let mut stride = RANSAC_REFINE_WORKGROUP / 2;
    while stride > 0 {
        for lid in 0..stride {
            for f in 0..GN_FLOATS {
                sums[lid][f] += sums[lid + stride][f];
            }
        }
        stride /= 2;
    }
    sums[0]
}

/// Twin of `accumulate()`.
fn accumulate(params: &RansacParams, pairs: &[FeaturePair], flags: &[u32], lid: usize, n: usize, pose: &Mat4, huber: f32) -> [f32; GN_FLOATS] {
    let mut acc = [0.0f32; GN_FLOATS];
    for p in owned(lid, n) {
        if flags[p] == 0 {
            continue;
        }
        let pair = &pairs[p];
        let q = transform_point(pose, [pair.src[0], pair.src[1], pair.src[2]]);
        let r = [pair.dst[0] - q[0], pair.dst[1] - q[1], pair.dst[2] - q[2]];
        let omega = pair_information(pose, pair, params.f_px);
        let e = dot3(r, m3_mul_vec(&omega, r)).max(0.0).sqrt();
        let w = if e <= huber { 1.0 } else { huber / e.max(1e-30) };
        let jc = [[0.0, q[2], -q[1]], [-q[2], 0.0, q[0]], [q[1], -q[0], 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]];
        let oj = jc.map(|c| m3_mul_vec(&omega, c));
        let mut f = 0;
        for i in 0..6 {
            for j in i..6 {
                acc[f] += w * dot3(jc[i], oj[j]);
                f += 1;
            }
        }
        for i in 0..6 {
            acc[21 + i] += w * dot3(oj[i], r);
        }
    }
    acc
}

/// Twin of `solve_step()`: the updated pose and whether it converged, or `None` when singular.
fn solve_step(sums: &[f32; GN_FLOATS], pose: &Mat4) -> Option<(Mat4, bool)> {
    let mut a = [0.0f32; 36];
    let mut g = [0.0f32; 6];
    let mut f = 0;
    for i in 0..6 {
        for j in i..6 {
            a[i * 6 + j] = sums[f];
            a[j * 6 + i] = sums[f];
            f += 1;
        }
        g[i] = sums[21 + i];
    }
    let mut d = [0.0f32; 6];
    for i in 0..6 {
        if !(a[i * 7] > 0.0) {
            return None;
        }
        d[i] = 1.0 / a[i * 7].sqrt();
    }
    let mut sc = [0.0f32; 36];
    let mut y = [0.0f32; 6];
    for i in 0..6 {
        for j in 0..6 {
            sc[i * 6 + j] = a[i * 6 + j] * d[i] * d[j];
        }
        y[i] = -d[i] * g[i];
    }
    let mut xi = cholesky_solve6(&sc, &y, GN_MIN_PIVOT)?;
    let mut norm2 = 0.0f32;
    for i in 0..6 {
        xi[i] *= d[i];
        norm2 += xi[i] * xi[i];
    }
    if !is_valid_f32(norm2) {
        return None;
    }
    let updated = orthonormalised(&mat4_mul(&twist_exp_mat([xi[0], xi[1], xi[2]], [xi[3], xi[4], xi[5]]), pose));
    Some((updated, norm2.sqrt() < GN_CONVERGED_STEP))
}

/// Runs the kernel's one workgroup.
pub fn ransac_refine(params: &RansacParams, hypotheses: &[Mat4], costs: &[f32], pairs: &[FeaturePair], estimate: &mut RigidEstimate, residuals: &mut [f32], inlier_flags: &mut [u32]) {
    let n = estimate.pairs as usize;
    let hypothesis_count = params.hypotheses.min(RANSAC_MAX_HYPOTHESES);
    // 1. Per invocation the least cost of its hypotheses, then the tree.
    let mut best_cost = [RANSAC_NO_COST; RANSAC_REFINE_WORKGROUP];
    let mut best_index = [RANSAC_MAX_HYPOTHESES; RANSAC_REFINE_WORKGROUP];
    for lid in 0..RANSAC_REFINE_WORKGROUP {
        for h in (lid..hypothesis_count as usize).step_by(RANSAC_REFINE_WORKGROUP) {
            if costs[h] < best_cost[lid] {
                best_cost[lid] = costs[h];
                best_index[lid] = h as u32;
            }
        }
    }
    let mut stride = RANSAC_REFINE_WORKGROUP / 2;
    while stride > 0 {
        for lid in 0..stride {
            let (c, i) = (best_cost[lid + stride], best_index[lid + stride]);
            if c < best_cost[lid] || (c == best_cost[lid] && i < best_index[lid]) {
                best_cost[lid] = c;
                best_index[lid] = i;
            }
        }
        stride /= 2;
    }
    let best = best_index[0];
    let mut state = if best < hypothesis_count { State::Running } else { State::Rejected };
    let mut pose = if best < hypothesis_count { hypotheses[best as usize] } else { IDENTITY };
    let mut refits = 0;
    let loose = CHI2_3DOF_95 * params.max_noise_scale * params.max_noise_scale;
    let compute = |pose: &Mat4, residuals: &mut [f32]| {
        for p in 0..n {
            residuals[p] = pair_normalised_residual(pose, &pairs[p], params.f_px);
        }
    };
    // 2, 3.
    compute(&pose, residuals);
    let mut scale = noise_scale(residuals, n, loose);
    let bound = scale.min(params.max_noise_scale);
    let (mut inliers, _) = classify(residuals, inlier_flags, n, CHI2_3DOF_95 * bound * bound, true);
    // `params.iterations` Gauss-Newton steps on the inliers when `running` (the kernel's
    // `gauss_newton`).
    let gauss_newton = |pose: &mut Mat4, state: &mut State, inlier_flags: &[u32], scale: f32, running: bool| {
        let huber = CHI2_3DOF_95.sqrt() * scale.min(params.max_noise_scale);
        let mut converged = false;
        for _ in 0..params.iterations {
            if !(running && *state == State::Running && !converged) {
                continue;
            }
            let mut sums: Vec<[f32; GN_FLOATS]> = (0..RANSAC_REFINE_WORKGROUP).map(|lid| accumulate(params, pairs, inlier_flags, lid, n, pose, huber)).collect();
            match solve_step(&reduce_sums(&mut sums), pose) {
                Some((next, done)) => {
                    *pose = next;
                    converged = done;
                }
                None => *state = State::Rejected,
            }
        }
    };
    // 4.
    for _ in 0..params.refits {
        if state == State::Running && inliers < params.min_inliers {
            state = State::Rejected;
        }
        let running = state == State::Running;
        gauss_newton(&mut pose, &mut state, inlier_flags, scale, running);
        let still = running && state == State::Running;
        if still {
            compute(&pose, residuals);
        }
        let next_scale = noise_scale(residuals, n, loose);
        let bound = next_scale.min(params.max_noise_scale);
        let (next_inliers, changed) = classify(residuals, inlier_flags, n, CHI2_3DOF_95 * bound * bound, still);
        if still {
            scale = next_scale;
            inliers = next_inliers;
            refits += 1;
            if changed == 0 {
                state = State::Settled;
            }
        }
    }
    // 4b. Inliers still changing: once more on the last classification.
    if state == State::Running && inliers < params.min_inliers {
        state = State::Rejected;
    }
    let unsettled = state == State::Running;
    gauss_newton(&mut pose, &mut state, inlier_flags, scale, unsettled);
    // 5.
    let mut sums: Vec<[f32; GN_FLOATS]> = (0..RANSAC_REFINE_WORKGROUP)
        .map(|lid| {
            let mut acc = [0.0f32; GN_FLOATS];
            for p in owned(lid, n) {
                if inlier_flags[p] == 1 {
                    let r = pair_residual(&pose, &pairs[p]);
                    acc[0] += dot3(r, r);
                }
            }
            acc
        })
        .collect();
    let sq = reduce_sums(&mut sums)[0];
    let accepted = state != State::Rejected && inliers >= params.min_inliers && scale <= params.max_noise_scale;
    if accepted {
        estimate.dst_from_src = pose;
    }
    estimate.inliers = inliers;
    estimate.accepted = u32::from(accepted);
    estimate.best_hypothesis = best;
    estimate.noise_scale = scale;
    estimate.rmse_m = (sq / inliers.max(1) as f32).sqrt();
    estimate.cost = best_cost[0];
    estimate.refits = refits;
}
