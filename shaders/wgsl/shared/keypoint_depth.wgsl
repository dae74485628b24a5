// SPDX-License-Identifier: MIT
// The depth about a keypoint, as seed 002's border filter (`corner_candidates`) and the
// keypoint's lift (`keypoint_select`) both read it: the importing kernel declares
// `depth_m: array<f32>` (full resolution, metres; invalid where none). Mirrors
// core/src/cpu/odometry/keypoint_depth.rs.
#import kinect

// The full-resolution pixel nearest level-0 position (x0, y0), kept one pixel inside the
// width x height image so that its 3x3 window is too.
fn keypoint_depth_pixel(x0: f32, y0: f32, width: i32, height: i32) -> vec2<i32> {
    return vec2<i32>(clamp(i32(floor(x0 + 0.5)), 1, width - 2), clamp(i32(floor(y0 + 0.5)), 1, height - 2));
}

// The largest depth difference between neighbouring pixels on one surface with the centre's
// depth z, metres: 4 σ(z) of the Kinect noise model plus 2 z / f (the step between two pixels
// on a surface at 63° to the ray).
fn same_surface_step_m(z: f32, fx_px: f32) -> f32 {
    return 4.0 * kinect_sigma_m(z) + 2.0 * z / fx_px;
}
