// SPDX-License-Identifier: MIT
// Robust rigid motion from matched keypoints on the GPU (seed 002's estimation): the pairs
// `match_select` keeps, the estimate `ransac_hypotheses` and `ransac_refine` write, the Kinect
// noise of a pair's residual and Kabsch on three pairs. Mirrors
// core/src/cpu/odometry/estimate.rs.
//
// A pair's residual dst − T src is measured against the Kinect noise model: each point's
// covariance is its axial σ_z(z)² (shared/kinect.wgsl) along its ray and one pyramid-level
// pixel's lateral (z · 2^level / f)² across it; the residual's covariance is
// R Σ_src Rᵀ + Σ_dst, and its squared Mahalanobis norm is χ²(3) distributed for an inlier.
#import invalid
#import kinect
#import plane_fitting

// χ²(3 degrees of freedom) at 95 %: a pair within it, times the frame's noise scale², is an
// inlier.
const CHI2_3DOF_95: f32 = 7.815;
// The median of χ²(3 degrees of freedom): the noise scale is the median normalised residual's
// ratio to it.
const CHI2_3DOF_MEDIAN: f32 = 2.366;
// Hypotheses `ransac_refine` chooses among at most (one per `ransac_hypotheses` workgroup).
const RANSAC_MAX_HYPOTHESES: u32 = 256u;
// A degenerate hypothesis's cost (above any real MSAC cost).
const RANSAC_NO_COST: f32 = 3.0e38;
// A sample whose triangle's doubled area is under this (m²; 5 cm sides) fixes the rotation
// poorly and is skipped.
const RANSAC_MIN_SAMPLE_AREA_M2: f32 = 0.0025;
// Kabsch on three pairs is degenerate when the second singular value is below this fraction of
// the first (the points are collinear to f32 precision).
const KABSCH_MIN_SINGULAR_RATIO: f32 = 1e-3;

// One kept match, lifted to 3D.
struct FeaturePair {
    // The current frame's point (camera frame, metres) and its pyramid level.
    src: vec4<f32>,
    // The reference frame's matched point and its level.
    dst: vec4<f32>,
    // (current slot, reference slot, Hamming distance in bits, 0).
    slots: vec4<u32>,
}

// The frame's estimate, written by match_select (the pair count, the rest reset) and
// ransac_refine (the rest).
struct RigidEstimate {
    // The reference camera from the current one (column-major); identity when rejected.
    dst_from_src: mat4x4<f32>,
    // Pairs kept by match_select.
    pairs: u32,
    // Pairs within the inlier bound of the final estimate.
    inliers: u32,
    // 1: accepted (at least `min_inliers` inliers, a non-singular refinement and a noise scale
    // within max_noise_scale).
    accepted: u32,
    // The hypothesis RANSAC chose (RANSAC_MAX_HYPOTHESES when none was usable).
    best_hypothesis: u32,
    // The frame's noise relative to the sensor model (≥ 1; beyond max_noise_scale the frame
    // is rejected).
    noise_scale: f32,
    // Root mean square residual of the inliers, metres.
    rmse_m: f32,
    // The chosen hypothesis's MSAC cost.
    cost: f32,
    // Refits run on the inliers.
    refits: u32,
}

// Settings shared by ransac_hypotheses and ransac_refine.
struct RansacParams {
    // Hypotheses drawn (≤ RANSAC_MAX_HYPOTHESES; one workgroup each).
    hypotheses: u32,
    // The frame's sample stream.
    seed: u32,
    // Fewest inliers for an accepted motion.
    min_inliers: u32,
    // Refits on the inliers after the best hypothesis.
    refits: u32,
    // Focal length, pixels (the lateral noise of one level-0 pixel is z / f).
    f_px: f32,
    // The largest noise scale a frame may show.
    max_noise_scale: f32,
    // Gauss-Newton iterations per refit.
    iterations: u32,
    _pad0: u32,
}

// The 3 × 3 symmetric noise covariance of a point `p` at pyramid `level`: lateral² I plus
// (axial² − lateral²) along the ray, m².
fn point_covariance(p: vec3<f32>, level: f32, f_px: f32) -> mat3x3<f32> {
    let axial = kinect_sigma_m(p.z);
    let lateral = p.z * f32(1u << u32(level)) / f_px;
    let ray = p / length(p);
    let k = axial * axial - lateral * lateral;
    let l2 = lateral * lateral;
    return mat3x3<f32>(
        vec3<f32>(k * ray.x * ray.x + l2, k * ray.y * ray.x, k * ray.z * ray.x),
        vec3<f32>(k * ray.x * ray.y, k * ray.y * ray.y + l2, k * ray.z * ray.y),
        vec3<f32>(k * ray.x * ray.z, k * ray.y * ray.z, k * ray.z * ray.z + l2),
    );
}

// The rotation block of a rigid transform.
fn rotation_of(m: mat4x4<f32>) -> mat3x3<f32> {
    return mat3x3<f32>(m[0].xyz, m[1].xyz, m[2].xyz);
}

