// SPDX-License-Identifier: MIT
//! Point-to-plane ICP normal equations (000-digest §1.3.4, Eq. 1.12-1.16), frame-to-model with
//! projective data association. Each invocation walks pixels ix, ix + threads, ... of the
//! current frame's level: transforms the vertex and normal to world with the current estimate
//! `world_from_camera`, projects the vertex into the predicted (raycast) maps rendered from
//! `camera_prev_from_world`, rejects pairs further apart than `dist_thresh_m` or whose normals
//! differ by more than acos(`cos_angle_thresh`), and accumulates, for the residual
//! r = m . (v - q) and Jacobian J = [v x m, m] (twist applied on the left, rotation first):
//! the 21 upper-triangle entries of JᵀWJ, the 6 of JᵀWr, Wr² and the inlier count, where the
//! weight W is Huber's (optional) times the Kinect noise model's (optional). The workgroup
//! then tree-reduces its 128 accumulators in workgroup memory (no atomics) and writes 32
//! floats: [JᵀJ row-major upper triangle (21), Jᵀr (6), r², count, 0, 0, 0].
#import invalid
#import camera
#import normal_equations

struct IcpReduceParams {
    // Intrinsics of this pyramid level (current frame and prediction alike).
    intrinsics: Intrinsics,
    // Current estimate of the frame's pose, column-major.
    world_from_camera: mat4x4<f32>,
    // Inverse of the pose the prediction was rendered from, column-major.
    camera_prev_from_world: mat4x4<f32>,
    // Largest point distance of a correspondence, metres.
    dist_thresh_m: f32,
    // Smallest cosine between the two normals of a correspondence.
    cos_angle_thresh: f32,
    // Threads in the dispatch (the pixel stride).
    thread_count: u32,
    // Residuals beyond this get Huber weight delta / |r| (0: off), metres.
    huber_delta_m: f32,
    // Non-zero: weight each pair by (σ(1 m) / σ(z))², the Kinect axial noise model
    // σ(z) = 0.0012 + 0.0019 (z - 0.4)² (Nguyen et al. 2012) at the current vertex's depth.
    noise_weighting: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    return 0.0012 + 0.0019 * d * d;
}

// Uniform `IcpReduceParams`.
@group(0) @binding(0) var<uniform> params: IcpReduceParams;
// Current frame's vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// Current frame's normals, camera frame.
@group(0) @binding(2) var<storage, read> normal_in_camera: array<vec4<f32>>;
// Predicted vertices, world frame.
@group(0) @binding(3) var<storage, read> predicted_vertex_in_world: array<vec4<f32>>;
// Predicted normals, world frame.
@group(0) @binding(4) var<storage, read> predicted_normal_in_world: array<vec4<f32>>;
// [`WORKGROUPS`] × [`SUM_FLOATS`] partial sums.
@group(0) @binding(5) var<storage, read_write> partial_sums: array<vec4<f32>>;


@compute @workgroup_size(128, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let k = params.intrinsics;
    let pixel_count = k.width_px * k.height_px;
    var acc = ne_zero();
    for (var ix = gid.x; ix < pixel_count; ix += params.thread_count) {
        let v_cam = vertex_in_camera[ix];
        let n_cam = normal_in_camera[ix];
        if !is_valid_f32(v_cam.z) || !is_valid_f32(n_cam.x) {
            continue;
        }
        let v = (params.world_from_camera * vec4<f32>(v_cam.xyz, 1.0)).xyz;
        let n = (params.world_from_camera * vec4<f32>(n_cam.xyz, 0.0)).xyz;
        let p_prev = (params.camera_prev_from_world * vec4<f32>(v, 1.0)).xyz;
        if !(p_prev.z > 0.0) {
            continue;
        }
        let u = floor(k.fx_px * p_prev.x / p_prev.z + k.cx_px + 0.5);
        let w = floor(k.fy_px * p_prev.y / p_prev.z + k.cy_px + 0.5);
        if !(u >= 0.0 && w >= 0.0 && u < f32(k.width_px) && w < f32(k.height_px)) {
            continue;
        }
        let jx = u32(w) * k.width_px + u32(u);
        let q = predicted_vertex_in_world[jx];
        let m = predicted_normal_in_world[jx];
        if !is_valid_f32(q.x) || !is_valid_f32(m.x) {
            continue;
        }
        let diff = v - q.xyz;
        if !(dot(diff, diff) <= params.dist_thresh_m * params.dist_thresh_m) || !(dot(n, m.xyz) >= params.cos_angle_thresh) {
            continue;
        }
        let r = dot(m.xyz, diff);
        var weight = 1.0;
        if params.noise_weighting != 0u {
            let ratio = kinect_sigma_m(1.0) / kinect_sigma_m(v_cam.z);
            weight = ratio * ratio;
        }
        if params.huber_delta_m > 0.0 && abs(r) > params.huber_delta_m {
            weight *= params.huber_delta_m / abs(r);
        }
        // Weighted least squares: scale the row by sqrt(weight).
        let sw = sqrt(weight);
        ne_add_row(&acc, cross(v, m.xyz) * sw, m.xyz * sw, r * sw);
    }
    ne_reduce_and_store(acc, lid, wid.x);
}
