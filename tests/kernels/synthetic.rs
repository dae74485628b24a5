// SPDX-License-Identifier: MIT
//! Synthetic depth scenes with known geometry.

use webfusion_core::PinholeIntrinsics;

/// 80x60 camera with TUM-like focal lengths scaled to the size.
pub(crate) const K_SMALL: PinholeIntrinsics = PinholeIntrinsics { fx_px: 64.7, fy_px: 64.6, cx_px: 39.8, cy_px: 31.9, width_px: 80, height_px: 60 };

/// Raw units per metre used by the synthetic scenes (TUM's 5000).
pub(crate) const UNITS_PER_M: f32 = 5000.0;

/// A wall at 2.0 m with a box face at 1.2 m in the middle (a step edge), a hole of zeros,
/// and a stripe out of range (9 m). Raw units.
pub(crate) fn step_scene(k: &PinholeIntrinsics) -> Vec<u16> {
    let (w, h) = (k.width_px, k.height_px);
    let mut units = vec![(2.0 * UNITS_PER_M) as u16; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let ix = (y * w + x) as usize;
            if (w / 4..w / 2).contains(&x) && (h / 4..3 * h / 4).contains(&y) {
                units[ix] = (1.2 * UNITS_PER_M) as u16;
            }
            if (3 * w / 4..3 * w / 4 + 4).contains(&x) && (h / 3..h / 3 + 5).contains(&y) {
                units[ix] = 0;
            }
            if y == h - 3 {
                units[ix] = 45000;
            }
        }
    }
    units
}

/// A plane through (0, 0, z0) with unit normal facing the camera, as metres per pixel
/// (ray-plane intersection along each pixel's ray).
pub(crate) fn plane_depth_m(k: &PinholeIntrinsics, z0_m: f32, normal: [f32; 3]) -> Vec<f32> {
    let mut out = Vec::with_capacity(k.pixel_count());
    for y in 0..k.height_px {
        for x in 0..k.width_px {
            let ray = [(x as f32 - k.cx_px) / k.fx_px, (y as f32 - k.cy_px) / k.fy_px, 1.0];
            // n . (t * ray - (0, 0, z0)) = 0  ->  t = n_z z0 / (n . ray); depth = t.
            let t = normal[2] * z0_m / (normal[0] * ray[0] + normal[1] * ray[1] + normal[2] * ray[2]);
            out.push(t);
        }
    }
    out
}
