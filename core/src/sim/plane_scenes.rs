// SPDX-License-Identifier: MIT
//! Scenes whose planes are known exactly, rendered by CPU ray casting in f64: the exact answers
//! of plane segmentation (seed 003). Each scene is a few rectangles (each on a known plane) and
//! optionally a cylinder (curved: it must not become planes), seen from one camera; the
//! renderer returns the depth, a colour texture, and per pixel the index of the plane it shows.
//!
//! World frame as in [`super::room`]: x right, y down, z forward. Planes are `n·p + d = 0` with
//! the unit normal `n` facing the camera; [`PlaneScene::planes_in_camera`] gives them in the
//! camera frame, the frame segmentation reports in.
//!
//! Noise (optional, seeded): axial Gaussian noise of standard deviation
//! σ(z) = 0.0012 + 0.0019 (z − 0.4)² metres (Nguyen, Izadi & Lovell 2012's Kinect v1 fit,
//! [`crate::cpu::shared::kinect_sigma_m`]: 1.9 mm at 1 m, 6.1 mm at 2 m, 14 mm at 3 m), drawn
//! per pixel from a counter-based generator, so a scene renders the same for the same seed.

use glam::{DQuat, DVec3};

use crate::cpu::shared::{kinect_sigma_m, pcg_hash, random_gauss2};
use crate::sim::room::{camera_ray, depth_units};
use crate::{ColorImage, DepthImage, PinholeIntrinsics, RgbdFrame, Se3};

/// Label of a pixel that shows no plane (a curved surface, or nothing).
pub const NO_PLANE: u32 = u32::MAX;

/// A plane `normal·p + offset_m = 0` (unit normal).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScenePlane {
    /// Unit normal.
    pub normal: DVec3,
    /// Offset, metres.
    pub offset_m: f64,
}

impl ScenePlane {
    /// The same plane in the frame `b` of a transform `a_from_b` (the plane given in `a`).
    pub fn in_frame(&self, a_from_b: &Se3) -> ScenePlane {
        // p_a = R p_b + t, so n·(R p_b + t) + d = (Rᵀn)·p_b + (d + n·t).
        ScenePlane { normal: a_from_b.rotation.inverse() * self.normal, offset_m: self.offset_m + self.normal.dot(a_from_b.translation_m) }
    }

    /// Signed distance of `p` from the plane, metres.
    pub fn distance_m(&self, p: DVec3) -> f64 {
        self.normal.dot(p) + self.offset_m
    }
}

/// A surface of a scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Surface {
    /// A rectangle: centre, two orthogonal unit axes and the half extents along them.
    Rect {
        /// Centre, world metres.
        centre: DVec3,
        /// First axis (unit).
        u: DVec3,
        /// Second axis (unit, orthogonal to `u`).
        v: DVec3,
        /// Half extents along `u` and `v`, metres.
        half_m: [f64; 2],
    },
    /// The outside of a finite cylinder: the centre of its axis, the axis (unit), radius and
    /// half length.
    Cylinder {
        /// Centre of the axis, world metres.
        centre: DVec3,
        /// Axis (unit).
        axis: DVec3,
        /// Radius, metres.
        radius_m: f64,
        /// Half the length, metres.
        half_length_m: f64,
    },
}

