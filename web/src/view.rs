// SPDX-License-Identifier: MIT
//! The 2D side of the views: the colour image, the free viewer's camera and the trajectory
//! drawn over the raycast model (the colour-mapped views are drawn on the GPU, `canvas.rs`).

use glam::{DMat3, DQuat, DVec3};
use wasm_bindgen::prelude::*;
use webfusion_core::odometry::assist::PairView;
use webfusion_core::{PinholeIntrinsics, Se3};

/// Packed RGB8 as RGBA8.
pub(crate) fn rgba_from_rgb(rgb8: &[u8]) -> Vec<u8> {
    rgb8.chunks_exact(3).flat_map(|p| [p[0], p[1], p[2], 255]).collect()
}

/// The 2D context of a canvas sized `width`x`height` (resized to fit).
///
/// Rasterised on the CPU (`willReadFrequently`): what the page draws in 2D comes from the host
/// (frames' colour, keypoints, trajectories), so a GPU-accelerated canvas only adds an upload
/// and, where the browser's GPU is itself software (SwiftShader), rasterises every stroke
/// there: the odometry view alone cost the GPU process 0.3 s a frame that way.
pub(crate) fn context_2d(canvas: &web_sys::HtmlCanvasElement, width: u32, height: u32) -> Result<web_sys::CanvasRenderingContext2d, JsValue> {
    if canvas.width() != width || canvas.height() != height {
        canvas.set_width(width);
        canvas.set_height(height);
    }
    let options = js_sys::Object::new();
    js_sys::Reflect::set(&options, &"willReadFrequently".into(), &JsValue::TRUE)?;
    canvas.get_context_with_context_options("2d", &options)?.ok_or("no 2d context")?.dyn_into().map_err(JsValue::from)
}

/// Puts RGBA8 pixels of `width`x`height` on a canvas, resizing it to fit.
pub(crate) fn draw_rgba(canvas: &web_sys::HtmlCanvasElement, width: u32, height: u32, rgba: &[u8]) -> Result<web_sys::CanvasRenderingContext2d, JsValue> {
    let ctx = context_2d(canvas, width, height)?;
    let image = web_sys::ImageData::new_with_u8_clamped_array_and_sh(wasm_bindgen::Clamped(rgba), width, height)?;
    ctx.put_image_data(&image, 0.0, 0.0)?;
    Ok(ctx)
}

/// An RGBA8 image: its frame index, width, height and pixels.
pub(crate) type FrameImage = (u64, u32, u32, Vec<u8>);

