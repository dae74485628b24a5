// SPDX-License-Identifier: MIT
//! Solves one Gauss-Newton step of the tracker on the GPU, so no iteration waits for the host.
//! One workgroup of 32 invocations: invocation i adds float i of every `track_reduce`
//! workgroup's partial sums; then invocation 0, unless this level is already done, assembles
//! JᵀJ (6 × 6) and Jᵀr and scales the system: rotation columns by `rotation_scale_m` (a
//! rotation of θ rad weighs like a translation of θ · that length) and the whole matrix by
//! 6 / trace, so its eigenvalues average 1 and f32 resolves them to ~1e-6. It computes the
//! condition numbers (cyclic Jacobi eigenvalues) of the scaled matrix and of its translation
//! block (the distribution of the surface normals, and photometric gradients, over the three
//! directions of translation): above `max_condition` the system is numerically rank-deficient
//! in f32, above `max_translation_condition` a direction of translation carries no more
//! information than noisy normals alone would fake (a corridor, a single wall), so the step is
//! not taken (it would be noise along that direction) and the level ends. Otherwise it
//! factors the scaled matrix (Cholesky), solves for the twist ξ = (ω, t) minimising
//! Σ (r + J ξ)², and updates the estimate to [R(ω) | t] · estimate (re-orthonormalised). The
//! level also ends, and its remaining `track_reduce` dispatches get 0 workgroups, once an
//! update moves no point within `reference_depth_m` by more than `converged_update_m`
//! (|t| + |ω| · reference depth), or when the system is not positive definite.
#import invalid
#import camera
#import linear_solve
#import rigid
#import track_state

@group(0) @binding(0) var<uniform> params: TrackParams;
// `reduce_workgroups` × 32 floats from `track_reduce`.
@group(0) @binding(1) var<storage, read> partial_sums: array<f32>;
// The tracker's state: the estimate is updated, this level's statistics written.
@group(0) @binding(2) var<storage, read_write> state: TrackState;
// `track_reduce`'s indirect dispatch arguments: zeroed for this level once it is done.
@group(0) @binding(3) var<storage, read_write> dispatch: TrackDispatch;

var<workgroup> sh_sums: array<f32, 32>;

// Largest over smallest eigenvalue of the symmetric n × n (n <= 6) leading block of `m_in`
// (row-major, stride 6), by cyclic Jacobi rotations; CONDITION_SINGULAR when the smallest is
// not positive.
fn condition_number(m_in: array<f32, 36>, n: u32) -> f32 {
    var m = m_in;
    for (var sweep = 0u; sweep < 12u; sweep++) {
        var off = 0.0;
        for (var p = 0u; p < n; p++) {
            for (var q = p + 1u; q < n; q++) {
                off += m[p * 6u + q] * m[p * 6u + q];
            }
        }
        if off < 1e-24 {
            break;
        }
        for (var p = 0u; p + 1u < n; p++) {
            for (var q = p + 1u; q < n; q++) {
                let apq = m[p * 6u + q];
                if abs(apq) < 1e-30 {
                    continue;
                }
                let theta = (m[q * 6u + q] - m[p * 6u + p]) / (2.0 * apq);
                var t = 0.5 / theta;
                if abs(theta) < 1e10 {
                    t = sign(theta) / (abs(theta) + sqrt(theta * theta + 1.0));
                    if theta == 0.0 {
                        t = 1.0;
                    }
                }
                let c = 1.0 / sqrt(t * t + 1.0);
                let s = t * c;
                for (var k = 0u; k < n; k++) {
                    let mkp = m[k * 6u + p];
                    let mkq = m[k * 6u + q];
                    m[k * 6u + p] = c * mkp - s * mkq;
                    m[k * 6u + q] = s * mkp + c * mkq;
                }
                for (var k = 0u; k < n; k++) {
                    let mpk = m[p * 6u + k];
                    let mqk = m[q * 6u + k];
                    m[p * 6u + k] = c * mpk - s * mqk;
                    m[q * 6u + k] = s * mpk + c * mqk;
                }
            }
        }
    }
    var lo = m[0];
    var hi = m[0];
    for (var i = 1u; i < n; i++) {
        lo = min(lo, m[i * 7u]);
        hi = max(hi, m[i * 7u]);
    }
    if !(lo > 0.0) {
        return CONDITION_SINGULAR;
    }
    return min(hi / lo, CONDITION_SINGULAR);
}

