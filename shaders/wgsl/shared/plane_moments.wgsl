// SPDX-License-Identifier: MIT
// Moments of a set of plane pixels (seed 003's plane statistics, §4.3.3), kept centred so that
// f32 holds the scatter of points metres from the camera: summing p pᵀ and subtracting the
// mean's square afterwards (003's form) loses a plane's millimetre thickness to rounding at
// 3 m. Two sets combine by Chan, Golub and LeVeque's pairwise update, so a tree reduction in
// workgroup memory or a walk over a pixel list gives the same moments as f64 sums to f32's
// precision. Layout, PLANE_MOMENT_VEC4S vec4 per set:
//   [0] (count, Σ footprint area m², 0, 0)
//   [1] (mean point, 0)           [2] (mean normal, 0)
//   [3] (S_xx, S_yy, S_zz, 0)     [4] (S_xy, S_xz, S_yz, 0): S = Σ (p - p̄)(p - p̄)ᵀ
//   [5 + i] (Σ (n_i - n̄_i)(p - p̄)ᵀ, 0) for i = 0, 1, 2: the normal-point cross scatter
//   [8] noise diagonal, [9] noise off-diagonal (xy, xz, yz): Σ σ(z)² r rᵀ, a plain sum
// Mirrors core/src/cpu/shared.rs (plane_moments_point, plane_moments_combine).

const PLANE_MOMENT_VEC4S: u32 = 10u;

fn plane_moments_zero() -> array<vec4<f32>, 10> {
    return array<vec4<f32>, 10>();
}

// The moments of one pixel: point p, normal n, footprint `area_m2` and noise covariance
// `noise_scale` p pᵀ (0 for none).
fn plane_moments_point(p: vec3<f32>, n: vec3<f32>, area_m2: f32, noise_scale: f32) -> array<vec4<f32>, 10> {
    var m = plane_moments_zero();
    m[0] = vec4<f32>(1.0, area_m2, 0.0, 0.0);
    m[1] = vec4<f32>(p, 0.0);
    m[2] = vec4<f32>(n, 0.0);
    m[8] = vec4<f32>(noise_scale * p * p, 0.0);
    m[9] = vec4<f32>(noise_scale * vec3<f32>(p.x * p.y, p.x * p.z, p.y * p.z), 0.0);
    return m;
}

// The moments of the union of two disjoint sets.
fn plane_moments_combine(a: array<vec4<f32>, 10>, b: array<vec4<f32>, 10>) -> array<vec4<f32>, 10> {
    let na = a[0].x;
    let nb = b[0].x;
    if nb == 0.0 {
        return a;
    }
    if na == 0.0 {
        return b;
    }
    let n = na + nb;
    let wb = nb / n;
    let f = na * wb;
    let dp = b[1].xyz - a[1].xyz;
    let dn = b[2].xyz - a[2].xyz;
    let fp = f * dp;
    var m = plane_moments_zero();
    m[0] = vec4<f32>(n, a[0].y + b[0].y, 0.0, 0.0);
    m[1] = vec4<f32>(a[1].xyz + wb * dp, 0.0);
    m[2] = vec4<f32>(a[2].xyz + wb * dn, 0.0);
    m[3] = vec4<f32>(a[3].xyz + b[3].xyz + fp * dp, 0.0);
    m[4] = vec4<f32>(a[4].xyz + b[4].xyz + vec3<f32>(fp.x * dp.y, fp.x * dp.z, fp.y * dp.z), 0.0);
    m[5] = vec4<f32>(a[5].xyz + b[5].xyz + dn.x * fp, 0.0);
    m[6] = vec4<f32>(a[6].xyz + b[6].xyz + dn.y * fp, 0.0);
    m[7] = vec4<f32>(a[7].xyz + b[7].xyz + dn.z * fp, 0.0);
    m[8] = a[8] + b[8];
    m[9] = a[9] + b[9];
    return m;
}