/// Draws a feature-odometry pair side by side (the last accepted frame left, the current one
/// right) with what `stage` (an index into `PAIR_STAGES`) shows: 0 the frames, 1 the
/// keypoints (circles of 3 · 2^level px), 2 their orientations, 3 the kept matches, 4 RANSAC's
/// inliers (green) and outliers (red).
pub(crate) fn draw_odometry_pair(canvas: &web_sys::HtmlCanvasElement, reference: &FrameImage, current: &FrameImage, pair: &PairView, stage: usize) -> Result<(), JsValue> {
    let (w, h) = (current.1, current.2);
    if (reference.1, reference.2) != (w, h) {
        return Err("the two frames differ in size".into());
    }
    let ctx = context_2d(canvas, 2 * w, h)?;
    for (image, x0) in [(reference, 0.0), (current, f64::from(w))] {
        let data = web_sys::ImageData::new_with_u8_clamped_array_and_sh(wasm_bindgen::Clamped(&image.3), w, h)?;
        ctx.put_image_data(&data, x0, 0.0)?;
    }
    ctx.set_line_width(1.5);
    // One path per colour, stroked once, not a stroke per keypoint or match (a thousand a frame).
    let radius = |k: &[f32; 4]| 3.0 * f64::from(1u32 << (k[3].max(0.0) as u32).min(4));
    if stage >= 1 {
        ctx.set_stroke_style_str("rgba(255, 220, 0, 0.9)");
        ctx.begin_path();
        for (keypoints, x0) in [(&pair.reference, 0.0), (&pair.current, f64::from(w))] {
            for k in keypoints.iter() {
                let (x, y, r) = (x0 + f64::from(k[0]), f64::from(k[1]), radius(k));
                // A new subpath at the circle's start, so no line joins it to the last one.
                ctx.move_to(x + r, y);
                ctx.arc(x, y, r, 0.0, std::f64::consts::TAU)?;
                if stage >= 2 {
                    ctx.move_to(x, y);
                    ctx.line_to(x + r * f64::from(k[2]).cos(), y + r * f64::from(k[2]).sin());
                }
            }
        }
        ctx.stroke();
    }
    if stage >= 3 {
        let colours: &[(&str, Option<bool>)] = if stage == 3 { &[("rgba(0, 200, 255, 0.8)", None)] } else { &[("rgba(40, 230, 40, 0.9)", Some(true)), ("rgba(255, 40, 40, 0.9)", Some(false))] };
        for &(colour, inliers) in colours {
            ctx.set_stroke_style_str(colour);
            ctx.begin_path();
            for &(q, t, _) in pair.matches.iter().filter(|m| inliers.is_none_or(|i| i == m.2)) {
                let (Some(c), Some(r)) = (pair.current.get(q as usize), pair.reference.get(t as usize)) else { continue };
                ctx.move_to(f64::from(r[0]), f64::from(r[1]));
                ctx.line_to(f64::from(w) + f64::from(c[0]), f64::from(c[1]));
            }
            ctx.stroke();
        }
    }
    Ok(())
}

/// The free viewer: it orbits a target point about the world's up direction (`up_in_world`: −y
/// in a tracked run's first-camera frame, where x is right, y down and z forward; a map fused at
/// given poses says its own, e.g. +z in a mocap or robot frame).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Orbit {
    pub(crate) target_in_world: DVec3,
    pub(crate) distance_m: f64,
    /// Turn about the up axis, radians (0: looking along `forward_in_world`, the world's z made
    /// level, like a first camera's; x where z is nearly vertical).
    pub(crate) yaw_rad: f64,
    /// Elevation, radians (positive: looking down from above).
    pub(crate) pitch_rad: f64,
    /// The world's up, a unit vector.
    up_in_world: DVec3,
}

impl Orbit {
    /// Looks at `target_in_world` from behind and above, in a world whose up is `up_in_world`
    /// (normalised; −y when it is not a direction).
    pub(crate) fn looking_at(target_in_world: DVec3, distance_m: f64, up_in_world: DVec3) -> Self {
        let up_in_world = up_in_world.try_normalize().unwrap_or(DVec3::NEG_Y);
        Self { target_in_world, distance_m, yaw_rad: 0.5, pitch_rad: 0.45, up_in_world }
    }

    /// The horizontal direction of yaw 0: the world's z made perpendicular to up (a first
    /// camera's view direction, levelled, so a map in that frame is first seen the way its
    /// camera saw it, whatever small tilt the up has), or x where z is nearly vertical (a
    /// mocap or robot frame).
    fn forward_in_world(&self) -> DVec3 {
        let up = self.up_in_world;
        let axis = if DVec3::Z.dot(up).abs() < 0.9 { DVec3::Z } else { DVec3::X };
        (axis - axis.dot(up) * up).normalize()
    }

    /// The viewer's pose: camera z towards the target, camera x level, camera y towards world
    /// down.
    pub(crate) fn world_from_viewer(&self) -> Se3 {
        let (sy, cy) = self.yaw_rad.sin_cos();
        let (sp, cp) = self.pitch_rad.sin_cos();
        let up = self.up_in_world;
        let forward = self.forward_in_world();
        let right = forward.cross(up);
        let eye = self.target_in_world + self.distance_m * (sy * cp * right + sp * up - cy * cp * forward);
        let z = (self.target_in_world - eye).normalize();
        let x = z.cross(up).normalize();
        let y = z.cross(x);
        Se3::new(DQuat::from_mat3(&DMat3::from_cols(x, y, z)), eye)
    }