impl Surface {
    /// An axis-aligned rectangle from two opposite corners that share one coordinate.
    ///
    /// # Panics
    /// If the corners do not share exactly one coordinate (a scene's constant).
    pub fn aligned_rect(a: DVec3, b: DVec3) -> Surface {
        let flat: Vec<usize> = (0..3).filter(|&i| a[i] == b[i]).collect();
        assert_eq!(flat.len(), 1, "an axis-aligned rectangle's corners share one coordinate");
        let (i, j) = match flat[0] {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let mut u = DVec3::ZERO;
        u[i] = 1.0;
        let mut v = DVec3::ZERO;
        v[j] = 1.0;
        Surface::Rect { centre: 0.5 * (a + b), u, v, half_m: [0.5 * (a[i] - b[i]).abs(), 0.5 * (a[j] - b[j]).abs()] }
    }

    /// Distance along the unit ray `o + t dir` to the surface, when ahead.
    pub fn intersect(&self, o: DVec3, dir: DVec3) -> Option<f64> {
        match *self {
            Surface::Rect { centre, u, v, half_m } => {
                let n = u.cross(v);
                let denom = n.dot(dir);
                if denom.abs() < 1e-12 {
                    return None;
                }
                let t = n.dot(centre - o) / denom;
                let q = o + t * dir - centre;
                (t > 1e-9 && q.dot(u).abs() <= half_m[0] && q.dot(v).abs() <= half_m[1]).then_some(t)
            }
            Surface::Cylinder { centre, axis, radius_m, half_length_m } => {
                // |(o + t dir - c) - ((o + t dir - c)·a) a|² = r², nearest root ahead.
                let oc = o - centre;
                let (d_perp, oc_perp) = (dir - dir.dot(axis) * axis, oc - oc.dot(axis) * axis);
                let a = d_perp.length_squared();
                let b = 2.0 * d_perp.dot(oc_perp);
                let c = oc_perp.length_squared() - radius_m * radius_m;
                let disc = b * b - 4.0 * a * c;
                if a < 1e-12 || disc < 0.0 {
                    return None;
                }
                let sq = disc.sqrt();
                [(-b - sq) / (2.0 * a), (-b + sq) / (2.0 * a)].into_iter().find(|&t| t > 1e-9 && (oc + t * dir).dot(axis).abs() <= half_length_m)
            }
        }
    }

    /// The plane of a rectangle, its normal facing `eye`; `None` for a cylinder.
    pub fn plane_facing(&self, eye: DVec3) -> Option<ScenePlane> {
        match *self {
            Surface::Rect { centre, u, v, .. } => {
                let mut n = u.cross(v).normalize();
                if n.dot(eye - centre) < 0.0 {
                    n = -n;
                }
                Some(ScenePlane { normal: n, offset_m: -n.dot(centre) })
            }
            Surface::Cylinder { .. } => None,
        }
    }
}

/// One scene: surfaces and the camera.
#[derive(Clone, Debug, PartialEq)]
pub struct PlaneScene {
    /// Name (the test's name for it).
    pub name: &'static str,
    /// The surfaces; a rectangle's index is its plane's index in [`Self::planes_in_camera`].
    pub surfaces: Vec<Surface>,
    /// The camera's pose.
    pub world_from_camera: Se3,
}

/// A rendered scene.
#[derive(Clone, Debug)]
pub struct RenderedScene {
    /// Depth and colour, TUM's 5000 units per metre.
    pub frame: RgbdFrame,
    /// Per pixel, the index of the surface it shows when that surface is a plane, else
    /// [`NO_PLANE`].
    pub plane_of_pixel: Vec<u32>,
}

/// Depth units per metre of the rendered frames (TUM's).
pub const UNITS_PER_METRE: f64 = 5000.0;

impl PlaneScene {
    /// A camera at the origin turned by `yaw_deg` (positive: to the right) and pitched down by
    /// `pitch_deg`.
    fn camera(yaw_deg: f64, pitch_deg: f64) -> Se3 {
        Se3::new(DQuat::from_rotation_y(yaw_deg.to_radians()) * DQuat::from_rotation_x(-pitch_deg.to_radians()), DVec3::ZERO)
    }

    /// A room corner: floor 1.2 m below the camera, a wall on the left at 1.3 m and one ahead at
    /// 3.2 m; three planes.
    pub fn room_corner() -> Self {
        let floor = Surface::aligned_rect(DVec3::new(-1.3, 1.2, 0.0), DVec3::new(2.0, 1.2, 3.2));
        let left = Surface::aligned_rect(DVec3::new(-1.3, -1.5, 0.0), DVec3::new(-1.3, 1.2, 3.2));
        let back = Surface::aligned_rect(DVec3::new(-1.3, -1.5, 3.2), DVec3::new(2.0, 1.2, 3.2));
        Self { name: "room corner", surfaces: vec![floor, left, back], world_from_camera: Self::camera(-15.0, 25.0) }
    }

    /// A 0.7 x 0.5 x 0.6 m box on a floor 1.2 m below the camera, a wall behind at 3.4 m: the
    /// box's top, front and left faces, the floor and the wall.
    pub fn box_on_floor() -> Self {
        let (lo, hi) = (DVec3::new(0.4, 0.7, 1.6), DVec3::new(1.1, 1.2, 2.2));
        let floor = Surface::aligned_rect(DVec3::new(-2.0, 1.2, 0.0), DVec3::new(4.0, 1.2, 3.4));
        let wall = Surface::aligned_rect(DVec3::new(-2.0, -1.5, 3.4), DVec3::new(4.0, 1.2, 3.4));
        let top = Surface::aligned_rect(DVec3::new(lo.x, lo.y, lo.z), DVec3::new(hi.x, lo.y, hi.z));
        let front = Surface::aligned_rect(DVec3::new(lo.x, lo.y, lo.z), DVec3::new(hi.x, hi.y, lo.z));
        let left = Surface::aligned_rect(DVec3::new(lo.x, lo.y, lo.z), DVec3::new(lo.x, hi.y, hi.z));
        Self { name: "box on a floor", surfaces: vec![floor, wall, top, front, left], world_from_camera: Self::camera(15.0, 28.0) }
    }