// The inverse of a symmetric positive-definite 3 × 3 matrix (adjugate over determinant); all
// zeros when it is not invertible (the pair then weighs nothing and is never an inlier).
fn symmetric_inverse3(c: mat3x3<f32>) -> mat3x3<f32> {
    let a00 = c[1][1] * c[2][2] - c[2][1] * c[1][2];
    let a01 = c[2][0] * c[1][2] - c[1][0] * c[2][2];
    let a02 = c[1][0] * c[2][1] - c[2][0] * c[1][1];
    let det = c[0][0] * a00 + c[0][1] * a01 + c[0][2] * a02;
    if !(det > 0.0) {
        return mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    }
    let a11 = c[0][0] * c[2][2] - c[2][0] * c[0][2];
    let a12 = c[2][0] * c[0][1] - c[0][0] * c[2][1];
    let a22 = c[0][0] * c[1][1] - c[1][0] * c[0][1];
    let inv = 1.0 / det;
    return mat3x3<f32>(
        vec3<f32>(a00 * inv, a01 * inv, a02 * inv),
        vec3<f32>(a01 * inv, a11 * inv, a12 * inv),
        vec3<f32>(a02 * inv, a12 * inv, a22 * inv),
    );
}

// The information (inverse covariance) of `pair`'s residual under `pose`.
fn pair_information(pose: mat4x4<f32>, pair: FeaturePair, f_px: f32) -> mat3x3<f32> {
    let r = rotation_of(pose);
    let c = r * point_covariance(pair.src.xyz, pair.src.w, f_px) * transpose(r) + point_covariance(pair.dst.xyz, pair.dst.w, f_px);
    return symmetric_inverse3(c);
}

// The residual dst − pose · src of `pair`, metres.
fn pair_residual(pose: mat4x4<f32>, pair: FeaturePair) -> vec3<f32> {
    return pair.dst.xyz - (pose * vec4<f32>(pair.src.xyz, 1.0)).xyz;
}

// The squared Mahalanobis norm of `pair`'s residual under `pose` (≥ 0); RANSAC_NO_COST when
// its covariance is not invertible.
fn pair_normalised_residual(pose: mat4x4<f32>, pair: FeaturePair, f_px: f32) -> f32 {
    let r = pair_residual(pose, pair);
    let info = pair_information(pose, pair, f_px);
    if !(info[0][0] > 0.0) {
        return RANSAC_NO_COST;
    }
    return max(dot(r, info * r), 0.0);
}

// The rigid motion taking the points a0, a1, a2 onto b0, b1, b2 in the least-squares sense
// (Kabsch: R = V Uᵀ from H = Σ (a − ā)(b − b̄)ᵀ = U S Vᵀ, the singular vectors from the cyclic
// Jacobi eigenvectors of HᵀH; the third axes are the cross products of the first two, which
// makes R a rotation, never a reflection, and is exact for three points whose H has rank 2),
// with column 3's w = 0 when the points are collinear.
fn kabsch3(a0: vec3<f32>, a1: vec3<f32>, a2: vec3<f32>, b0: vec3<f32>, b1: vec3<f32>, b2: vec3<f32>) -> mat4x4<f32> {
    let ca = (a0 + a1 + a2) / 3.0;
    let cb = (b0 + b1 + b2) / 3.0;
    var a = array<vec3<f32>, 3>(a0 - ca, a1 - ca, a2 - ca);
    var b = array<vec3<f32>, 3>(b0 - cb, b1 - cb, b2 - cb);
    // h[r][c] = Σ a_r b_c.
    var h: array<array<f32, 3>, 3>;
    for (var r = 0u; r < 3u; r++) {
        for (var c = 0u; c < 3u; c++) {
            h[r][c] = a[0][r] * b[0][c] + a[1][r] * b[1][c] + a[2][r] * b[2][c];
        }
    }
    var hth: array<array<f32, 3>, 3>;
    for (var i = 0u; i < 3u; i++) {
        for (var j = 0u; j < 3u; j++) {
            hth[i][j] = h[0][i] * h[0][j] + h[1][i] * h[1][j] + h[2][i] * h[2][j];
        }
    }
    let e = eigen_symmetric3(hth);
    let s1 = sqrt(max(e.values[2], 0.0));
    let s2 = sqrt(max(e.values[1], 0.0));
    let none = mat4x4<f32>(vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0), vec4<f32>(0.0));
    if !(s1 > 0.0) || !(s2 > KABSCH_MIN_SINGULAR_RATIO * s1) {
        return none;
    }
    let v1 = e.vectors[2];
    let v2 = e.vectors[1];
    let hm = mat3x3<f32>(vec3<f32>(h[0][0], h[1][0], h[2][0]), vec3<f32>(h[0][1], h[1][1], h[2][1]), vec3<f32>(h[0][2], h[1][2], h[2][2]));
    let u1 = normalize(hm * v1);
    let w2 = hm * v2;
    let u2 = normalize(w2 - dot(w2, u1) * u1);
    let u3 = cross(u1, u2);
    let v3 = cross(v1, v2);
    // R = v1 u1ᵀ + v2 u2ᵀ + v3 u3ᵀ; column c is Σ v_i u_i[c].
    let rot = mat3x3<f32>(v1 * u1.x + v2 * u2.x + v3 * u3.x, v1 * u1.y + v2 * u2.y + v3 * u3.y, v1 * u1.z + v2 * u2.z + v3 * u3.z);
    let t = cb - rot * ca;
    return mat4x4<f32>(vec4<f32>(rot[0], 0.0), vec4<f32>(rot[1], 0.0), vec4<f32>(rot[2], 0.0), vec4<f32>(t, 1.0));
}