    pub(crate) fn orbit(&mut self, dx_px: f32, dy_px: f32) {
        self.yaw_rad += f64::from(dx_px) * 0.01;
        self.pitch_rad = (self.pitch_rad + f64::from(dy_px) * 0.01).clamp(-1.5, 1.5);
    }

    /// Moves the target in the view plane, by pixels at the target's distance.
    pub(crate) fn pan(&mut self, dx_px: f32, dy_px: f32, focal_px: f32) {
        let pose = self.world_from_viewer();
        let scale = self.distance_m / f64::from(focal_px);
        let right = pose.rotation * DVec3::X;
        let down = pose.rotation * DVec3::Y;
        self.target_in_world -= scale * (f64::from(dx_px) * right + f64::from(dy_px) * down);
    }

    pub(crate) fn zoom(&mut self, factor: f32) {
        self.distance_m = (self.distance_m * f64::from(factor)).clamp(0.1, 50.0);
    }
}

/// Pixel of a world point seen by a camera at `world_from_camera`, if in front of it.
pub(crate) fn project(k: &PinholeIntrinsics, world_from_camera: &Se3, point_in_world: DVec3) -> Option<(f64, f64)> {
    let p = world_from_camera.inverse().transform_point(point_in_world);
    (p.z > 0.05).then(|| (f64::from(k.fx_px) * p.x / p.z + f64::from(k.cx_px), f64::from(k.fy_px) * p.y / p.z + f64::from(k.cy_px)))
}

/// Draws a polyline of world points (`None` breaks it) on `ctx`, as seen from the viewer.
pub(crate) fn draw_path(ctx: &web_sys::CanvasRenderingContext2d, k: &PinholeIntrinsics, world_from_viewer: &Se3, points: impl Iterator<Item = DVec3>, colour: &str) {
    ctx.set_stroke_style_str(colour);
    ctx.set_line_width(2.0);
    ctx.begin_path();
    let mut drawing = false;
    for point in points {
        match project(k, world_from_viewer, point) {
            Some((u, v)) if drawing => ctx.line_to(u, v),
            Some((u, v)) => {
                ctx.move_to(u, v);
                drawing = true;
            }
            None => drawing = false,
        }
    }
    ctx.stroke();
}

/// Draws the current camera as a small frustum.
pub(crate) fn draw_camera(ctx: &web_sys::CanvasRenderingContext2d, k: &PinholeIntrinsics, world_from_viewer: &Se3, world_from_camera: &Se3, colour: &str) {
    let s = 0.12;
    let corners = [DVec3::new(-s, -0.75 * s, s), DVec3::new(s, -0.75 * s, s), DVec3::new(s, 0.75 * s, s), DVec3::new(-s, 0.75 * s, s)].map(|c| world_from_camera.transform_point(c));
    let centre = world_from_camera.translation_m;
    for c in corners {
        draw_path(ctx, k, world_from_viewer, [centre, c].into_iter(), colour);
    }
    draw_path(ctx, k, world_from_viewer, corners.into_iter().chain(std::iter::once(corners[0])), colour);
}

#[cfg(test)]
mod tests {
    use wasm_bindgen_test::wasm_bindgen_test;

