// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/shared/rigid_estimate.wgsl`: the Kinect noise of a matched
//! pair's residual and Kabsch on three pairs, in f32 like the kernels (3 × 3 matrices as WGSL's
//! `mat3x3`: an array of columns).

use crate::cpu::planes::plane_fit::eigen_symmetric3_f32;
use crate::cpu::shared::{Mat4, cross3, dot3, kinect_sigma_m, normalize3, transform_point};
use crate::kernels::gpu_data::FeaturePair;

/// Twin of `CHI2_3DOF_95`.
pub const CHI2_3DOF_95: f32 = 7.815;
/// Twin of `CHI2_3DOF_MEDIAN`.
pub const CHI2_3DOF_MEDIAN: f32 = 2.366;
/// Twin of `RANSAC_MAX_HYPOTHESES`.
pub const RANSAC_MAX_HYPOTHESES: u32 = 256;
/// Twin of `RANSAC_NO_COST`.
pub const RANSAC_NO_COST: f32 = 3.0e38;
/// Twin of `RANSAC_MIN_SAMPLE_AREA_M2`.
pub const RANSAC_MIN_SAMPLE_AREA_M2: f32 = 0.0025;
/// Twin of `KABSCH_MIN_SINGULAR_RATIO`.
pub const KABSCH_MIN_SINGULAR_RATIO: f32 = 1e-3;

/// A 3 × 3 matrix as WGSL's `mat3x3<f32>`: `m[c]` is column c.
pub type M3 = [[f32; 3]; 3];

/// The identity transform.
pub const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// `m · v`.
pub fn m3_mul_vec(m: &M3, v: [f32; 3]) -> [f32; 3] {
    [0, 1, 2].map(|r| m[0][r] * v[0] + m[1][r] * v[1] + m[2][r] * v[2])
}

/// `a · b`.
pub fn m3_mul(a: &M3, b: &M3) -> M3 {
    [m3_mul_vec(a, b[0]), m3_mul_vec(a, b[1]), m3_mul_vec(a, b[2])]
}

/// `mᵀ`.
pub fn m3_transpose(m: &M3) -> M3 {
    [0, 1, 2].map(|c| [m[0][c], m[1][c], m[2][c]])
}

fn m3_add(a: &M3, b: &M3) -> M3 {
    [0, 1, 2].map(|c| [0, 1, 2].map(|r| a[c][r] + b[c][r]))
}

