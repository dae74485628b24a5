// SPDX-License-Identifier: MIT
//! A synthetic furnished room of any size, rendered exactly (CPU ray casting in f64): the
//! "room-sized run" of the sparse map and a scene with exact answers for tracking.
//!
//! World frame: x right, y down (gravity along +y), z forward; the room spans
//! [-w/2, w/2] x [-h + 1.5, 1.5] x [-d/2, d/2] metres, so the floor is at y = 1.5 m and a camera
//! at y = 0 is 1.5 m above it. Along the walls stand cabinets and shelves, in the room tables and
//! pillars, laid out in proportion to its size (deterministically: the same room for the same
//! size), so every view holds structure in three directions and ICP stays well conditioned.
//! Colour is a view-independent texture (each surface's albedo times a 30 cm checker and a 7 cm
//! stripe), so brightness constancy holds exactly for the photometric term.

use glam::{DQuat, DVec3};

use crate::{ColorImage, DepthImage, PinholeIntrinsics, RgbdFrame, Se3};

/// Height of the floor on the world's y axis (down), metres.
pub const FLOOR_Y_M: f64 = 1.5;

/// An axis-aligned box of furniture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FurnitureBox {
    /// Lower corner, world metres.
    pub min: DVec3,
    /// Upper corner, world metres.
    pub max: DVec3,
    /// Base colour, RGB in [0, 1].
    pub albedo: [f64; 3],
}

/// What a ray meets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Distance along the (unit) ray, metres.
    pub t_m: f64,
    /// The point hit, world metres.
    pub point: DVec3,
    /// The surface's base colour.
    pub albedo: [f64; 3],
}

/// Distance along the ray from `o` (inside the box `lo`..`hi`) in direction `dir` to where it
/// leaves the box, when that lies ahead.
pub fn ray_box_exit(o: DVec3, dir: DVec3, lo: DVec3, hi: DVec3) -> Option<f64> {
    let mut exit = f64::INFINITY;
    for i in 0..3 {
        if dir[i] > 0.0 {
            exit = exit.min((hi[i] - o[i]) / dir[i]);
        } else if dir[i] < 0.0 {
            exit = exit.min((lo[i] - o[i]) / dir[i]);
        }
    }
    (exit.is_finite() && exit > 0.0).then_some(exit)
}

/// Distance along the ray from `o` in direction `dir` to where it enters the solid box
/// `min`..`max` (the slab method), when that lies ahead.
pub fn ray_box_entry(o: DVec3, dir: DVec3, min: DVec3, max: DVec3) -> Option<f64> {
    let (mut t_near, mut t_far) = (f64::NEG_INFINITY, f64::INFINITY);
    for i in 0..3 {
        if dir[i].abs() < 1e-15 {
            if o[i] < min[i] || o[i] > max[i] {
                t_near = f64::INFINITY;
            }
            continue;
        }
        let (a, c) = ((min[i] - o[i]) / dir[i], (max[i] - o[i]) / dir[i]);
        t_near = t_near.max(a.min(c));
        t_far = t_far.min(a.max(c));
    }
    (t_near <= t_far && t_near > 0.0).then_some(t_near)
}

/// The unit direction, in the camera frame, of pixel (`x`, `y`)'s ray.
pub fn camera_ray(k: &PinholeIntrinsics, x: u32, y: u32) -> DVec3 {
    DVec3::new((f64::from(x) - f64::from(k.cx_px)) / f64::from(k.fx_px), (f64::from(y) - f64::from(k.cy_px)) / f64::from(k.fy_px), 1.0).normalize()
}

/// The raw depth of a hit `t_m` along a pixel's unit ray whose camera-frame z is `ray_z`: z depth
/// in units of 1/`units_per_m` metres, rounded; 0 where it does not fit a u16 (none, or too far).
pub fn depth_units(t_m: f64, ray_z: f64, units_per_m: f64) -> u16 {
    let units = (t_m * ray_z * units_per_m).round();
    if units > 0.0 && units < 65535.0 { units as u16 } else { 0 }
}

