// SPDX-License-Identifier: MIT
//! Pinhole camera model and calibration.
//!
//! Pixel coordinates have their origin at the centre of the top-left pixel, x to the right,
//! y down; the camera looks down +z (000-digest §2.1, Eq. 3.7).

use glam::Vec3;

/// Pinhole intrinsics of a depth image (registered to colour on Kinect-class sensors).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PinholeIntrinsics {
    /// Focal length along x, in pixels.
    pub fx_px: f32,
    /// Focal length along y, in pixels.
    pub fy_px: f32,
    /// Principal point x, in pixels.
    pub cx_px: f32,
    /// Principal point y, in pixels.
    pub cy_px: f32,
    /// Image width in pixels.
    pub width_px: u32,
    /// Image height in pixels.
    pub height_px: u32,
}

impl PinholeIntrinsics {
    /// The Kinect's nominal camera, 525 px at 640x480, scaled to `width_px` x `height_px`
    /// (what `simulate` and `synth-room` use without `--intrinsics`, and the page's virtual
    /// sensor at a pose no real frame has).
    pub fn nominal_kinect(width_px: u32, height_px: u32) -> Self {
        let f = 525.0 * width_px as f32 / 640.0;
        Self { fx_px: f, fy_px: f, cx_px: 0.5 * width_px as f32 - 0.5, cy_px: 0.5 * height_px as f32 - 0.5, width_px, height_px }
    }

    /// Intrinsics of the image made by averaging 2x2 blocks (`depth_pyramid_down`).
    ///
    /// A coarse pixel u covers fine pixels 2u and 2u+1, whose centre is 2u + 0.5, so
    /// `cx' = (cx - 0.5) / 2`; the size is halved and rounded down.
    pub fn half_resolution(&self) -> Self {
        Self {
            fx_px: self.fx_px * 0.5,
            fy_px: self.fy_px * 0.5,
            cx_px: (self.cx_px - 0.5) * 0.5,
            cy_px: (self.cy_px - 0.5) * 0.5,
            width_px: self.width_px / 2,
            height_px: self.height_px / 2,
        }
    }

    /// Intrinsics of pyramid level `level` (0 = full resolution).
    pub fn pyramid_level(&self, level: usize) -> Self {
        (0..level).fold(*self, |k, _| k.half_resolution())
    }

    /// Number of pixels.
    pub fn pixel_count(&self) -> usize {
        self.width_px as usize * self.height_px as usize
    }

    /// Back-projects pixel `(u, v)` at depth `z_m` into the camera frame (Eq. 3.7).
    pub fn back_project(&self, u_px: f32, v_px: f32, z_m: f32) -> Vec3 {
        Vec3::new((u_px - self.cx_px) * z_m / self.fx_px, (v_px - self.cy_px) * z_m / self.fy_px, z_m)
    }

    /// Projects a camera-frame point to continuous pixel coordinates (Eq. 3.2).
    pub fn project(&self, point_in_camera: Vec3) -> glam::Vec2 {
        glam::Vec2::new(
            self.fx_px * point_in_camera.x / point_in_camera.z + self.cx_px,
            self.fy_px * point_in_camera.y / point_in_camera.z + self.cy_px,
        )
    }
}

/// Depth units of the TUM RGB-D benchmark and of OpenNI's 100 µm mode: 5000 units per metre.
pub const TUM_DEPTH_UNITS_PER_METRE: f32 = 5000.0;

/// Published TUM RGB-D calibration of the `freiburg1` Kinect (640x480).
pub const TUM_FREIBURG1: PinholeIntrinsics =
    PinholeIntrinsics { fx_px: 517.3, fy_px: 516.5, cx_px: 318.6, cy_px: 255.3, width_px: 640, height_px: 480 };
/// Published TUM RGB-D calibration of the `freiburg2` Kinect (640x480).
pub const TUM_FREIBURG2: PinholeIntrinsics =
    PinholeIntrinsics { fx_px: 520.9, fy_px: 521.0, cx_px: 325.1, cy_px: 249.7, width_px: 640, height_px: 480 };
/// Published TUM RGB-D calibration of the `freiburg3` Asus Xtion (640x480).
pub const TUM_FREIBURG3: PinholeIntrinsics =
    PinholeIntrinsics { fx_px: 535.4, fy_px: 539.2, cx_px: 320.1, cy_px: 247.6, width_px: 640, height_px: 480 };

/// Everything needed to interpret a source's frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RgbdCalibration {
    /// Intrinsics of the (colour-registered) depth image.
    pub intrinsics: PinholeIntrinsics,
    /// Raw depth units per metre (5000 for TUM, 1000 for OpenNI millimetres).
    pub depth_units_per_metre: f32,
}

impl RgbdCalibration {
    /// Metres per raw depth unit, as the kernels use it.
    pub fn metres_per_depth_unit(&self) -> f32 {
        1.0 / self.depth_units_per_metre
    }
}
