// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/track_solve.wgsl`, statement by statement in f32: the
//! same sum order over the partials, scaling, cyclic Jacobi eigenvalues, Cholesky and update.

use crate::cpu::shared::{cholesky_solve6, is_valid_f32, mat4_mul, orthonormalised, twist_exp_mat};
use crate::kernels::track_solve::{TrackDispatch, TrackParams, TrackState};

/// Twin of `CONDITION_SINGULAR`.
pub const CONDITION_SINGULAR: f32 = 1e30;

/// Twin of `condition_number()`: largest over smallest eigenvalue of the symmetric n × n
/// leading block of `m_in` (row-major, stride 6) by cyclic Jacobi rotations;
/// [`CONDITION_SINGULAR`] when the smallest is not positive.
pub fn condition_number(m_in: &[f32; 36], n: usize) -> f32 {
    let mut m = *m_in;
    for _sweep in 0..12 {
        let mut off = 0.0f32;
        for p in 0..n {
            for q in p + 1..n {
                off += m[p * 6 + q] * m[p * 6 + q];
            }
        }
        if off < 1e-24 {
            break;
        }
        for p in 0..n.saturating_sub(1) {
            for q in p + 1..n {
                let apq = m[p * 6 + q];
                if apq.abs() < 1e-30 {
                    continue;
                }
                let theta = (m[q * 6 + q] - m[p * 6 + p]) / (2.0 * apq);
                let mut t = 0.5 / theta;
                if theta.abs() < 1e10 {
                    t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                    if theta == 0.0 {
                        t = 1.0;
                    }
                }
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (mkp, mkq) = (m[k * 6 + p], m[k * 6 + q]);
                    m[k * 6 + p] = c * mkp - s * mkq;
                    m[k * 6 + q] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let (mpk, mqk) = (m[p * 6 + k], m[q * 6 + k]);
                    m[p * 6 + k] = c * mpk - s * mqk;
                    m[q * 6 + k] = s * mpk + c * mqk;
                }
            }
        }
    }
    let (mut lo, mut hi) = (m[0], m[0]);
    for i in 1..n {
        lo = lo.min(m[i * 7]);
        hi = hi.max(m[i * 7]);
    }
    if !(lo > 0.0) {
        return CONDITION_SINGULAR;
    }
    (hi / lo).min(CONDITION_SINGULAR)
}

/// One invocation of the kernel's workgroup: sums the partials, then solves and updates `state`
/// and `dispatch` as invocation 0 does.
pub fn track_solve(params: &TrackParams, partial_sums: &[f32], state: &mut TrackState, dispatch: &mut TrackDispatch) {
    let mut sums = [0.0f32; 32];
    for (lid, s) in sums.iter_mut().enumerate() {
        for w in 0..params.reduce_workgroups as usize {
            *s += partial_sums[w * 32 + lid];
        }
    }
    let level = params.level as usize;
    let bit = 1u32 << level;
    if state.done_levels & bit != 0 {
        return;
    }
    let mut stats = state.levels[level];
    stats.iterations += 1;
    stats.inliers = (sums[28] + 0.5) as u32;
    stats.rgb_pairs = (sums[30] + 0.5) as u32;
    stats.rms_residual_m = (sums[27] / sums[28].max(1.0)).sqrt();

    let mut a = [0.0f32; 36];
    let mut kk = 0;
    for i in 0..6 {
        for j in i..6 {
            a[i * 6 + j] = sums[kk];
            a[j * 6 + i] = sums[kk];
            kk += 1;
        }
    }
    let rl = params.rotation_scale_m;
    let d = [rl, rl, rl, 1.0, 1.0, 1.0];
    let mut trace = 0.0f32;
    for i in 0..6 {
        trace += a[i * 7] * d[i] * d[i];
    }
    let mut ok = trace > 0.0 && is_valid_f32(trace);
    let c = if ok { 6.0 / trace } else { 0.0 };
    let mut s = [0.0f32; 36];
    let mut y = [0.0f32; 6];
    for i in 0..6 {
        for j in 0..6 {
            s[i * 6 + j] = c * a[i * 6 + j] * d[i] * d[j];
        }
        y[i] = -c * sums[21 + i] * d[i];
    }
    stats.condition = CONDITION_SINGULAR;
    stats.translation_condition = CONDITION_SINGULAR;
    if ok {
        stats.condition = condition_number(&s, 6);
        let mut t = [0.0f32; 36];
        for i in 0..3 {
            for j in 0..3 {
                t[i * 6 + j] = s[(i + 3) * 6 + j + 3];
            }
        }
        stats.translation_condition = condition_number(&t, 3);
        ok = stats.condition <= params.max_condition && stats.translation_condition <= params.max_translation_condition;
    }
    let mut xi = [0.0f32; 6];
    if ok {
        match cholesky_solve6(&s, &y, 1e-12) {
            Some(x) => xi = x,
            None => {
                stats.condition = CONDITION_SINGULAR;
                ok = false;
            }
        }
    }
    if ok {
        for i in 0..6 {
            xi[i] *= d[i];
            ok = ok && is_valid_f32(xi[i]);
        }
        if !ok {
            stats.condition = CONDITION_SINGULAR;
        }
    }
    if !ok {
        stats.last_update_m = 0.0;
        state.levels[level] = stats;
        state.done_levels |= bit;
        dispatch.reduce[level] = [0, 1, 1, 0];
        return;
    }
    let omega = [xi[0], xi[1], xi[2]];
    let t = [xi[3], xi[4], xi[5]];
    state.estimate = orthonormalised(&mat4_mul(&twist_exp_mat(omega, t), &state.estimate));
    let len = |v: [f32; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    stats.last_update_m = len(t) + len(omega) * params.reference_depth_m;
    state.levels[level] = stats;
    if stats.last_update_m <= params.converged_update_m {
        state.done_levels |= bit;
        dispatch.reduce[level] = [0, 1, 1, 0];
    }
}
