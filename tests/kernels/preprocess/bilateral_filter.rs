// SPDX-License-Identifier: MIT
//! `bilateral_filter`: GPU `exp` may differ from Rust's by a few ulp; the weighted mean of
//! depths near 1-5 m then differs by well under a micrometre.

use webfusion_core::cpu;
use webfusion_core::kernels::bilateral_filter::{self, BilateralFilterParams};
use webfusion_tests::{Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel, sample_frame};

use crate::synthetic::{K_SMALL, UNITS_PER_M, step_scene};

/// 2 µm absolute plus 1e-6 relative (metres).
const TOL: Tolerance = Tolerance { absolute: 2e-6, relative: 1e-6 };

fn run(params: &BilateralFilterParams, depth_m: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let n = depth_m.len();
    let out = run_kernel(&gpu, &gpu.kernels.bilateral_filter, params, &[bytemuck::cast_slice(depth_m)], &[4 * n], bilateral_filter::invocations(params.width_px, params.height_px));
    let mut cpu_out = vec![0.0; n];
    cpu::bilateral_filter(params, depth_m, &mut cpu_out);
    finish(&gpu);
    (cast(&out[0]), cpu_out)
}

fn params(w: u32, h: u32) -> BilateralFilterParams {
    BilateralFilterParams { width_px: w, height_px: h, radius_px: 3, sigma_space_px: 3.0, sigma_range_m: 0.03, ..Default::default() }
}

#[test]
fn synthetic_step_is_preserved_and_matches_cpu() {
    let k = K_SMALL;
    let depth_m: Vec<f32> = step_scene(&k).iter().map(|&u| if u == 0 || u > 25000 { f32::NAN } else { u as f32 / UNITS_PER_M }).collect();
    let p = params(k.width_px, k.height_px);
    let (g, c) = run(&p, &depth_m);
    compare_f32("depth_out_m", &g, &c, TOL).unwrap();
    // Exact answer: the scene is piecewise constant and the 0.8 m step is 27 range sigmas, so
    // every pixel keeps its own side's depth.
    for (i, (&out, &inp)) in g.iter().zip(&depth_m).enumerate() {
        if inp.is_nan() {
            assert!(out.is_nan(), "hole at {i} must stay invalid");
        } else {
            assert!((out - inp).abs() < 1e-6, "pixel {i}: {inp} m filtered to {out} m across the step");
        }
    }
    assert_negative_control("depth_out_m", &g, &c, TOL);
}

#[test]
fn synthetic_noise_is_reduced() {
    let k = K_SMALL;
    // A 1.5 m wall with deterministic +-5 mm noise: the filter must bring it closer to 1.5 m.
    let depth_m: Vec<f32> = (0..k.pixel_count()).map(|i| 1.5 + 0.005 * (((i * 7919) % 11) as f32 / 5.0 - 1.0)).collect();
    let p = params(k.width_px, k.height_px);
    let (g, c) = run(&p, &depth_m);
    compare_f32("depth_out_m", &g, &c, TOL).unwrap();
    let rms = |v: &[f32]| (v.iter().map(|d| (d - 1.5).powi(2)).sum::<f32>() / v.len() as f32).sqrt();
    assert!(rms(&g) < 0.5 * rms(&depth_m), "noise rms {} -> {}", rms(&depth_m), rms(&g));
}

#[test]
fn real_frame_matches_cpu() {
    let (calib, frame) = sample_frame(0);
    let k = calib.intrinsics;
    let depth_m: Vec<f32> = frame.depth.units.iter().map(|&u| if u == 0 { f32::NAN } else { u as f32 * calib.metres_per_depth_unit() }).collect();
    let (g, c) = run(&params(k.width_px, k.height_px), &depth_m);
    let cmp = compare_f32("depth_out_m", &g, &c, TOL).unwrap();
    eprintln!("bilateral real frame: {cmp:?}");
    assert_negative_control("depth_out_m", &g, &c, TOL);
}

#[test]
fn width_not_a_multiple_of_the_invocation_matches_cpu() {
    // Each invocation filters PIXELS_PER_INVOCATION pixels: a width of 4k + 1 leaves the last
    // invocation of each row one pixel, and the window still ends at the image's right edge.
    let (calib, frame) = sample_frame(0);
    let k = calib.intrinsics;
    let (w, h) = (4 * 19 + 1, 41);
    assert_ne!(w % bilateral_filter::PIXELS_PER_INVOCATION, 0);
    let depth_m: Vec<f32> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x + 300, y + 200)))
        .map(|(x, y)| frame.depth.units[(y * k.width_px + x) as usize])
        .enumerate()
        // Holes at every 17th pixel, so some windows skip neighbours and some centres are invalid.
        .map(|(i, u)| if u == 0 || i % 17 == 0 { f32::NAN } else { u as f32 * calib.metres_per_depth_unit() })
        .collect();
    assert!(depth_m.iter().any(|d| d.is_nan()) && depth_m.iter().any(|d| !d.is_nan()), "the crop must hold holes and depth");
    let (g, c) = run(&params(w, h), &depth_m);
    compare_f32("depth_out_m", &g, &c, TOL).unwrap();
    assert_negative_control("depth_out_m", &g, &c, TOL);
}
