// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/view/plane_overlay.wgsl`.

use crate::cpu::shared::{back_project, dot3, is_valid_f32, transform_vector};
use crate::kernels::gpu_data::{CameraPose, OverlayPlane, PlaneOverlayParams};

/// Draws the planes over every pixel of `rgba8` (rows `row_stride_px` apart; pixels no covered
/// texel falls on, and padding, left as they are), as the kernel's invocations do.
pub fn plane_overlay(params: &PlaneOverlayParams, pose: &CameraPose, planes: &[OverlayPlane], texels: &[u32], depth_m: &[f32], rgba8: &mut [u32]) {
    let k = &params.intrinsics;
    if pose.enabled == 0 {
        return;
    }
    let m = &pose.world_from_camera;
    let origin = [m[3][0], m[3][1], m[3][2]];
    for gy in 0..k.height_px {
        for gx in 0..k.width_px {
            let ray_cam = back_project(k, gx as f32, gy as f32, 1.0);
            let dir = transform_vector(m, ray_cam);
            let mut best_z = params.far_m;
            let mut best = params.plane_count;
            let mut colour = 0u32;
            for i in 0..params.plane_count {
                let pl = &planes[i as usize];
                let n = [pl.plane[0], pl.plane[1], pl.plane[2]];
                let facing = dot3(n, dir);
                if !(facing < 0.0) {
                    continue;
                }
                let z = -(dot3(n, origin) + pl.plane[3]) / facing;
                if !(z >= params.near_m && z < best_z) {
                    continue;
                }
                let p: [f32; 3] = std::array::from_fn(|a| origin[a] + dir[a] * z);
                let tx = (dot3([pl.to_texel_x[0], pl.to_texel_x[1], pl.to_texel_x[2]], p) + pl.to_texel_x[3]).floor();
                let ty = (dot3([pl.to_texel_y[0], pl.to_texel_y[1], pl.to_texel_y[2]], p) + pl.to_texel_y[3]).floor();
                if !(tx >= 0.0 && ty >= 0.0 && tx < pl.width as f32 && ty < pl.height as f32) {
                    continue;
                }
                let word = texels[(pl.first_texel + ty as u32 * pl.width + tx as u32) as usize];
                if word >> 24 == 0 {
                    continue;
                }
                best_z = z;
                best = i;
                colour = word;
            }
            if best == params.plane_count {
                continue;
            }
            let surface_z = depth_m[(gy * k.width_px + gx) as usize];
            if is_valid_f32(surface_z) {
                let s: [f32; 3] = std::array::from_fn(|a| origin[a] + dir[a] * surface_z);
                let pl = &planes[best as usize];
                if dot3([pl.plane[0], pl.plane[1], pl.plane[2]], s) + pl.plane[3] > params.occlusion_m {
                    continue;
                }
            }
            rgba8[(gy * params.row_stride_px + gx) as usize] = colour;
        }
    }
}
