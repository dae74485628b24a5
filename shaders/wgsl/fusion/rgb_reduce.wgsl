// SPDX-License-Identifier: MIT
//! Photometric normal equations (direct RGB-D odometry as in DVO / ElasticFusion), in the same
//! 6-DOF parametrisation as `icp_reduce`. Each invocation walks pixels ix, ix + threads, ... of
//! the current frame's level: maps the vertex to world with the estimate `world_from_camera`
//! (p), then into the previous frame (`camera_prev_from_world`), projects it (u'), checks the
//! previous depth there agrees within `max_depth_diff_m` (visibility), and uses the residual
//! r = I_prev(u') - I_cur(u) with bilinear I_prev and its central-difference gradient g.
//! With gp = (∂π/∂p_prev)ᵀ g and gw = R_prev gp, the row is J = [p x gw, gw] (twist applied on
//! the left, like ICP). Residuals beyond `max_residual` are rejected; the workgroup reduces
//! like `icp_reduce` and writes 32 floats per workgroup in the same layout.
#import invalid
#import camera
#import normal_equations

struct RgbReduceParams {
    // Intrinsics of this pyramid level (both frames).
    intrinsics: Intrinsics,
    // Current estimate of the frame's pose, column-major.
    world_from_camera: mat4x4<f32>,
    // Inverse of the previous frame's pose, column-major.
    camera_prev_from_world: mat4x4<f32>,
    // The previous frame's pose, column-major.
    world_from_camera_prev: mat4x4<f32>,
    // Largest difference between the warped depth and the previous depth there, metres.
    max_depth_diff_m: f32,
    // Largest accepted intensity residual (intensities in [0, 1]).
    max_residual: f32,
    // Threads in the dispatch (the pixel stride).
    thread_count: u32,
    _pad0: u32,
}

// Uniform `RgbReduceParams`.
@group(0) @binding(0) var<uniform> params: RgbReduceParams;
// Current frame's vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// Current frame's intensity.
@group(0) @binding(2) var<storage, read> intensity: array<f32>;
// Previous frame's intensity.
@group(0) @binding(3) var<storage, read> prev_intensity: array<f32>;
// Previous frame's depth, metres.
@group(0) @binding(4) var<storage, read> prev_depth_m: array<f32>;
// `icp_reduce::WORKGROUPS` × `icp_reduce::SUM_FLOATS` partial sums.
@group(0) @binding(5) var<storage, read_write> partial_sums: array<vec4<f32>>;


// Bilinear previous intensity at (x, y); the caller keeps 0 <= x < w - 1, 0 <= y < h - 1.
fn prev_bilinear(x: f32, y: f32) -> f32 {
    let w = params.intrinsics.width_px;
    let x0 = u32(x);
    let y0 = u32(y);
    let fx = x - f32(x0);
    let fy = y - f32(y0);
    let i = y0 * w + x0;
    let top = prev_intensity[i] * (1.0 - fx) + prev_intensity[i + 1u] * fx;
    let bottom = prev_intensity[i + w] * (1.0 - fx) + prev_intensity[i + w + 1u] * fx;
    return top * (1.0 - fy) + bottom * fy;
}

@compute @workgroup_size(128, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let k = params.intrinsics;
    let pixel_count = k.width_px * k.height_px;
    var acc = ne_zero();
    for (var ix = gid.x; ix < pixel_count; ix += params.thread_count) {
        let v_cam = vertex_in_camera[ix];
        if !is_valid_f32(v_cam.z) {
            continue;
        }
        let p = (params.world_from_camera * vec4<f32>(v_cam.xyz, 1.0)).xyz;
        let q = (params.camera_prev_from_world * vec4<f32>(p, 1.0)).xyz;
        if !(q.z > 0.0) {
            continue;
        }
        let u = k.fx_px * q.x / q.z + k.cx_px;
        let w = k.fy_px * q.y / q.z + k.cy_px;
        // One pixel of margin for the central differences.
        if !(u >= 1.0 && w >= 1.0 && u < f32(k.width_px) - 2.0 && w < f32(k.height_px) - 2.0) {
            continue;
        }
        let nearest = u32(w + 0.5) * k.width_px + u32(u + 0.5);
        let z_prev = prev_depth_m[nearest];
        if !is_valid_f32(z_prev) || !(abs(z_prev - q.z) <= params.max_depth_diff_m) {
            continue;
        }
        let r = prev_bilinear(u, w) - intensity[ix];
        if !(abs(r) <= params.max_residual) {
            continue;
        }
        let gx = 0.5 * (prev_bilinear(u + 1.0, w) - prev_bilinear(u - 1.0, w));
        let gy = 0.5 * (prev_bilinear(u, w + 1.0) - prev_bilinear(u, w - 1.0));
        let inv_z = 1.0 / q.z;
        let gp = vec3<f32>(gx * k.fx_px * inv_z, gy * k.fy_px * inv_z, -(gx * k.fx_px * q.x + gy * k.fy_px * q.y) * inv_z * inv_z);
        let gw = (params.world_from_camera_prev * vec4<f32>(gp, 0.0)).xyz;
        ne_add_row(&acc, cross(p, gw), gw, r);
    }
    ne_reduce_and_store(acc, lid, wid.x);
}