    use super::*;

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 420.0, fy_px: 420.0, cx_px: 319.5, cy_px: 239.5, width_px: 640, height_px: 480 };

    fn assert_near(a: (f64, f64), b: (f64, f64), what: &str) {
        assert!((a.0 - b.0).abs() < 1e-6 && (a.1 - b.1).abs() < 1e-6, "{what}: {a:?} vs {b:?}");
    }

    #[wasm_bindgen_test]
    fn the_orbit_camera_keeps_its_target_centred_at_its_distance() {
        let target = DVec3::new(0.3, -0.2, 1.5);
        // A first camera's world (y down) and a mocap or robot world (z up), and a tilted one.
        for up in [DVec3::NEG_Y, DVec3::Z, DVec3::new(0.3, -0.9, 0.2).normalize()] {
            let mut orbit = Orbit::looking_at(target, 3.0, up);
            for (dx, dy) in [(0.0, 0.0), (120.0, -40.0), (-300.0, 500.0)] {
                orbit.orbit(dx, dy);
                let pose = orbit.world_from_viewer();
                assert_near(project(&K, &pose, target).expect("target in front"), (319.5, 239.5), "target at the principal point");
                assert!((pose.translation_m.distance(target) - 3.0).abs() < 1e-9, "distance kept");
                // The viewer's x axis is level and its y axis points down the world, so the
                // world's up is up on screen and the horizon is level.
                assert!((pose.rotation * DVec3::X).dot(up).abs() < 1e-9, "level horizon, up {up}");
                assert!((pose.rotation * DVec3::Y).dot(up) <= 0.0, "no upside-down view, up {up}");
                // Elevation above the horizontal plane through the target is the pitch.
                let elevation = ((pose.translation_m - target).dot(up) / 3.0).asin();
                assert!((elevation - orbit.pitch_rad).abs() < 1e-9, "elevation {elevation} vs pitch {}", orbit.pitch_rad);
            }
            assert!(orbit.pitch_rad <= 1.5, "pitch clamped short of the pole");
        }
        // In a first camera's world, yaw 0 looks along +z like that camera, also when the up
        // (the mean of the cameras' up axes) tilts a little towards x.
        let level = Orbit { yaw_rad: 0.0, pitch_rad: 0.0, ..Orbit::looking_at(target, 3.0, DVec3::NEG_Y) };
        assert!((level.world_from_viewer().rotation * DVec3::Z - DVec3::Z).length() < 1e-9, "yaw 0 looks along +z");
        let tilted = Orbit { yaw_rad: 0.0, pitch_rad: 0.0, ..Orbit::looking_at(target, 3.0, DVec3::new(0.058, -0.995, 0.075)) };
        assert!((tilted.world_from_viewer().rotation * DVec3::Z).dot(DVec3::Z) > 0.99, "yaw 0 still looks along +z");
        // Negative control: in a z-up world yaw 0 looks along x.
        let z_up = Orbit { yaw_rad: 0.0, pitch_rad: 0.0, ..Orbit::looking_at(target, 3.0, DVec3::Z) };
        assert!((z_up.world_from_viewer().rotation * DVec3::Z - DVec3::X).length() < 1e-9, "z up: yaw 0 looks along +x");
        // Not a direction: the first camera's up.
        assert_eq!(Orbit::looking_at(target, 3.0, DVec3::ZERO).up_in_world, DVec3::NEG_Y);
    }

    #[wasm_bindgen_test]
    fn panning_moves_the_old_target_by_the_dragged_pixels() {
        let target = DVec3::new(0.0, 0.0, 2.0);
        let mut orbit = Orbit::looking_at(target, 2.0, DVec3::NEG_Y);
        orbit.pan(40.0, -25.0, K.fx_px);
        let pose = orbit.world_from_viewer();
        // The scene follows the pointer: the old target moves by the drag.
        assert_near(project(&K, &pose, target).expect("in front"), (319.5 + 40.0, 239.5 - 25.0), "old target follows the drag");
        orbit.zoom(0.5);
        assert!((orbit.distance_m - 1.0).abs() < 1e-12, "zoom scales the distance");
    }

    #[wasm_bindgen_test]
    fn points_behind_the_viewer_are_not_drawn() {
        let orbit = Orbit::looking_at(DVec3::new(0.0, 0.0, 2.0), 2.0, DVec3::Z);
        let pose = orbit.world_from_viewer();
        let behind = pose.transform_point(DVec3::new(0.0, 0.0, -1.0));
        assert_eq!(project(&K, &pose, behind), None, "behind the viewer");
        assert_eq!(rgba_from_rgb(&[1, 2, 3, 4, 5, 6]), vec![1, 2, 3, 255, 4, 5, 6, 255], "RGB gains opaque alpha");
    }
}
