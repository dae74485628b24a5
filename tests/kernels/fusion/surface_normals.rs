// SPDX-License-Identifier: MIT
//! `surface_normals`: normals of a rendered surface from its neighbours' vertices, GPU against
//! the CPU twin on a real frame's surface (holes and silhouettes included), the exact normal of
//! a tilted plane turned toward the camera, and nothing written for a disabled pose.
//!
//! Tolerances: a difference of neighbours, a cross product and a normalisation in f32, which FMA
//! contraction may round differently: 1e-5 per component.

use glam::{DQuat, DVec3};
use webfusion_core::cpu;
use webfusion_core::fusion::predictor::camera_pose;
use webfusion_core::kernels::surface_normals::{CameraPose, SurfaceNormalsParams};
use webfusion_core::{PinholeIntrinsics, Se3};
use webfusion_tests::{SENTINEL_F32, Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots};

use crate::preprocess::chain::real_cpu_chain;

const TOL: Tolerance = Tolerance { absolute: 1e-5, relative: 0.0 };

fn normals(k: &PinholeIntrinsics, pose: &CameraPose, vertex: &[[f32; 4]]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let p = SurfaceNormalsParams { width_px: k.width_px, height_px: k.height_px, min_cross_norm_sq: 1e-20, ..Default::default() };
    let n = k.pixel_count();
    let out = run_kernel_slots(&gpu, &gpu.kernels.surface_normals, &p, &[Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(vertex)), Slot::Out(16 * n)], [k.width_px, k.height_px, 1]);
    finish(&gpu);
    let mut c = vec![[SENTINEL_F32; 4]; n];
    cpu::surface_normals(&p, pose, vertex, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn a_real_surface_matches_the_twin() {
    let chain = real_cpu_chain();
    let l = &chain.levels[0];
    // The frame's own surface, placed in a world the camera is posed in.
    let world_from_camera = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.1).normalize(), 0.4), DVec3::new(0.5, -0.2, 1.0));
    let m = world_from_camera.to_cols_f32();
    let vertex: Vec<[f32; 4]> = l.vertex_in_camera.iter().map(|v| if v[0].is_nan() { *v } else { let p = cpu::shared::transform_point(&m, [v[0], v[1], v[2]]); [p[0], p[1], p[2], 1.0] }).collect();
    let (g, c) = normals(&l.intrinsics, &camera_pose(Some(&world_from_camera)), &vertex);
    let cmp = compare_vec4("normal_in_world", &g, &c, TOL).unwrap();
    assert!(cmp.invalid > 0 && cmp.invalid < cmp.compared * 9 / 10, "holes and surface ({} invalid of {})", cmp.invalid / 4, cmp.compared / 4);
    assert_negative_control_vec4("normal_in_world", &g, &c, TOL);
    // Every normal faces the camera.
    let centre = world_from_camera.translation_m;
    for (n, v) in g.iter().zip(&vertex).filter(|(n, _)| !n[0].is_nan()) {
        let to_point = DVec3::new(f64::from(v[0]), f64::from(v[1]), f64::from(v[2])) - centre;
        assert!(to_point.dot(DVec3::new(f64::from(n[0]), f64::from(n[1]), f64::from(n[2]))) <= 0.0, "normal {n:?} faces away from the camera");
    }
}

#[test]
fn a_tilted_plane_has_its_normal_and_a_disabled_pose_writes_nothing() {
    let k = crate::synthetic::K_SMALL;
    let normal_cam = [0.2f32, -0.3, -0.932_737_9];
    let depth = crate::synthetic::plane_depth_m(&k, 1.5, normal_cam);
    let vertex: Vec<[f32; 4]> = (0..k.pixel_count())
        .map(|i| {
            let (x, y) = ((i as u32 % k.width_px) as f32, (i as u32 / k.width_px) as f32);
            let z = depth[i];
            [(x - k.cx_px) * z / k.fx_px, (y - k.cy_px) * z / k.fy_px, z, 1.0]
        })
        .collect();
    let (g, _) = normals(&k, &camera_pose(Some(&Se3::IDENTITY)), &vertex);
    let len = normal_cam.iter().map(|v| v * v).sum::<f32>().sqrt();
    for (i, n) in g.iter().enumerate() {
        let (x, y) = (i as u32 % k.width_px, i as u32 / k.width_px);
        if x == 0 || y == 0 || x + 1 == k.width_px || y + 1 == k.height_px {
            assert!(n[0].is_nan(), "no normal on the border");
            continue;
        }
        // The plane's normal, turned toward the camera (its z is negative).
        for a in 0..3 {
            assert!((n[a] - normal_cam[a] / len).abs() < 1e-4, "pixel ({x}, {y}): {n:?}");
        }
    }
    let (g, c) = normals(&k, &CameraPose::default(), &vertex);
    assert!(g.iter().flatten().all(|v| v.to_bits() == SENTINEL_F32.to_bits()), "nothing written for a disabled pose");
    assert!(c.iter().flatten().all(|v| v.to_bits() == SENTINEL_F32.to_bits()), "nor by the twin");
}