    /// Four steps of 18 cm rise and 30 cm run going up away from the camera from 1.4 m, on a
    /// floor 1.3 m below it, a wall behind the top step: the floor, four risers and four treads
    /// (parallel planes 18 and 30 cm apart) and the wall.
    pub fn stairs() -> Self {
        let (rise, run, z0, floor_y, half_w) = (0.18, 0.30, 1.4, 1.3, 1.6);
        let mut surfaces = vec![Surface::aligned_rect(DVec3::new(-half_w, floor_y, 0.0), DVec3::new(half_w, floor_y, z0))];
        for i in 0..4 {
            let (z, y) = (z0 + f64::from(i) * run, floor_y - f64::from(i) * rise);
            surfaces.push(Surface::aligned_rect(DVec3::new(-half_w, y, z), DVec3::new(half_w, y - rise, z)));
            surfaces.push(Surface::aligned_rect(DVec3::new(-half_w, y - rise, z), DVec3::new(half_w, y - rise, z + run)));
        }
        let top_y = floor_y - 4.0 * rise;
        surfaces.push(Surface::aligned_rect(DVec3::new(-half_w, -1.5, z0 + 4.0 * run), DVec3::new(half_w, top_y, z0 + 4.0 * run)));
        Self { name: "stairs", surfaces, world_from_camera: Self::camera(0.0, 30.0) }
    }

    /// A wall 1.8 m ahead and a 1.2 x 0.9 m whiteboard 2 cm in front of it, the floor 1.3 m
    /// below the camera: two parallel planes 2 cm apart (seed 003 merges them).
    pub fn whiteboard() -> Self {
        let wall = Surface::aligned_rect(DVec3::new(-2.0, -1.5, 1.8), DVec3::new(2.0, 1.3, 1.8));
        let board = Surface::aligned_rect(DVec3::new(-0.6, -0.55, 1.78), DVec3::new(0.6, 0.35, 1.78));
        let floor = Surface::aligned_rect(DVec3::new(-2.0, 1.3, 0.0), DVec3::new(2.0, 1.3, 1.8));
        Self { name: "whiteboard on a wall", surfaces: vec![wall, board, floor], world_from_camera: Self::camera(0.0, 12.0) }
    }

    /// A standing cylinder of 25 cm radius 1.7 m ahead, a wall behind at 3 m and the floor 1.2 m
    /// below the camera: the cylinder must not become planes.
    pub fn cylinder() -> Self {
        let floor = Surface::aligned_rect(DVec3::new(-2.0, 1.2, 0.0), DVec3::new(2.0, 1.2, 3.0));
        let wall = Surface::aligned_rect(DVec3::new(-2.0, -1.5, 3.0), DVec3::new(2.0, 1.2, 3.0));
        let column = Surface::Cylinder { centre: DVec3::new(0.0, 0.0, 1.7), axis: DVec3::Y, radius_m: 0.25, half_length_m: 1.2 };
        Self { name: "cylinder", surfaces: vec![floor, wall, column], world_from_camera: Self::camera(0.0, 20.0) }
    }

    /// Every scene above.
    pub fn all() -> Vec<PlaneScene> {
        vec![Self::room_corner(), Self::box_on_floor(), Self::stairs(), Self::whiteboard(), Self::cylinder()]
    }

    /// Each surface's plane in the camera frame (`None` for curved surfaces), indexed like
    /// [`Self::surfaces`].
    pub fn planes_in_camera(&self) -> Vec<Option<ScenePlane>> {
        let eye = self.world_from_camera.translation_m;
        self.surfaces.iter().map(|s| s.plane_facing(eye).map(|p| p.in_frame(&self.world_from_camera))).collect()
    }