fn sub3(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn scale3(a: [f32; 3], k: f32) -> [f32; 3] {
    a.map(|c| c * k)
}

fn xyz(v: [f32; 4]) -> [f32; 3] {
    [v[0], v[1], v[2]]
}

/// Twin of `point_covariance()`.
pub fn point_covariance(p: [f32; 3], level: f32, f_px: f32) -> M3 {
    let axial = kinect_sigma_m(p[2]);
    let lateral = p[2] * (1u32 << level as u32) as f32 / f_px;
    let ray = normalize3(p);
    let k = axial * axial - lateral * lateral;
    let l2 = lateral * lateral;
    [
        [k * ray[0] * ray[0] + l2, k * ray[1] * ray[0], k * ray[2] * ray[0]],
        [k * ray[0] * ray[1], k * ray[1] * ray[1] + l2, k * ray[2] * ray[1]],
        [k * ray[0] * ray[2], k * ray[1] * ray[2], k * ray[2] * ray[2] + l2],
    ]
}

/// Twin of `rotation_of()`.
pub fn rotation_of(m: &Mat4) -> M3 {
    [xyz(m[0]), xyz(m[1]), xyz(m[2])]
}

/// Twin of `symmetric_inverse3()`.
pub fn symmetric_inverse3(c: &M3) -> M3 {
    let a00 = c[1][1] * c[2][2] - c[2][1] * c[1][2];
    let a01 = c[2][0] * c[1][2] - c[1][0] * c[2][2];
    let a02 = c[1][0] * c[2][1] - c[2][0] * c[1][1];
    let det = c[0][0] * a00 + c[0][1] * a01 + c[0][2] * a02;
    if !(det > 0.0) {
        return [[0.0; 3]; 3];
    }
    let a11 = c[0][0] * c[2][2] - c[2][0] * c[0][2];
    let a12 = c[2][0] * c[0][1] - c[0][0] * c[2][1];
    let a22 = c[0][0] * c[1][1] - c[1][0] * c[0][1];
    let inv = 1.0 / det;
    [[a00 * inv, a01 * inv, a02 * inv], [a01 * inv, a11 * inv, a12 * inv], [a02 * inv, a12 * inv, a22 * inv]]
}

/// Twin of `pair_information()`.
pub fn pair_information(pose: &Mat4, pair: &FeaturePair, f_px: f32) -> M3 {
    let r = rotation_of(pose);
    let rotated = m3_mul(&m3_mul(&r, &point_covariance(xyz(pair.src), pair.src[3], f_px)), &m3_transpose(&r));
    symmetric_inverse3(&m3_add(&rotated, &point_covariance(xyz(pair.dst), pair.dst[3], f_px)))
}

/// Twin of `pair_residual()`.
pub fn pair_residual(pose: &Mat4, pair: &FeaturePair) -> [f32; 3] {
    sub3(xyz(pair.dst), transform_point(pose, xyz(pair.src)))
}

/// Twin of `pair_normalised_residual()`.
pub fn pair_normalised_residual(pose: &Mat4, pair: &FeaturePair, f_px: f32) -> f32 {
    let r = pair_residual(pose, pair);
    let info = pair_information(pose, pair, f_px);
    if !(info[0][0] > 0.0) {
        return RANSAC_NO_COST;
    }
    dot3(r, m3_mul_vec(&info, r)).max(0.0)
}

/// Twin of `kabsch3()`: reference_from_current of three pairs, column 3's w = 0 when degenerate.
pub fn kabsch3(a0: [f32; 3], a1: [f32; 3], a2: [f32; 3], b0: [f32; 3], b1: [f32; 3], b2: [f32; 3]) -> Mat4 {
    let centroid = |p: [f32; 3], q: [f32; 3], s: [f32; 3]| [0, 1, 2].map(|i| (p[i] + q[i] + s[i]) / 3.0);
    let (ca, cb) = (centroid(a0, a1, a2), centroid(b0, b1, b2));
    let a = [sub3(a0, ca), sub3(a1, ca), sub3(a2, ca)];
    let b = [sub3(b0, cb), sub3(b1, cb), sub3(b2, cb)];
    let mut h = [[0.0f32; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            h[r][c] = a[0][r] * b[0][c] + a[1][r] * b[1][c] + a[2][r] * b[2][c];
        }
    }
    let mut hth = [[0.0f32; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            hth[i][j] = h[0][i] * h[0][j] + h[1][i] * h[1][j] + h[2][i] * h[2][j];
        }
    }
    let (values, vectors) = eigen_symmetric3_f32(hth);
    let s1 = values[2].max(0.0).sqrt();
    let s2 = values[1].max(0.0).sqrt();
    if !(s1 > 0.0) || !(s2 > KABSCH_MIN_SINGULAR_RATIO * s1) {
        return [[0.0; 4]; 4];
    }
    let (v1, v2) = (vectors[2], vectors[1]);
    let hm: M3 = [[h[0][0], h[1][0], h[2][0]], [h[0][1], h[1][1], h[2][1]], [h[0][2], h[1][2], h[2][2]]];
    let u1 = normalize3(m3_mul_vec(&hm, v1));
    let w2 = m3_mul_vec(&hm, v2);
    let u2 = normalize3(sub3(w2, scale3(u1, dot3(w2, u1))));
    let u3 = cross3(u1, u2);
    let v3 = cross3(v1, v2);
    let col = |c: usize| [0, 1, 2].map(|r| v1[r] * u1[c] + v2[r] * u2[c] + v3[r] * u3[c]);
    let rot: M3 = [col(0), col(1), col(2)];
    let t = sub3(cb, m3_mul_vec(&rot, ca));
    [[rot[0][0], rot[0][1], rot[0][2], 0.0], [rot[1][0], rot[1][1], rot[1][2], 0.0], [rot[2][0], rot[2][1], rot[2][2], 0.0], [t[0], t[1], t[2], 1.0]]
}
