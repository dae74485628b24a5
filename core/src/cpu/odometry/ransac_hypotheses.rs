// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/odometry/ransac_hypotheses.wgsl`.

use crate::cpu::odometry::estimate::{CHI2_3DOF_95, RANSAC_MIN_SAMPLE_AREA_M2, RANSAC_NO_COST, kabsch3, pair_normalised_residual};
use crate::cpu::shared::{Mat4, cross3, dot3, pcg_hash};
use crate::kernels::gpu_data::{FeaturePair, RansacParams, RigidEstimate};

/// Twin of `RANSAC_HYPOTHESES_WORKGROUP`.
pub const RANSAC_HYPOTHESES_WORKGROUP: usize = 64;

/// Sample `h`'s pose (column 3's w = 0 when unusable), as invocation 0 draws and fits it.
pub fn ransac_sample(params: &RansacParams, pairs: &[FeaturePair], n: u32, h: u32) -> Mat4 {
    if n < params.min_inliers.max(3) {
        return [[0.0; 4]; 4];
    }
    let mut state = pcg_hash(pcg_hash(h) ^ params.seed);
    state = pcg_hash(state);
    let i = state % n;
    state = pcg_hash(state);
    let mut j = state % n;
    state = pcg_hash(state);
    let mut k = state % n;
    if j == i || k == i || k == j {
        j = (i + 1 + j % (n - 1)) % n;
        k = (i + 2 + k % (n - 2).max(1)) % n;
    }
    let (a, b, c) = (&pairs[i as usize], &pairs[j as usize], &pairs[k as usize]);
    let p = |v: [f32; 4]| [v[0], v[1], v[2]];
    let (ab, ac) = ([0, 1, 2].map(|x| b.src[x] - a.src[x]), [0, 1, 2].map(|x| c.src[x] - a.src[x]));
    let cr = cross3(ab, ac);
    let area = dot3(cr, cr).sqrt();
    if j != i && k != i && k != j && area >= RANSAC_MIN_SAMPLE_AREA_M2 {
        return kabsch3(p(a.src), p(b.src), p(c.src), p(a.dst), p(b.dst), p(c.dst));
    }
    [[0.0; 4]; 4]
}

/// Draws and scores hypotheses `0..params.hypotheses` (one workgroup each) as the kernel does.
pub fn ransac_hypotheses(params: &RansacParams, pairs: &[FeaturePair], estimate: &RigidEstimate, hypotheses: &mut [Mat4], costs: &mut [f32]) {
    let n = estimate.pairs;
    let loose = CHI2_3DOF_95 * params.max_noise_scale * params.max_noise_scale;
    for h in 0..params.hypotheses {
        let pose = ransac_sample(params, pairs, n, h);
        let usable = pose[3][3] == 1.0;
        let mut scratch = [0.0f32; RANSAC_HYPOTHESES_WORKGROUP];
        if usable {
            for (lid, cost) in scratch.iter_mut().enumerate() {
                for p in (lid..n as usize).step_by(RANSAC_HYPOTHESES_WORKGROUP) {
                    *cost += pair_normalised_residual(&pose, &pairs[p], params.f_px).min(loose);
                }
            }
        }
        let mut stride = RANSAC_HYPOTHESES_WORKGROUP / 2;
        while stride > 0 {
            for lid in 0..stride {
                scratch[lid] += scratch[lid + stride];
            }
            stride /= 2;
        }
        hypotheses[h as usize] = pose;
        costs[h as usize] = if usable { scratch[0] } else { RANSAC_NO_COST };
    }
}