@compute @workgroup_size(32, 1, 1)
fn main(@builtin(local_invocation_index) lid: u32) {
    var sum = 0.0;
    for (var w = 0u; w < params.reduce_workgroups; w++) {
        sum += partial_sums[w * 32u + lid];
    }
    sh_sums[lid] = sum;
    workgroupBarrier();
    if lid != 0u {
        return;
    }
    let level = params.level;
    let bit = 1u << level;
    if (state.done_levels & bit) != 0u {
        return;
    }
    var stats = state.levels[level];
    stats.iterations += 1u;
    stats.inliers = u32(sh_sums[28] + 0.5);
    stats.rgb_pairs = u32(sh_sums[30] + 0.5);
    stats.rms_residual_m = sqrt(sh_sums[27] / max(sh_sums[28], 1.0));

    // Scaled system: s = c D A D, y = -c D b with D = diag(L, L, L, 1, 1, 1) and c = 6 / trace
    // of D A D; then ξ = D z with s z = y.
    var a: array<f32, 36>;
    var kk = 0u;
    for (var i = 0u; i < 6u; i++) {
        for (var j = i; j < 6u; j++) {
            a[i * 6u + j] = sh_sums[kk];
            a[j * 6u + i] = sh_sums[kk];
            kk++;
        }
    }
    let rl = params.rotation_scale_m;
    var d = array<f32, 6>(rl, rl, rl, 1.0, 1.0, 1.0);
    var trace = 0.0;
    for (var i = 0u; i < 6u; i++) {
        trace += a[i * 7u] * d[i] * d[i];
    }
    var ok = trace > 0.0 && is_valid_f32(trace);
    let c = select(0.0, 6.0 / trace, ok);
    var s: array<f32, 36>;
    var y: array<f32, 6>;
    for (var i = 0u; i < 6u; i++) {
        for (var j = 0u; j < 6u; j++) {
            s[i * 6u + j] = c * a[i * 6u + j] * d[i] * d[j];
        }
        y[i] = -c * sh_sums[21u + i] * d[i];
    }
    stats.condition = CONDITION_SINGULAR;
    stats.translation_condition = CONDITION_SINGULAR;
    if ok {
        stats.condition = condition_number(s, 6u);
        // The translation block (rows and columns 3..6) moved to the leading 3 × 3.
        var t: array<f32, 36>;
        for (var i = 0u; i < 3u; i++) {
            for (var j = 0u; j < 3u; j++) {
                t[i * 6u + j] = s[(i + 3u) * 6u + j + 3u];
            }
        }
        stats.translation_condition = condition_number(t, 3u);
        ok = stats.condition <= params.max_condition && stats.translation_condition <= params.max_translation_condition;
    }
    // Cholesky s = L Lᵀ, then L g = y, Lᵀ z = g (shared/linear_solve.wgsl).
    var xi: array<f32, 6>;
    if ok {
        let solved = cholesky_solve6(s, y, 1e-12);
        ok = solved.ok;
        if !ok {
            stats.condition = CONDITION_SINGULAR;
        }
        xi = solved.x;
    }
    if ok {
        for (var i = 0u; i < 6u; i++) {
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
        dispatch.reduce[level] = vec4<u32>(0u, 1u, 1u, 0u);
        return;
    }
    let omega = vec3<f32>(xi[0], xi[1], xi[2]);
    let t = vec3<f32>(xi[3], xi[4], xi[5]);
    state.estimate = orthonormalised(twist_exp_mat(omega, t) * state.estimate);
    stats.last_update_m = length(t) + length(omega) * params.reference_depth_m;
    state.levels[level] = stats;
    if stats.last_update_m <= params.converged_update_m {
        state.done_levels |= bit;
        dispatch.reduce[level] = vec4<u32>(0u, 1u, 1u, 0u);
    }
}