/// A furnished room (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticRoom {
    /// Width (x), height (y) and depth (z), metres.
    pub size_m: [f64; 3],
    /// The furniture.
    pub boxes: Vec<FurnitureBox>,
}

impl SyntheticRoom {
    /// A room of `width_m` x `height_m` x `depth_m` with furniture along its walls and in it.
    ///
    /// # Panics
    /// If a size is below 2 m or not finite (a caller's constant).
    pub fn new(width_m: f64, height_m: f64, depth_m: f64) -> Self {
        assert!([width_m, height_m, depth_m].iter().all(|s| s.is_finite() && *s >= 2.0), "a room of at least 2 m each way");
        let (hw, hd) = (0.5 * width_m, 0.5 * depth_m);
        let floor = FLOOR_Y_M;
        let mut boxes = Vec::new();
        let mut add = |min: [f64; 3], max: [f64; 3], albedo: [f64; 3]| boxes.push(FurnitureBox { min: DVec3::from_array(min), max: DVec3::from_array(max), albedo });
        // Cabinets and shelves along the four walls, every ~2.5 m, alternating heights.
        let along = |len: f64| ((len / 2.5).floor() as usize).max(1);
        for i in 0..along(width_m) {
            let x = -hw + (i as f64 + 0.5) * width_m / along(width_m) as f64;
            let tall = if i % 2 == 0 { 1.9 } else { 0.9 };
            add([x - 0.45, floor - tall, -hd], [x + 0.45, floor, -hd + 0.45], [0.75, 0.55, 0.35]);
            add([x - 0.6, floor - 0.8 - 0.4 * (i % 3) as f64, hd - 0.4], [x + 0.3, floor, hd], [0.35, 0.5, 0.75]);
        }
        for i in 0..along(depth_m) {
            let z = -hd + (i as f64 + 0.5) * depth_m / along(depth_m) as f64;
            let tall = if i % 2 == 0 { 1.2 } else { 2.0 };
            add([-hw, floor - tall, z - 0.5], [-hw + 0.5, floor, z + 0.4], [0.45, 0.7, 0.45]);
            add([hw - 0.35, floor - 0.7 - 0.5 * (i % 2) as f64, z - 0.35], [hw, floor, z + 0.55], [0.8, 0.4, 0.4]);
        }
        // Tables and pillars on a grid inside the room, clear of a ring through the middle.
        for (fx, fz, kind) in [(-0.3, -0.3, 0), (0.3, 0.3, 0), (0.3, -0.3, 1), (-0.3, 0.3, 1), (0.0, 0.0, 2)] {
            let (x, z) = (fx * width_m, fz * depth_m);
            match kind {
                0 => {
                    add([x - 0.6, floor - 0.75, z - 0.4], [x + 0.6, floor - 0.7, z + 0.4], [0.6, 0.45, 0.3]);
                    add([x - 0.55, floor - 0.7, z - 0.35], [x - 0.45, floor, z - 0.25], [0.3, 0.3, 0.3]);
                    add([x + 0.45, floor - 0.7, z + 0.25], [x + 0.55, floor, z + 0.35], [0.3, 0.3, 0.3]);
                }
                1 => add([x - 0.2, floor - height_m, z - 0.2], [x + 0.2, floor, z + 0.2], [0.85, 0.85, 0.8]),
                _ => add([x - 0.35, floor - 1.1, z - 0.35], [x + 0.35, floor, z + 0.35], [0.5, 0.35, 0.6]),
            }
        }
        Self { size_m: [width_m, height_m, depth_m], boxes }
    }

