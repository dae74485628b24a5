// SPDX-License-Identifier: MIT
//! Synthetic depth scenes with known geometry.

use webfusion_core::PinholeIntrinsics;
use webfusion_core::sim::room::{camera_ray, depth_units, ray_box_entry, ray_box_exit};

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

/// The analytic test room: the inside of a box (walls, floor, ceiling), a solid box standing on
/// the floor and a sphere, in world metres (y down, the first camera looking along +z).
pub(crate) struct Room;

impl Room {
    const ROOM_MIN: [f32; 3] = [-1.6, -1.2, -1.0];
    const ROOM_MAX: [f32; 3] = [1.6, 1.0, 3.2];
    const BOX_MIN: [f32; 3] = [-0.6, 0.4, 1.5];
    const BOX_MAX: [f32; 3] = [0.0, 1.0, 2.1];
    const SPHERE_CENTRE: [f32; 3] = [0.6, 0.1, 1.9];
    const SPHERE_RADIUS_M: f32 = 0.35;

    /// Distance along the unit ray `dir` from `o` to the first surface (f64 for exactness).
    pub(crate) fn ray_distance(o: [f64; 3], dir: [f64; 3]) -> Option<f64> {
        let (o, dir) = (glam::DVec3::from_array(o), glam::DVec3::from_array(dir));
        let v = |a: [f32; 3]| glam::DVec3::from_array(a.map(f64::from));
        // Inside the room: the nearest exit face; then the solid box and the sphere.
        let mut best = ray_box_exit(o, dir, v(Self::ROOM_MIN), v(Self::ROOM_MAX)).unwrap_or(f64::INFINITY);
        if let Some(t) = ray_box_entry(o, dir, v(Self::BOX_MIN), v(Self::BOX_MAX)) {
            best = best.min(t);
        }
        let oc = o - v(Self::SPHERE_CENTRE);
        let b = oc.dot(dir);
        let cc = oc.length_squared() - f64::from(Self::SPHERE_RADIUS_M).powi(2);
        let disc = b * b - cc;
        if disc >= 0.0 {
            let t = -b - disc.sqrt();
            if t > 0.0 {
                best = best.min(t);
            }
        }
        best.is_finite().then_some(best)
    }

    /// Raw depth (units of 1/`UNITS_PER_M` m) seen from `world_from_camera`.
    pub(crate) fn render_depth_units(k: &PinholeIntrinsics, world_from_camera: &webfusion_core::Se3) -> Vec<u16> {
        render_scene_units(k, world_from_camera, Self::ray_distance)
    }
}

/// Raw depth (units of 1/`UNITS_PER_M` m) of a scene given by its ray-distance function,
/// seen from `world_from_camera`; rays meeting nothing (or beyond the u16 range) read 0.
pub(crate) fn render_scene_units(k: &PinholeIntrinsics, world_from_camera: &webfusion_core::Se3, ray_distance: impl Fn([f64; 3], [f64; 3]) -> Option<f64>) -> Vec<u16> {
    let mut out = Vec::with_capacity(k.pixel_count());
    let o = world_from_camera.translation_m;
    for y in 0..k.height_px {
        for x in 0..k.width_px {
            let dir_cam = camera_ray(k, x, y);
            let dir = world_from_camera.rotation * dir_cam;
            out.push(ray_distance(o.to_array(), dir.to_array()).map_or(0, |t| depth_units(t, dir_cam.z, f64::from(UNITS_PER_M))));
        }
    }
    out
}

/// Distance along `dir` from `o` to the nearest of the planes `n · p = d` (unit n) in front.
pub(crate) fn nearest_plane(o: [f64; 3], dir: [f64; 3], planes: &[([f64; 3], f64)]) -> Option<f64> {
    planes
        .iter()
        .filter_map(|(n, d)| {
            let denom = n[0] * dir[0] + n[1] * dir[1] + n[2] * dir[2];
            let t = (d - (n[0] * o[0] + n[1] * o[1] + n[2] * o[2])) / denom;
            (denom.abs() > 1e-12 && t > 1e-9).then_some(t)
        })
        .min_by(f64::total_cmp)
}
