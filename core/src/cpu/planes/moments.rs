// SPDX-License-Identifier: MIT
//! Twins of `shared/plane_moments.wgsl`: the centred moments of a set of plane pixels and their
//! pairwise combination (see the WGSL for the layout and why they are centred).

/// vec4s per set of moments.
pub const PLANE_MOMENT_VEC4S: usize = 10;

/// One set of moments, [`PLANE_MOMENT_VEC4S`] vec4 in the WGSL layout.
pub type PlaneMoments = [[f32; 4]; PLANE_MOMENT_VEC4S];

/// Twin of `plane_moments_zero()`.
pub fn plane_moments_zero() -> PlaneMoments {
    [[0.0; 4]; PLANE_MOMENT_VEC4S]
}

fn v3(a: [f32; 4]) -> [f32; 3] {
    [a[0], a[1], a[2]]
}

fn v4(a: [f32; 3]) -> [f32; 4] {
    [a[0], a[1], a[2], 0.0]
}

/// Twin of `plane_moments_point()`: the moments of one pixel.
pub fn plane_moments_point(p: [f32; 3], n: [f32; 3], area_m2: f32, noise_scale: f32) -> PlaneMoments {
    let mut m = plane_moments_zero();
    m[0] = [1.0, area_m2, 0.0, 0.0];
    m[1] = v4(p);
    m[2] = v4(n);
    m[8] = v4(std::array::from_fn(|i| noise_scale * p[i] * p[i]));
    m[9] = v4([noise_scale * (p[0] * p[1]), noise_scale * (p[0] * p[2]), noise_scale * (p[1] * p[2])]);
    m
}

/// Twin of `plane_moments_combine()`: the moments of the union of two disjoint sets.
pub fn plane_moments_combine(a: &PlaneMoments, b: &PlaneMoments) -> PlaneMoments {
    let (na, nb) = (a[0][0], b[0][0]);
    if nb == 0.0 {
        return *a;
    }
    if na == 0.0 {
        return *b;
    }
    let n = na + nb;
    let wb = nb / n;
    let f = na * wb;
    let dp: [f32; 3] = std::array::from_fn(|i| b[1][i] - a[1][i]);
    let dn: [f32; 3] = std::array::from_fn(|i| b[2][i] - a[2][i]);
    let fp = dp.map(|d| f * d);
    let sum = |i: usize, extra: [f32; 3]| v4(std::array::from_fn(|c| a[i][c] + b[i][c] + extra[c]));
    let mut m = plane_moments_zero();
    m[0] = [n, a[0][1] + b[0][1], 0.0, 0.0];
    m[1] = v4(std::array::from_fn(|i| a[1][i] + wb * dp[i]));
    m[2] = v4(std::array::from_fn(|i| a[2][i] + wb * dn[i]));
    m[3] = sum(3, std::array::from_fn(|i| fp[i] * dp[i]));
    m[4] = sum(4, [fp[0] * dp[1], fp[0] * dp[2], fp[1] * dp[2]]);
    for r in 0..3 {
        m[5 + r] = sum(5 + r, fp.map(|x| dn[r] * x));
    }
    m[8] = std::array::from_fn(|c| a[8][c] + b[8][c]);
    m[9] = std::array::from_fn(|c| a[9][c] + b[9][c]);
    m
}

/// Moments from their f32 layout to the f64 [`PlaneSums`](crate::planes::reference::PlaneSums)
/// form (raw sums), for comparison with the reference and for host-side fits.
pub fn plane_moments_to_sums(m: &PlaneMoments) -> crate::planes::reference::PlaneSums {
    let n = f64::from(m[0][0]);
    let c = v3(m[1]).map(f64::from);
    let nbar = v3(m[2]).map(f64::from);
    let s = |i: usize, j: usize| -> f64 {
        let (i, j) = (i.min(j), i.max(j));
        f64::from(if i == j { m[3][i] } else { m[4][i + j - 1] })
    };
    let noise = |i: usize, j: usize| -> f64 {
        let (i, j) = (i.min(j), i.max(j));
        f64::from(if i == j { m[8][i] } else { m[9][i + j - 1] })
    };
    crate::planes::reference::PlaneSums {
        count: n,
        p: c.map(|v| v * n),
        pp: std::array::from_fn(|i| std::array::from_fn(|j| s(i, j) + n * c[i] * c[j])),
        n: nbar.map(|v| v * n),
        np: std::array::from_fn(|i| std::array::from_fn(|j| f64::from(m[5 + i][j]) + n * nbar[i] * c[j])),
        area_m2: f64::from(m[0][1]),
        noise: std::array::from_fn(|i| std::array::from_fn(|j| noise(i, j))),
    }
}
