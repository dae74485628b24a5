// SPDX-License-Identifier: MIT
//! `depth_to_metres`: exact (a single f32 multiply, correctly rounded on both sides).

use webfusion_core::cpu;
use webfusion_core::cpu::shared::pack_u16_pairs;
use webfusion_core::kernels::depth_to_metres::DepthToMetresParams;
use webfusion_tests::{Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel, sample_frame};

use crate::synthetic::{K_SMALL, UNITS_PER_M, step_scene};

/// Raw units -> metres is one multiply: GPU and CPU must agree bit for bit.
const TOL: Tolerance = Tolerance::EXACT;

fn run(width_px: u32, height_px: u32, units: &[u16], metres_per_unit: f32) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let params = DepthToMetresParams { width_px, height_px, metres_per_unit, min_depth_m: 0.3, max_depth_m: 5.0, ..Default::default() };
    let packed = pack_u16_pairs(units);
    let n = units.len();
    let out = run_kernel(&gpu, &gpu.kernels.depth_to_metres, &params, &[bytemuck::cast_slice(&packed)], &[4 * n], [width_px, height_px, 1]);
    let mut cpu_out = vec![0.0; n];
    cpu::depth_to_metres(&params, &packed, &mut cpu_out);
    finish(&gpu);
    (cast(&out[0]), cpu_out)
}

#[test]
fn synthetic_matches_cpu_and_exact_answer() {
    let units = step_scene(&K_SMALL);
    let (g, c) = run(K_SMALL.width_px, K_SMALL.height_px, &units, 1.0 / UNITS_PER_M);
    let cmp = compare_f32("depth_m", &g, &c, TOL).unwrap();
    assert!(cmp.invalid > 0 && cmp.invalid < cmp.compared, "scene has both holes and valid depth: {cmp:?}");
    for (i, &u) in units.iter().enumerate() {
        let expected = u as f32 * (1.0 / UNITS_PER_M);
        if u == 0 || !(0.3..=5.0).contains(&expected) {
            assert!(g[i].is_nan(), "pixel {i} (raw {u}) must be invalid");
        } else {
            assert_eq!(g[i], expected, "pixel {i} (raw {u})");
        }
    }
    assert_negative_control("depth_m", &g, &c, TOL);
}

#[test]
fn every_u16_value_and_odd_width() {
    // 257 x 255 = 65535 pixels holding every raw value but 65535; odd width exercises the
    // u16 packing across word boundaries.
    let units: Vec<u16> = (0..257 * 255).map(|i| i as u16).collect();
    let (g, c) = run(257, 255, &units, 0.001);
    compare_f32("depth_m", &g, &c, TOL).unwrap();
    assert!(g[1].is_nan(), "1 mm is below the 0.3 m minimum");
    assert_eq!(g[1000], 1.0, "raw 1000 at 1 mm per unit");
}

#[test]
fn real_frame_matches_cpu() {
    let (calib, frame) = sample_frame(0);
    let k = calib.intrinsics;
    let (g, c) = run(k.width_px, k.height_px, &frame.depth.units, calib.metres_per_depth_unit());
    let cmp = compare_f32("depth_m", &g, &c, TOL).unwrap();
    assert!(cmp.compared - cmp.invalid > 200_000, "a real Kinect frame has mostly valid depth: {cmp:?}");
    assert_negative_control("depth_m", &g, &c, TOL);
}
