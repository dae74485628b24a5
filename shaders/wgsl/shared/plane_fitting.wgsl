// SPDX-License-Identifier: MIT
// Plane fits from moments (shared/plane_moments.wgsl), in f32: the fit of kernel plane_fit and
// of the plane list's merges. Mirrors core/src/cpu/planes/plane_fit.rs.

const PLANE_FIT_VEC4S: u32 = 5u;
// Jacobi stops once the off-diagonal norm is below this times the largest diagonal entry (each
// rotation sets its entry to exactly 0, so f32 gets there in a few sweeps), or after
// JACOBI_SWEEPS.
const JACOBI_TOLERANCE: f32 = 1e-10;
const JACOBI_SWEEPS: u32 = 20u;

// Eigenvalues ascending, and vectors[i] the unit eigenvector of values[i].
struct Eigen3 {
    values: vec3<f32>,
    vectors: array<vec3<f32>, 3>,
}

// Eigen-decomposition of the symmetric matrix `m` by cyclic Jacobi rotations over the pairs
// (0, 1), (0, 2), (1, 2).
fn eigen_symmetric3(m: array<array<f32, 3>, 3>) -> Eigen3 {
    var a = m;
    var v = array<array<f32, 3>, 3>(array<f32, 3>(1.0, 0.0, 0.0), array<f32, 3>(0.0, 1.0, 0.0), array<f32, 3>(0.0, 0.0, 1.0));
    let scale = max(max(abs(a[0][0]), abs(a[1][1])), max(abs(a[2][2]), 1e-30));
    for (var sweep = 0u; sweep < JACOBI_SWEEPS; sweep++) {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (JACOBI_TOLERANCE * scale) * (JACOBI_TOLERANCE * scale) {
            break;
        }
        for (var r = 0u; r < 3u; r++) {
            let p = select(0u, 1u, r == 2u);
            let q = select(1u, 2u, r >= 1u);
            let o = 3u - p - q;
            let apq = a[p][q];
            if apq == 0.0 {
                continue;
            }
            // A ← Pᵀ A P with P the rotation in the (p, q) plane that zeroes a_pq.
            let theta = (a[q][q] - a[p][p]) / (2.0 * apq);
            let t = select(-1.0, 1.0, theta >= 0.0) / (abs(theta) + sqrt(theta * theta + 1.0));
            let c = 1.0 / sqrt(t * t + 1.0);
            let s = t * c;
            let aop = a[o][p];
            let aoq = a[o][q];
            a[p][p] = a[p][p] - t * apq;
            a[q][q] = a[q][q] + t * apq;
            a[p][q] = 0.0;
            a[q][p] = 0.0;
            a[o][p] = c * aop - s * aoq;
            a[p][o] = a[o][p];
            a[o][q] = s * aop + c * aoq;
            a[q][o] = a[o][q];
            for (var i = 0u; i < 3u; i++) {
                let vip = v[i][p];
                let viq = v[i][q];
                v[i][p] = c * vip - s * viq;
                v[i][q] = s * vip + c * viq;
            }
        }
    }
    // Ascending by a stable rank (the lower index first among equals).
    var e: Eigen3;
    for (var i = 0u; i < 3u; i++) {
        var rank = 0u;
        for (var j = 0u; j < 3u; j++) {
            if a[j][j] < a[i][i] || (a[j][j] == a[i][i] && j < i) {
                rank += 1u;
            }
        }
        e.values[rank] = a[i][i];
        e.vectors[rank] = vec3<f32>(v[0][i], v[1][i], v[2][i]);
    }
    return e;
}

// vᵀ m v.
fn quadratic(m: array<array<f32, 3>, 3>, v: vec3<f32>) -> f32 {
    var sum = 0.0;
    for (var i = 0u; i < 3u; i++) {
        var row = 0.0;
        for (var j = 0u; j < 3u; j++) {
            row += v[i] * m[i][j] * v[j];
        }
        sum += row;
    }
    return sum;
}

// The symmetric 3 x 3 matrix of a (diagonal, off-diagonal xy xz yz) pair, times `k`.
fn symmetric(diagonal: vec4<f32>, off: vec4<f32>, k: f32) -> array<array<f32, 3>, 3> {
    return array<array<f32, 3>, 3>(
        array<f32, 3>(diagonal.x * k, off.x * k, off.y * k),
        array<f32, 3>(off.x * k, diagonal.y * k, off.z * k),
        array<f32, 3>(off.y * k, off.z * k, diagonal.z * k),
    );
}

// The fit of one set of moments (at least 3 pixels; see kernel plane_fit for what it computes):
// (normal, offset), (centroid, count), (first axis, variance), (second axis, variance),
// (rms m, bend degrees, area m², 1); all zeros for fewer than 3 pixels.
fn plane_fit_moments(m: array<vec4<f32>, 10>) -> array<vec4<f32>, 5> {
    var out = array<vec4<f32>, 5>();
    let count = m[0].x;
    if !(count >= 3.0) {
        return out;
    }
    let k = 1.0 / count;
    let centroid = m[1].xyz;
    let raw_cov = symmetric(m[3], m[4], k);
    let noise = symmetric(m[8], m[9], k);
    var e = eigen_symmetric3(raw_cov);
    for (var noise_round = 0u; noise_round < 2u; noise_round++) {
        let predicted = quadratic(noise, e.vectors[0]);
        if !(predicted > 0.0) {
            break;
        }
        let level = clamp(quadratic(raw_cov, e.vectors[0]) / predicted, 0.0, 1.0);
        var cov = raw_cov;
        for (var i = 0u; i < 3u; i++) {
            for (var j = 0u; j < 3u; j++) {
                cov[i][j] = raw_cov[i][j] - level * noise[i][j];
            }
        }
        e = eigen_symmetric3(cov);
    }
    var normal = e.vectors[0];
    if dot(normal, centroid) > 0.0 {
        normal = -normal;
    }
    // cov(n, p)(i, j) = E[(n_i - n̄_i)(p_j - p̄_j)].
    var cov_np: array<array<f32, 3>, 3>;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            cov_np[i][j] = m[5u + i][j] * k;
        }
    }
    let tangents = array<vec3<f32>, 2>(e.vectors[2], e.vectors[1]);
    let variance = vec2<f32>(max(e.values[2], 0.0), max(e.values[1], 0.0));
    var bend = 0.0;
    for (var a = 0u; a < 2u; a++) {
        if variance[a] > 0.0 {
            // tᵀ cov(n, p) t = cov(n·t, p·t).
            let rate = quadratic(cov_np, tangents[a]) / variance[a];
            bend = max(bend, abs(rate) * sqrt(12.0 * variance[a]));
        }
    }
    out[0] = vec4<f32>(normal, -dot(normal, centroid));
    out[1] = vec4<f32>(centroid, count);
    out[2] = vec4<f32>(tangents[0], variance[0]);
    out[3] = vec4<f32>(tangents[1], variance[1]);
    out[4] = vec4<f32>(sqrt(max(quadratic(raw_cov, normal), 0.0)), degrees(bend), m[0].y, 1.0);
    return out;
}
