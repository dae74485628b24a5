// SPDX-License-Identifier: MIT
//! One Gauss-Newton iteration's normal equations of the tracker, geometric and photometric rows
//! in one pass. Each invocation walks pixels ix, ix + threads, ... of the current frame's level
//! and, with the estimate T = `state.estimate` and the last fused frame's pose
//! `state.previous_view` (where the previous intensity was taken), adds for each pixel
//! - its point-to-plane row (000-digest §1.3.4, Eq. 1.12-1.16): the vertex and normal mapped to
//!   world by T, projected into the prediction (projective association), pairs further apart
//!   than `dist_thresh_m` or whose normals differ by more than acos(`cos_angle_thresh`)
//!   rejected; residual r = m · (v - q), row J = [v × m, m], weighted by Huber (optional) times
//!   the Kinect axial noise model (optional);
//! - its photometric row (DVO-style): r = I_ref(u') - I(u) with I_ref and its gradient (kept by
//!   `keep_previous`) bilinear at the reprojection u' of the vertex into the previous frame,
//!   kept when the previous depth there agrees within `rgb_max_depth_diff_m` and
//!   |r| <= `rgb_max_residual`; with the projected intensity gradient gw in world,
//!   J = [p × gw, gw], scaled by sqrt(`rgb_weight`). Only where the pixel's surface is well
//!   measured, as the geometric row needs it: a valid normal (no hole or depth step among its
//!   neighbours: a pixel there may mix two surfaces, and its warp goes astray), and with the
//!   noise model on, scaled by σ_z(z) / σ_z(z, θ) (Nguyen et al.'s incidence term: 1 up to
//!   60°, towards 0 at grazing incidence and at the silhouettes whose normals face sideways);
//! both into one accumulator (the twist is applied on the left, rotation first). The workgroup
//! tree-reduces its 128 accumulators (no atomics) and writes 32 floats: [JᵀJ (21), Jᵀr (6),
//! Σ r² and count of the geometric rows, Σ r² and count of the photometric rows, 0].
//! Dispatched indirectly from `TrackDispatch`: a converged level runs no workgroup at all.
#import invalid
#import camera
#import rigid
#import track_state
#import normal_equations
#import kinect

@group(0) @binding(0) var<uniform> params: TrackParams;
// The tracker's state (estimate, reference).
@group(0) @binding(1) var<storage, read> state: TrackState;
// Current frame's vertices at this level, camera frame.
@group(0) @binding(2) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// Current frame's normals at this level, camera frame.
@group(0) @binding(3) var<storage, read> normal_in_camera: array<vec4<f32>>;
// Predicted vertices at this level, world frame (rendered at the reference pose).
@group(0) @binding(4) var<storage, read> predicted_vertex_in_world: array<vec4<f32>>;
// Predicted normals at this level, world frame.
@group(0) @binding(5) var<storage, read> predicted_normal_in_world: array<vec4<f32>>;
// Current frame's intensity at this level, [0, 1].
@group(0) @binding(6) var<storage, read> intensity: array<f32>;
// The reference frame's (intensity, ∂I/∂x, ∂I/∂y, depth in metres) at this level.
@group(0) @binding(7) var<storage, read> previous: array<vec4<f32>>;
// Out: `reduce_workgroups` × 8 vec4 partial sums.
@group(0) @binding(8) var<storage, read_write> partial_sums: array<vec4<f32>>;

// Bilinear reference (intensity, ∂I/∂x, ∂I/∂y) at (x, y); the caller keeps 0 <= x < w - 1,
// 0 <= y < h - 1.
fn previous_bilinear(x: f32, y: f32) -> vec3<f32> {
    let w = params.intrinsics.width_px;
    let x0 = u32(x);
    let y0 = u32(y);
    let fx = x - f32(x0);
    let fy = y - f32(y0);
    let i = y0 * w + x0;
    let top = previous[i].xyz * (1.0 - fx) + previous[i + 1u].xyz * fx;
    let bottom = previous[i + w].xyz * (1.0 - fx) + previous[i + w + 1u].xyz * fx;
    return top * (1.0 - fy) + bottom * fy;
}

