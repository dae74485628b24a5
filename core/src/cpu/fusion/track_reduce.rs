// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/fusion/track_reduce.wgsl`: the same per-thread walk, the same
//! per-pixel rows and the same tree reduction order (`reduce_normal_equations`), so only fused
//! multiply-adds separate it from the GPU.

pub use crate::cpu::shared::{kinect_sigma_at_angle_m, kinect_sigma_m};
use crate::cpu::shared::{
    NE_SUM_FLOATS, cross3, dot3, is_valid_f32, ne_add_icp_stats, ne_add_jacobian, ne_add_rgb_stats, reduce_normal_equations, rigid_inverse, transform_point, transform_vector,
};
use crate::kernels::track_reduce::{TrackParams, TrackState};

/// The current frame's maps at one level and the reference's, as the kernel binds them.
#[derive(Clone, Copy, Debug)]
pub struct TrackInputs<'a> {
    /// Vertices, camera frame.
    pub vertex_in_camera: &'a [[f32; 4]],
    /// Normals, camera frame.
    pub normal_in_camera: &'a [[f32; 4]],
    /// Predicted vertices, world frame.
    pub predicted_vertex_in_world: &'a [[f32; 4]],
    /// Predicted normals, world frame.
    pub predicted_normal_in_world: &'a [[f32; 4]],
    /// Intensity.
    pub intensity: &'a [f32],
    /// The reference frame's (intensity, ∂I/∂x, ∂I/∂y, depth).
    pub previous: &'a [[f32; 4]],
}

fn previous_bilinear(params: &TrackParams, previous: &[[f32; 4]], x: f32, y: f32) -> [f32; 3] {
    let w = params.intrinsics.width_px as usize;
    let (x0, y0) = (x as u32 as usize, y as u32 as usize);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let i = y0 * w + x0;
    std::array::from_fn(|c| {
        let top = previous[i][c] * (1.0 - fx) + previous[i + 1][c] * fx;
        let bottom = previous[i + w][c] * (1.0 - fx) + previous[i + w + 1][c] * fx;
        top * (1.0 - fy) + bottom * fy
    })
}

