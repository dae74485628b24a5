// SPDX-License-Identifier: MIT
//! `prediction_down`: the coarser predicted surface is the mean of each 2x2 block's vertices and
//! the normalised sum of its normals, invalid unless all four are valid; GPU against the CPU
//! twin on a real frame's surface (holes included), and exact answers on a plane.
//!
//! Tolerances: the four-term sums may be contracted into FMAs: 1e-6 m on vertices, 1e-6 on
//! normal components.

use webfusion_core::cpu;
use webfusion_core::kernels::prediction_down::PredictionDownParams;
use webfusion_tests::{SENTINEL_F32, Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots};

use crate::preprocess::chain::real_cpu_chain;

const TOL: Tolerance = Tolerance { absolute: 1e-6, relative: 1e-6 };

fn down(p: &PredictionDownParams, vertex: &[[f32; 4]], normal: &[[f32; 4]]) -> ((Vec<[f32; 4]>, Vec<[f32; 4]>), (Vec<[f32; 4]>, Vec<[f32; 4]>)) {
    let gpu = gpu();
    let n = (p.dst_width_px * p.dst_height_px) as usize;
    let out = run_kernel_slots(&gpu, &gpu.kernels.prediction_down, p, &[Slot::In(bytemuck::cast_slice(vertex)), Slot::In(bytemuck::cast_slice(normal)), Slot::Out(16 * n), Slot::Out(16 * n)], [p.dst_width_px, p.dst_height_px, 1]);
    finish(&gpu);
    let (mut cv, mut cn) = (vec![[SENTINEL_F32; 4]; n], vec![[SENTINEL_F32; 4]; n]);
    cpu::prediction_down(p, vertex, normal, &mut cv, &mut cn);
    ((cast(&out[0]), cast(&out[1])), (cv, cn))
}

#[test]
fn a_real_surface_downsamples_as_the_twin_does() {
    let chain = real_cpu_chain();
    let l = &chain.levels[0];
    let k = l.intrinsics;
    let p = PredictionDownParams { src_width_px: k.width_px, src_height_px: k.height_px, dst_width_px: k.width_px / 2, dst_height_px: k.height_px / 2 };
    let ((gv, gn), (cv, cn)) = down(&p, &l.vertex_in_camera, &l.normal_in_camera);
    let cmp = compare_vec4("vertex", &gv, &cv, TOL).unwrap();
    compare_vec4("normal", &gn, &cn, TOL).unwrap();
    assert!(cmp.invalid > 0 && cmp.invalid < cmp.compared, "holes and surface both present ({} of {})", cmp.invalid, cmp.compared);
    assert_negative_control_vec4("vertex", &gv, &cv, TOL);
    assert_negative_control_vec4("normal", &gn, &cn, TOL);
}

#[test]
fn a_plane_keeps_its_points_and_normal_and_a_hole_stays_a_hole() {
    let (w, h) = (8u32, 6u32);
    let vertex: Vec<[f32; 4]> = (0..w * h).map(|i| [(i % w) as f32 * 0.01, (i / w) as f32 * 0.01, 2.0, 1.0]).collect();
    let mut normal = vec![[0.0f32, 0.0, -1.0, 0.0]; (w * h) as usize];
    normal[(2 * w + 5) as usize] = [f32::NAN; 4];
    let p = PredictionDownParams { src_width_px: w, src_height_px: h, dst_width_px: w / 2, dst_height_px: h / 2 };
    let ((gv, gn), _) = down(&p, &vertex, &normal);
    assert_eq!(gv[0], [0.005, 0.005, 2.0, 1.0], "block mean");
    assert_eq!(gn[0], [0.0, 0.0, -1.0, 0.0], "normal kept");
    let hole = (w / 2 + 2) as usize;
    assert!(gv[hole][0].is_nan() && gn[hole][0].is_nan(), "a block with one invalid normal is invalid");
}