@compute @workgroup_size(128, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let k = params.intrinsics;
    let pixel_count = k.width_px * k.height_px;
    let world_from_camera = state.estimate;
    // The prediction's camera (projective association) and the previous frame's (photometric).
    let camera_ref_from_world = rigid_inverse(state.reference);
    let camera_prev_from_world = rigid_inverse(state.previous_view);
    let rgb_scale = sqrt(max(params.rgb_weight, 0.0));
    var acc = ne_zero();
    for (var ix = gid.x; ix < pixel_count; ix += params.thread_count) {
        let v_cam = vertex_in_camera[ix];
        if !is_valid_f32(v_cam.z) {
            continue;
        }
        let v = (world_from_camera * vec4<f32>(v_cam.xyz, 1.0)).xyz;
        let p_ref = (camera_ref_from_world * vec4<f32>(v, 1.0)).xyz;
        if !(p_ref.z > 0.0) {
            continue;
        }
        // Point-to-plane row.
        let n_cam = normal_in_camera[ix];
        let u = floor(k.fx_px * p_ref.x / p_ref.z + k.cx_px + 0.5);
        let w = floor(k.fy_px * p_ref.y / p_ref.z + k.cy_px + 0.5);
        if is_valid_f32(n_cam.x) && u >= 0.0 && w >= 0.0 && u < f32(k.width_px) && w < f32(k.height_px) {
            let jx = u32(w) * k.width_px + u32(u);
            let q = predicted_vertex_in_world[jx];
            let m = predicted_normal_in_world[jx];
            let n = (world_from_camera * vec4<f32>(n_cam.xyz, 0.0)).xyz;
            let diff = v - q.xyz;
            if is_valid_f32(q.x) && is_valid_f32(m.x) && dot(diff, diff) <= params.dist_thresh_m * params.dist_thresh_m && dot(n, m.xyz) >= params.cos_angle_thresh {
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
                ne_add_jacobian(&acc, cross(v, m.xyz) * sw, m.xyz * sw, r * sw);
                ne_add_icp_stats(&acc, r * sw);
            }
        }
        // Photometric row.
        let p_prev = (camera_prev_from_world * vec4<f32>(v, 1.0)).xyz;
        if rgb_scale > 0.0 && p_prev.z > 0.0 && is_valid_f32(n_cam.x) {
            let uf = k.fx_px * p_prev.x / p_prev.z + k.cx_px;
            let wf = k.fy_px * p_prev.y / p_prev.z + k.cy_px;
            // One pixel of margin for the central differences.
            if uf >= 1.0 && wf >= 1.0 && uf < f32(k.width_px) - 2.0 && wf < f32(k.height_px) - 2.0 {
                let z_ref = previous[u32(wf + 0.5) * k.width_px + u32(uf + 0.5)].w;
                if is_valid_f32(z_ref) && abs(z_ref - p_prev.z) <= params.rgb_max_depth_diff_m {
                    let ig = previous_bilinear(uf, wf);
                    let r = ig.x - intensity[ix];
                    if abs(r) <= params.rgb_max_residual {
                        let gx = ig.y;
                        let gy = ig.z;
                        let inv_z = 1.0 / p_prev.z;
                        let gp = vec3<f32>(gx * k.fx_px * inv_z, gy * k.fy_px * inv_z, -(gx * k.fx_px * p_prev.x + gy * k.fy_px * p_prev.y) * inv_z * inv_z);
                        let gw = (state.previous_view * vec4<f32>(gp, 0.0)).xyz;
                        var s = rgb_scale;
                        if params.noise_weighting != 0u {
                            let cos_incidence = min(abs(dot(n_cam.xyz, v_cam.xyz)) / length(v_cam.xyz), 1.0);
                            s *= kinect_sigma_m(v_cam.z) / kinect_sigma_at_angle_m(v_cam.z, acos(cos_incidence));
                        }
                        ne_add_jacobian(&acc, cross(v, gw) * s, gw * s, r * s);
                        ne_add_rgb_stats(&acc, r);
                    }
                }
            }
        }
    }
    ne_reduce_and_store(acc, lid, wid.x);
}
