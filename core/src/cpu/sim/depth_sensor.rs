// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/sim/depth_sensor.wgsl`, statement by statement.

use crate::cpu::shared::{dot3, invalid_f32, is_valid_f32, kinect_lateral_sigma_px, kinect_sigma_at_angle_m, pcg_hash, random_gauss2};
use crate::kernels::gpu_data::CameraPose;
use crate::kernels::depth_sensor::DepthSensorParams;

/// The raycast a virtual sensor reads: per pixel, depth along z (NaN: none), world-frame
/// vertex and unit normal (NaN: none).
#[derive(Clone, Copy, Debug)]
pub struct SensorInput<'a> {
    /// Depth along the camera's z, metres.
    pub depth_m: &'a [f32],
    /// Surface points, world frame.
    pub vertex_in_world: &'a [[f32; 4]],
    /// Unit normals, world frame.
    pub normal_in_world: &'a [[f32; 4]],
    /// Per pixel, 1 where the projector's light is blocked (`projector_shadow`).
    pub shadow: &'a [u32],
}

struct Sensor<'a> {
    p: &'a DepthSensorParams,
    pose: &'a CameraPose,
    input: SensorInput<'a>,
}

impl Sensor<'_> {
    fn model_depth(&self, x: i32, y: i32) -> f32 {
        let k = &self.p.intrinsics;
        if x < 0 || y < 0 || x >= k.width_px as i32 || y >= k.height_px as i32 {
            return invalid_f32();
        }
        self.input.depth_m[y as usize * k.width_px as usize + x as usize]
    }

    fn incidence_rad(&self, ix: usize) -> f32 {
        let n = self.input.normal_in_world[ix];
        if !is_valid_f32(n[0]) {
            return 0.0;
        }
        let v = self.input.vertex_in_world[ix];
        let c = self.pose.world_from_camera[3];
        let d = [v[0] - c[0], v[1] - c[1], v[2] - c[2]];
        let len = dot3(d, d).sqrt();
        let ray = [d[0] / len, d[1] / len, d[2] / len];
        dot3(ray, [n[0], n[1], n[2]]).abs().clamp(0.0, 1.0).acos()
    }

    fn disparity_px(&self, z_m: f32) -> f32 {
        self.p.baseline_m.abs() * self.p.disparity_focal_px / z_m
    }

    fn at_depth_edge(&self, x: i32, y: i32, z_m: f32) -> bool {
        let d = self.disparity_px(z_m);
        [(-1, 0), (1, 0), (0, -1), (0, 1)].iter().any(|&(dx, dy)| {
            let zn = self.model_depth(x + dx, y + dy);
            is_valid_f32(zn) && (self.disparity_px(zn) - d).abs() > self.p.edge_disparity_px
        })
    }

    fn to_units(&self, x: i32, y: i32, z_m: f32) -> u32 {
        if !(z_m >= self.p.min_depth_m && z_m <= self.p.max_depth_m) {
            return 0;
        }
        let mut d = z_m;
        if self.p.radial != 0 {
            let k = &self.p.intrinsics;
            let rx = (x as f32 - k.cx_px) / k.fx_px;
            let ry = (y as f32 - k.cy_px) / k.fy_px;
            d = z_m * (rx * rx + ry * ry + 1.0).sqrt();
        }
        let units = (d * self.p.units_per_metre + 0.5).floor();
        if units > 65535.0 {
            return 0;
        }
        units as u32
    }

    fn sense(&self, ix: u32) -> u32 {
        let k = &self.p.intrinsics;
        let x = (ix % k.width_px) as i32;
        let y = (ix / k.width_px) as i32;
        let z0 = self.input.depth_m[ix as usize];
        if !is_valid_f32(z0) {
            return 0;
        }
        if self.p.noise == 0 {
            return self.to_units(x, y, z0);
        }
        let mut state = pcg_hash(ix.wrapping_add(pcg_hash(self.p.frame_index.wrapping_add(pcg_hash(self.p.seed)))));
        let theta0 = self.incidence_rad(ix as usize);
        if theta0 > self.p.max_incidence_rad {
            return 0;
        }
        let g = random_gauss2(&mut state);
        let sigma_l = kinect_lateral_sigma_px(theta0);
        let sx = (x as f32 + g[0] * sigma_l + 0.5).floor() as i32;
        let sy = (y as f32 + g[1] * sigma_l + 0.5).floor() as i32;
        let zs = self.model_depth(sx, sy);
        if !is_valid_f32(zs) {
            return 0;
        }
        let s = sy as usize * k.width_px as usize + sx as usize;
        let theta = self.incidence_rad(s);
        if theta > self.p.max_incidence_rad || self.at_depth_edge(sx, sy, zs) || self.input.shadow[s] != 0 {
            return 0;
        }
        let z_noisy = zs + random_gauss2(&mut state)[0] * kinect_sigma_at_angle_m(zs, theta);
        let bf = self.p.baseline_m.abs() * self.p.disparity_focal_px;
        let disparity = (bf / z_noisy * self.p.disparity_subpixel + 0.5).floor() / self.p.disparity_subpixel;
        if !(z_noisy > 0.0) || !(disparity > 0.0) {
            return 0;
        }
        self.to_units(x, y, bf / disparity)
    }
}

/// The sensor's raw depth of every pixel (one u16 each; the kernel packs two per word).
pub fn depth_sensor(params: &DepthSensorParams, pose: &CameraPose, input: SensorInput<'_>) -> Vec<u16> {
    let sensor = Sensor { p: params, pose, input };
    let n = params.intrinsics.width_px * params.intrinsics.height_px;
    (0..n).map(|ix| sensor.sense(ix) as u16).collect()
}
