// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/icp_reduce.wgsl`: the same per-thread walk and the same
//! tree reduction order (`reduce_normal_equations`), so only fused multiply-adds separate it
//! from the GPU.

use crate::cpu::shared::{cross3, dot3, is_valid_f32, reduce_normal_equations, transform_point, transform_vector};
use crate::kernels::icp_reduce::{IcpReduceParams, kinect_sigma_m};

/// One point-to-plane correspondence's weighted row (√w J, √w r) (the kernel's loop body):
/// `None` when the pixel has no valid pair. Shared by the reference and the tracker's diagnostics.
pub fn icp_row(params: &IcpReduceParams, v_cam: [f32; 4], n_cam: [f32; 4], predicted_vertex_in_world: &[[f32; 4]], predicted_normal_in_world: &[[f32; 4]]) -> Option<[f32; 7]> {
    let k = &params.intrinsics;
    if !is_valid_f32(v_cam[2]) || !is_valid_f32(n_cam[0]) {
        return None;
    }
    let v = transform_point(&params.world_from_camera, [v_cam[0], v_cam[1], v_cam[2]]);
    let n = transform_vector(&params.world_from_camera, [n_cam[0], n_cam[1], n_cam[2]]);
    let p_prev = transform_point(&params.camera_prev_from_world, v);
    if !(p_prev[2] > 0.0) {
        return None;
    }
    let u = (k.fx_px * p_prev[0] / p_prev[2] + k.cx_px + 0.5).floor();
    let w = (k.fy_px * p_prev[1] / p_prev[2] + k.cy_px + 0.5).floor();
    if !(u >= 0.0 && w >= 0.0 && u < k.width_px as f32 && w < k.height_px as f32) {
        return None;
    }
    let jx = (w as u32 * k.width_px + u as u32) as usize;
    let q = predicted_vertex_in_world[jx];
    let m = predicted_normal_in_world[jx];
    if !is_valid_f32(q[0]) || !is_valid_f32(m[0]) {
        return None;
    }
    let m3 = [m[0], m[1], m[2]];
    let diff = [v[0] - q[0], v[1] - q[1], v[2] - q[2]];
    if !(dot3(diff, diff) <= params.dist_thresh_m * params.dist_thresh_m) || !(dot3(n, m3) >= params.cos_angle_thresh) {
        return None;
    }
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
    Some([a[0], a[1], a[2], m3[0] * sw, m3[1] * sw, m3[2] * sw, r * sw])
}

/// Fills `partial_sums` (one block of `SUM_FLOATS` per workgroup) as the kernel does.
pub fn icp_reduce(
    params: &IcpReduceParams,
    vertex_in_camera: &[[f32; 4]],
    normal_in_camera: &[[f32; 4]],
    predicted_vertex_in_world: &[[f32; 4]],
    predicted_normal_in_world: &[[f32; 4]],
    partial_sums: &mut [f32],
) {
    let pixel_count = params.intrinsics.width_px * params.intrinsics.height_px;
    reduce_normal_equations(params.thread_count, pixel_count, partial_sums, |ix| {
        icp_row(params, vertex_in_camera[ix], normal_in_camera[ix], predicted_vertex_in_world, predicted_normal_in_world)
    });
}