    /// The room's inside box: lower and upper corners, world metres.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        let [w, h, d] = self.size_m;
        (DVec3::new(-0.5 * w, FLOOR_Y_M - h, -0.5 * d), DVec3::new(0.5 * w, FLOOR_Y_M, 0.5 * d))
    }

    /// The first surface along the unit ray from `o` (inside the room) in direction `dir`.
    pub fn cast(&self, o: DVec3, dir: DVec3) -> Option<Hit> {
        let (lo, hi) = self.bounds();
        // The room's walls, floor and ceiling: where the ray leaves it; then the nearest box.
        let mut best = ray_box_exit(o, dir, lo, hi).map(|t| (t, [0.82, 0.8, 0.74]));
        for b in &self.boxes {
            if let Some(t_near) = ray_box_entry(o, dir, b.min, b.max)
                && best.is_none_or(|(t, _)| t_near < t)
            {
                best = Some((t_near, b.albedo));
            }
        }
        best.map(|(t_m, albedo)| Hit { t_m, point: o + t_m * dir, albedo })
    }

    /// The texture at world point `p`: a 30 cm checker and a 7 cm stripe, in [0.55, 1].
    pub fn texture(p: DVec3) -> f64 {
        let cell = (p / 0.3).floor();
        let checker = (cell.x + cell.y + cell.z).rem_euclid(2.0);
        let stripe = 0.5 + 0.5 * (2.0 * std::f64::consts::PI * (p.x + p.y + p.z) / 0.07).sin();
        0.55 + 0.3 * checker + 0.15 * stripe
    }

    /// Depth (z along the camera axis, raw units of 1/`units_per_m` metres; 0 where the depth
    /// does not fit a u16) and colour (RGB8) seen from `world_from_camera`.
    pub fn render(&self, k: &PinholeIntrinsics, world_from_camera: &Se3, units_per_m: f64) -> (Vec<u16>, Vec<u8>) {
        // Bands of rows on every core (natively; one band in the browser), joined in order.
        #[cfg(not(target_arch = "wasm32"))]
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get).min(k.height_px as usize).max(1);
        #[cfg(target_arch = "wasm32")]
        let threads = 1usize;
        let rows = (k.height_px as usize).div_ceil(threads);
        let bands: Vec<(u32, u32)> = (0..threads).map(|t| ((t * rows) as u32, (((t + 1) * rows) as u32).min(k.height_px))).filter(|(a, b)| a < b).collect();
        let parts: Vec<(Vec<u16>, Vec<u8>)> = if bands.len() == 1 {
            vec![self.render_rows(k, world_from_camera, units_per_m, bands[0])]
        } else {
            std::thread::scope(|scope| {
                let handles: Vec<_> = bands.iter().map(|&band| scope.spawn(move || self.render_rows(k, world_from_camera, units_per_m, band))).collect();
                handles.into_iter().map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).collect()
            })
        };
        let mut depth = Vec::with_capacity(k.pixel_count());
        let mut color = Vec::with_capacity(3 * k.pixel_count());
        for (d, c) in parts {
            depth.extend(d);
            color.extend(c);
        }
        (depth, color)
    }

    /// [`Self::render`] of rows `first..end`.
    fn render_rows(&self, k: &PinholeIntrinsics, world_from_camera: &Se3, units_per_m: f64, (first, end): (u32, u32)) -> (Vec<u16>, Vec<u8>) {
        let n = ((end - first) * k.width_px) as usize;
        let mut depth = Vec::with_capacity(n);
        let mut color = Vec::with_capacity(3 * n);
        let o = world_from_camera.translation_m;
        for y in first..end {
            for x in 0..k.width_px {
                let dir_cam = camera_ray(k, x, y);
                match self.cast(o, world_from_camera.rotation * dir_cam) {
                    Some(hit) => {
                        depth.push(depth_units(hit.t_m, dir_cam.z, units_per_m));
                        let shade = Self::texture(hit.point);
                        color.extend(hit.albedo.map(|a| (255.0 * a * shade).round().clamp(0.0, 255.0) as u8));
                    }
                    None => {
                        depth.push(0);
                        color.extend([0, 0, 0]);
                    }
                }
            }
        }
        (depth, color)
    }

    /// A camera path of `frames` poses: one loop around the room's centre at a quarter of its
    /// smaller width, 1.5 m above the floor, looking 40° outward of the direction of travel and
    /// 12° down (walls, furniture and floor in view), with a slow ±4° nod and ±5 cm bob; the
    /// loop closes on the first pose, so the camera sees the start again at the end.
    pub fn path(&self, frames: usize) -> Vec<Se3> {
        let r = 0.25 * self.size_m[0].min(self.size_m[2]);
        (0..frames)
            .map(|i| {
                let phi = 2.0 * std::f64::consts::PI * i as f64 / frames.max(1) as f64;
                let nod = 4f64.to_radians() * (5.0 * phi).sin();
                let position = DVec3::new(r * phi.cos(), 0.05 * (3.0 * phi).sin(), r * phi.sin());
                // Heading: the tangent of the loop (direction of travel), turned 40° outward.
                let heading = phi + std::f64::consts::FRAC_PI_2 - 40f64.to_radians();
                let yaw = DQuat::from_rotation_y(-heading + std::f64::consts::FRAC_PI_2);
                let pitch = DQuat::from_rotation_x(-(12f64.to_radians() + nod));
                Se3::new(yaw * pitch, position)
            })
            .collect()
    }

    /// Frame `index` of a recording along `path`, rendered with TUM's 5000 units per metre.
    pub fn frame(&self, k: &PinholeIntrinsics, path: &[Se3], index: usize) -> RgbdFrame {
        let (depth, color) = self.render(k, &path[index], 5000.0);
        let t_ns = index as i64 * 33_333_333;
        RgbdFrame {
            index: index as u64,
            depth_timestamp_ns: t_ns,
            color_timestamp_ns: t_ns,
            depth: DepthImage::new(k.width_px, k.height_px, depth).expect("the renderer fills every pixel"),
            color: ColorImage::new(k.width_px, k.height_px, color).expect("the renderer fills every pixel"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 60.0, fy_px: 60.0, cx_px: 39.5, cy_px: 29.5, width_px: 80, height_px: 60 };

    #[test]
    fn rays_meet_the_walls_and_furniture_where_they_are() {
        let room = SyntheticRoom::new(10.0, 3.0, 10.0);
        // Straight down from the camera height at a clear spot: the floor, 1.5 m below.
        let hit = room.cast(DVec3::new(0.0, 0.0, -2.5), DVec3::Y).expect("the floor");
        assert!((hit.t_m - 1.5).abs() < 1e-12, "floor at {} m", hit.t_m);
        // Straight up: the ceiling, 1.5 m above (3 m room).
        let hit = room.cast(DVec3::new(0.0, 0.0, -2.5), -DVec3::Y).expect("the ceiling");
        assert!((hit.t_m - 1.5).abs() < 1e-12, "ceiling at {} m", hit.t_m);
        // The central cabinet (0.35 m half-width) from 2 m along -x at its mid-height.
        let hit = room.cast(DVec3::new(-2.0, 1.0, 0.0), DVec3::X).expect("the cabinet");
        assert!((hit.t_m - 1.65).abs() < 1e-12, "cabinet at {} m", hit.t_m);
        // Negative control: a ray leaving through a clear stretch of wall reaches the wall.
        let hit = room.cast(DVec3::new(0.0, -1.2, -2.5), DVec3::NEG_Z).expect("the wall");
        assert!((hit.t_m - 2.5).abs() < 1e-12 && hit.albedo == [0.82, 0.8, 0.74], "the back wall at {} m", hit.t_m);
    }

    #[test]
    fn the_path_loops_and_every_frame_sees_the_room() {
        let room = SyntheticRoom::new(6.0, 3.0, 6.0);
        let path = room.path(24);
        let step = path[0].inverse() * path[1];
        assert!(step.translation_m.length() < 0.5 && step.rotation_angle_rad() < 0.3, "consecutive poses are close");
        let closing = path[23].inverse() * path[0];
        assert!(closing.translation_m.length() < 0.5, "the loop closes on the first pose");
        for (i, pose) in path.iter().enumerate() {
            let (depth, color) = room.render(&K, pose, 5000.0);
            let valid = depth.iter().filter(|&&d| d > 0).count();
            assert_eq!(valid, K.pixel_count(), "frame {i}: every ray meets the closed room");
            assert_eq!(color.len(), 3 * K.pixel_count());
        }
    }
}
