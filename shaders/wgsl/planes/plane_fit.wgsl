// SPDX-License-Identifier: MIT
//! Each invocation fits one plane to its moments (plane_sums_reduce's output; seed 003 §4.3.3's
//! eigen-decomposition, and the f64 reference's `planes::reference::fit` in f32): the normal is
//! the smallest eigenvector (cyclic Jacobi rotations) of the points' covariance less their
//! model noise covariance, the noise's level measured on the plane itself (the variance along
//! the normal over the model's prediction, at most 1; two rounds, each with the last normal),
//! so depth noise along oblique rays does not tilt a narrow plane. It faces the camera
//! (n·centroid < 0). The in-plane axes are the other eigenvectors, largest spread first; the
//! bend (the planarity test's measure) is, over both axes t, the largest |cov(n·t, p·t) /
//! var(p·t)| · √(12 var(p·t)) in degrees; rms is the points' RMS distance from the plane.
//! Out per plane, PLANE_FIT_VEC4S vec4: (normal, offset d of n·p + d = 0), (centroid, count),
//! (first axis, its variance), (second axis, its variance), (rms m, bend degrees, area m²,
//! 1); all zeros for a plane of fewer than 3 pixels. Mirrors core/src/cpu/planes/plane_fit.rs.
#import plane_moments
#import plane_fitting

struct PlaneFitParams {
    // Planes in `moments`.
    plane_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneFitParams;
// Per plane PLANE_MOMENT_VEC4S vec4 (plane_sums_reduce's output).
@group(0) @binding(1) var<storage, read> moments: array<vec4<f32>>;
// Out: per plane PLANE_FIT_VEC4S vec4.
@group(0) @binding(2) var<storage, read_write> fits: array<vec4<f32>>;

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let plane = gid.x;
    if plane >= params.plane_count {
        return;
    }
    var m = plane_moments_zero();
    for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
        m[j] = moments[plane * PLANE_MOMENT_VEC4S + j];
    }
    let fit = plane_fit_moments(m);
    for (var j = 0u; j < PLANE_FIT_VEC4S; j++) {
        fits[plane * PLANE_FIT_VEC4S + j] = fit[j];
    }
}
