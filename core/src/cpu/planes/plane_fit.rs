// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_fit.wgsl` and `shared/plane_fitting.wgsl`, in
//! f32 like the kernel
//! ([`crate::planes::reference::fit`] is the f64 fit both are held to).

use crate::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments};
use crate::cpu::shared::dot3 as dot;
use crate::kernels::plane_fit::PlaneFitParams;

/// vec4s per fitted plane.
pub const PLANE_FIT_VEC4S: usize = 5;
/// Twin of `JACOBI_TOLERANCE`.
pub const JACOBI_TOLERANCE: f32 = 1e-10;
/// Twin of `JACOBI_SWEEPS`.
pub const JACOBI_SWEEPS: u32 = 20;

type M3 = [[f32; 3]; 3];

/// Twin of `eigen_symmetric3()`: eigenvalues ascending, and `vectors[i]` the unit eigenvector
/// of `values[i]`.
pub fn eigen_symmetric3_f32(m: M3) -> ([f32; 3], [[f32; 3]; 3]) {
    let mut a = m;
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0f32]];
    let scale = a[0][0].abs().max(a[1][1].abs()).max(a[2][2].abs().max(1e-30));
    for _ in 0..JACOBI_SWEEPS {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (JACOBI_TOLERANCE * scale) * (JACOBI_TOLERANCE * scale) {
            break;
        }
        for (p, q) in [(0usize, 1usize), (0, 2), (1, 2)] {
            let o = 3 - p - q;
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = if theta >= 0.0 { 1.0 } else { -1.0 } / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            let (aop, aoq) = (a[o][p], a[o][q]);
            a[p][p] -= t * apq;
            a[q][q] += t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            a[o][p] = c * aop - s * aoq;
            a[p][o] = a[o][p];
            a[o][q] = s * aop + c * aoq;
            a[q][o] = a[o][q];
            for row in &mut v {
                let (vip, viq) = (row[p], row[q]);
                row[p] = c * vip - s * viq;
                row[q] = s * vip + c * viq;
            }
        }
    }
    let (mut values, mut vectors) = ([0.0f32; 3], [[0.0f32; 3]; 3]);
    for i in 0..3 {
        let rank = (0..3).filter(|&j| a[j][j] < a[i][i] || (a[j][j] == a[i][i] && j < i)).count();
        values[rank] = a[i][i];
        vectors[rank] = [v[0][i], v[1][i], v[2][i]];
    }
    (values, vectors)
}

fn quadratic(m: &M3, v: [f32; 3]) -> f32 {
    let mut sum = 0.0;
    for i in 0..3 {
        let mut row = 0.0;
        for j in 0..3 {
            row += v[i] * m[i][j] * v[j];
        }
        sum += row;
    }
    sum
}

fn symmetric(diagonal: [f32; 4], off: [f32; 4], k: f32) -> M3 {
    [[diagonal[0] * k, off[0] * k, off[1] * k], [off[0] * k, diagonal[1] * k, off[2] * k], [off[1] * k, off[2] * k, diagonal[2] * k]]
}

/// Twin of `plane_fit_moments()` in `shared/plane_fitting.wgsl`: the fit of one set of moments.
pub fn plane_fit_moments(m: &PlaneMoments) -> [[f32; 4]; PLANE_FIT_VEC4S] {
    let count = m[0][0];
    if !(count >= 3.0) {
        return [[0.0; 4]; PLANE_FIT_VEC4S];
    }
    let k = 1.0 / count;
    let centroid = [m[1][0], m[1][1], m[1][2]];
    let raw_cov = symmetric(m[3], m[4], k);
    let noise = symmetric(m[8], m[9], k);
    let (mut values, mut vectors) = eigen_symmetric3_f32(raw_cov);
    for _ in 0..2 {
        let predicted = quadratic(&noise, vectors[0]);
        if !(predicted > 0.0) {
            break;
        }
        let level = (quadratic(&raw_cov, vectors[0]) / predicted).clamp(0.0, 1.0);
        let cov: M3 = std::array::from_fn(|i| std::array::from_fn(|j| raw_cov[i][j] - level * noise[i][j]));
        (values, vectors) = eigen_symmetric3_f32(cov);
    }
    let mut normal = vectors[0];
    if dot(normal, centroid) > 0.0 {
        normal = normal.map(|x| -x);
    }
    let cov_np: M3 = std::array::from_fn(|i| std::array::from_fn(|j| m[5 + i][j] * k));
    let tangents = [vectors[2], vectors[1]];
    let variance = [values[2].max(0.0), values[1].max(0.0)];
    let mut bend = 0.0f32;
    for a in 0..2 {
        if variance[a] > 0.0 {
            let rate = quadratic(&cov_np, tangents[a]) / variance[a];
            bend = bend.max(rate.abs() * (12.0 * variance[a]).sqrt());
        }
    }
    let v4 = |v: [f32; 3], w: f32| [v[0], v[1], v[2], w];
    [
        v4(normal, -dot(normal, centroid)),
        v4(centroid, count),
        v4(tangents[0], variance[0]),
        v4(tangents[1], variance[1]),
        [quadratic(&raw_cov, normal).max(0.0).sqrt(), bend.to_degrees(), m[0][1], 1.0],
    ]
}

/// Fits every plane as the kernel's invocations do.
pub fn plane_fit(params: &PlaneFitParams, moments: &[[f32; 4]], fits: &mut [[f32; 4]]) {
    for plane in 0..params.plane_count as usize {
        let m: PlaneMoments = moments[plane * PLANE_MOMENT_VEC4S..(plane + 1) * PLANE_MOMENT_VEC4S].try_into().expect("10 vec4");
        fits[plane * PLANE_FIT_VEC4S..(plane + 1) * PLANE_FIT_VEC4S].copy_from_slice(&plane_fit_moments(&m));
    }
}
