// SPDX-License-Identifier: MIT
//! The depth about a keypoint, shared by the twins of `corner_candidates` (002's border filter)
//! and `keypoint_select` (the lift): twin of `shaders/wgsl/shared/keypoint_depth.wgsl`.

use crate::cpu::shared::kinect_sigma_m;

/// The full-resolution pixel nearest level-0 position (x0, y0), kept one pixel inside the
/// `width` x `height` image so that its 3x3 window is too.
pub(crate) fn keypoint_depth_pixel(x0: f32, y0: f32, width: i32, height: i32) -> (i32, i32) {
    (((x0 + 0.5).floor() as i32).clamp(1, width - 2), ((y0 + 0.5).floor() as i32).clamp(1, height - 2))
}

/// The largest depth difference between neighbouring pixels on one surface with the centre's
/// depth `z_m`, metres: 4 σ(z) of the Kinect noise model plus 2 z / f.
pub(crate) fn same_surface_step_m(z_m: f32, fx_px: f32) -> f32 {
    4.0 * kinect_sigma_m(z_m) + 2.0 * z_m / fx_px
}