    /// The nearest surface along a world ray: its index and distance.
    pub fn cast(&self, o: DVec3, dir: DVec3) -> Option<(usize, f64)> {
        self.surfaces.iter().enumerate().filter_map(|(i, s)| s.intersect(o, dir).map(|t| (i, t))).min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Renders the scene at `k`, exact or with the module's axial noise drawn from `seed`.
    pub fn render(&self, k: &PinholeIntrinsics, noise_seed: Option<u32>) -> RenderedScene {
        let n = k.pixel_count();
        let (mut depth, mut color, mut labels) = (Vec::with_capacity(n), Vec::with_capacity(3 * n), Vec::with_capacity(n));
        let o = self.world_from_camera.translation_m;
        for y in 0..k.height_px {
            for x in 0..k.width_px {
                let dir_cam = camera_ray(k, x, y);
                let Some((surface, t)) = self.cast(o, self.world_from_camera.rotation * dir_cam) else {
                    depth.push(0);
                    color.extend([0, 0, 0]);
                    labels.push(NO_PLANE);
                    continue;
                };
                let mut z = t * dir_cam.z;
                if let Some(seed) = noise_seed {
                    let mut state = pcg_hash(seed ^ pcg_hash(y * k.width_px + x));
                    z += f64::from(kinect_sigma_m(z as f32)) * f64::from(random_gauss2(&mut state)[0]);
                }
                depth.push(depth_units(z, 1.0, UNITS_PER_METRE));
                // A texture of 10 cm checks, a shade per surface: something for texturing to show.
                let p = o + t * (self.world_from_camera.rotation * dir_cam);
                let check = ((p.x / 0.1).floor() + (p.y / 0.1).floor() + (p.z / 0.1).floor()).rem_euclid(2.0);
                let shade = 0.35 + 0.1 * (surface % 5) as f64 + 0.2 * check;
                color.extend([(255.0 * shade) as u8, (200.0 * shade) as u8, (160.0 * shade) as u8]);
                labels.push(if matches!(self.surfaces[surface], Surface::Rect { .. }) { surface as u32 } else { NO_PLANE });
            }
        }
        RenderedScene {
            frame: RgbdFrame {
                index: 0,
                depth_timestamp_ns: 0,
                color_timestamp_ns: 0,
                depth: DepthImage::new(k.width_px, k.height_px, depth).expect("the renderer fills every pixel"),
                color: ColorImage::new(k.width_px, k.height_px, color).expect("the renderer fills every pixel"),
            },
            plane_of_pixel: labels,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

    #[test]
    fn rendered_points_lie_on_their_planes_in_the_camera_frame() {
        for scene in PlaneScene::all() {
            let r = scene.render(&K, None);
            let planes = scene.planes_in_camera();
            let mut seen = vec![0usize; planes.len()];
            for (i, &label) in r.plane_of_pixel.iter().enumerate() {
                let units = r.frame.depth.units[i];
                if label == NO_PLANE || units == 0 {
                    continue;
                }
                let (x, y) = (i as u32 % K.width_px, i as u32 / K.width_px);
                let ray = camera_ray(&K, x, y);
                let p = ray * (f64::from(units) / UNITS_PER_METRE / ray.z);
                let plane = planes[label as usize].expect("a labelled pixel shows a plane");
                assert!(plane.distance_m(p).abs() < 1e-3, "{}: pixel {i} lies {} m off its plane", scene.name, plane.distance_m(p));
                assert!(plane.normal.dot(p) < 0.0, "{}: the normal faces the camera", scene.name);
                seen[label as usize] += 1;
            }
            for (s, count) in seen.iter().enumerate() {
                if planes[s].is_some() {
                    assert!(*count > 0, "{}: surface {s} is in view", scene.name);
                }
            }
        }
    }

    #[test]
    fn depth_stays_within_the_range_segmentation_is_tested_at() {
        for scene in PlaneScene::all() {
            let r = scene.render(&K, None);
            let (lo, hi) = r.frame.depth.units.iter().filter(|&&u| u > 0).fold((u16::MAX, 0), |(a, b), &u| (a.min(u), b.max(u)));
            let (lo, hi) = (f64::from(lo) / UNITS_PER_METRE, f64::from(hi) / UNITS_PER_METRE);
            assert!(lo > 0.5 && hi < 4.5, "{}: depth {lo:.2}..{hi:.2} m", scene.name);
            assert!(r.frame.depth.units.iter().filter(|&&u| u > 0).count() > 9 * K.pixel_count() / 10, "{}: the view is filled", scene.name);
        }
    }

    #[test]
    fn noise_is_seeded_and_grows_with_depth() {
        let scene = PlaneScene::room_corner();
        let a = scene.render(&K, Some(7));
        assert_eq!(a.frame.depth.units, scene.render(&K, Some(7)).frame.depth.units, "same seed, same image");
        assert_ne!(a.frame.depth.units, scene.render(&K, Some(8)).frame.depth.units, "another seed, another image");
        let exact = scene.render(&K, None);
        // Spread of noisy - exact by depth: near (< 1.8 m) vs far (> 2.8 m).
        let spread = |near: bool| {
            let e: Vec<f64> = (0..K.pixel_count())
                .filter(|&i| exact.frame.depth.units[i] > 0 && a.frame.depth.units[i] > 0)
                .filter(|&i| {
                    let z = f64::from(exact.frame.depth.units[i]) / UNITS_PER_METRE;
                    if near { z < 1.8 } else { z > 2.8 }
                })
                .map(|i| (f64::from(a.frame.depth.units[i]) - f64::from(exact.frame.depth.units[i])) / UNITS_PER_METRE)
                .collect();
            (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
        };
        let (near, far) = (spread(true), spread(false));
        assert!(near < 0.006 && far > 0.011 && far < 0.02, "noise spread {near:.4} m near, {far:.4} m far");
    }
}