/// The rows pixel `ix` adds (the kernel's loop body): the point-to-plane row as
/// `(√w J, √w r)` and the photometric row as `(√λ J, √λ r, r)`, each `None` when rejected.
#[expect(clippy::type_complexity, reason = "the two optional rows of one pixel")]
pub fn track_rows(params: &TrackParams, state: &TrackState, inputs: &TrackInputs, ix: usize) -> (Option<[f32; 7]>, Option<([f32; 7], f32)>) {
    let k = &params.intrinsics;
    let world_from_camera = &state.estimate;
    let camera_ref_from_world = rigid_inverse(&state.reference);
    let camera_prev_from_world = rigid_inverse(&state.previous_view);
    let rgb_scale = params.rgb_weight.max(0.0).sqrt();
    let v_cam = inputs.vertex_in_camera[ix];
    if !is_valid_f32(v_cam[2]) {
        return (None, None);
    }
    let v = transform_point(world_from_camera, [v_cam[0], v_cam[1], v_cam[2]]);
    let p_ref = transform_point(&camera_ref_from_world, v);
    if !(p_ref[2] > 0.0) {
        return (None, None);
    }
    let mut icp = None;
    let n_cam = inputs.normal_in_camera[ix];
    let u = (k.fx_px * p_ref[0] / p_ref[2] + k.cx_px + 0.5).floor();
    let w = (k.fy_px * p_ref[1] / p_ref[2] + k.cy_px + 0.5).floor();
    if is_valid_f32(n_cam[0]) && u >= 0.0 && w >= 0.0 && u < k.width_px as f32 && w < k.height_px as f32 {
        let jx = (w as u32 * k.width_px + u as u32) as usize;
        let q = inputs.predicted_vertex_in_world[jx];
        let m = inputs.predicted_normal_in_world[jx];
        let n = transform_vector(world_from_camera, [n_cam[0], n_cam[1], n_cam[2]]);
        let m3 = [m[0], m[1], m[2]];
        let diff = [v[0] - q[0], v[1] - q[1], v[2] - q[2]];
        if is_valid_f32(q[0]) && is_valid_f32(m[0]) && dot3(diff, diff) <= params.dist_thresh_m * params.dist_thresh_m && dot3(n, m3) >= params.cos_angle_thresh {
            let r = dot3(m3, diff);
            let mut weight = 1.0f32;
            if params.noise_weighting != 0 {
                let ratio = kinect_sigma_m(1.0) / kinect_sigma_m(v_cam[2]);
                weight = ratio * ratio;
            }
            if params.huber_delta_m > 0.0 && r.abs() > params.huber_delta_m {
                weight *= params.huber_delta_m / r.abs();
            }
            let sw = weight.sqrt();
            let a = cross3(v, m3).map(|c| c * sw);
            icp = Some([a[0], a[1], a[2], m3[0] * sw, m3[1] * sw, m3[2] * sw, r * sw]);
        }
    }
    let mut rgb = None;
    let p_prev = transform_point(&camera_prev_from_world, v);
    if rgb_scale > 0.0 && p_prev[2] > 0.0 && is_valid_f32(n_cam[0]) {
        let uf = k.fx_px * p_prev[0] / p_prev[2] + k.cx_px;
        let wf = k.fy_px * p_prev[1] / p_prev[2] + k.cy_px;
        if uf >= 1.0 && wf >= 1.0 && uf < k.width_px as f32 - 2.0 && wf < k.height_px as f32 - 2.0 {
            let z_ref = inputs.previous[((wf + 0.5) as u32 * k.width_px + (uf + 0.5) as u32) as usize][3];
            if is_valid_f32(z_ref) && (z_ref - p_prev[2]).abs() <= params.rgb_max_depth_diff_m {
                let ig = previous_bilinear(params, inputs.previous, uf, wf);
                let r = ig[0] - inputs.intensity[ix];
                if r.abs() <= params.rgb_max_residual {
                    let (gx, gy) = (ig[1], ig[2]);
                    let inv_z = 1.0 / p_prev[2];
                    let gp = [gx * k.fx_px * inv_z, gy * k.fy_px * inv_z, -(gx * k.fx_px * p_prev[0] + gy * k.fy_px * p_prev[1]) * inv_z * inv_z];
                    let gw = transform_vector(&state.previous_view, gp);
                    let a = cross3(v, gw);
                    let mut s = rgb_scale;
                    if params.noise_weighting != 0 {
                        let vc = [v_cam[0], v_cam[1], v_cam[2]];
                        let cos_incidence = (dot3([n_cam[0], n_cam[1], n_cam[2]], vc).abs() / dot3(vc, vc).sqrt()).min(1.0);
                        s *= kinect_sigma_m(v_cam[2]) / kinect_sigma_at_angle_m(v_cam[2], cos_incidence.acos());
                    }
                    rgb = Some(([a[0] * s, a[1] * s, a[2] * s, gw[0] * s, gw[1] * s, gw[2] * s, r * s], r));
                }
            }
        }
    }
    (icp, rgb)
}

/// Fills `partial_sums` (one block of [`NE_SUM_FLOATS`] per workgroup) as the kernel does.
pub fn track_reduce(params: &TrackParams, state: &TrackState, inputs: &TrackInputs, partial_sums: &mut [f32]) {
    let pixel_count = params.intrinsics.width_px * params.intrinsics.height_px;
    reduce_normal_equations(params.thread_count, pixel_count, partial_sums, |ix, acc: &mut [f32; NE_SUM_FLOATS]| {
        let (icp, rgb) = track_rows(params, state, inputs, ix);
        if let Some(row) = icp {
            ne_add_jacobian(acc, [row[0], row[1], row[2]], [row[3], row[4], row[5]], row[6]);
            ne_add_icp_stats(acc, row[6]);
        }
        if let Some((row, r)) = rgb {
            ne_add_jacobian(acc, [row[0], row[1], row[2]], [row[3], row[4], row[5]], row[6]);
            ne_add_rgb_stats(acc, r);
        }
    });
}
