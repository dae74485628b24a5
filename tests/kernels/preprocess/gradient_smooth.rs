// SPDX-License-Identifier: MIT
//! `gradient_smooth`: weighted means with GPU `exp` weights; a few ulp of the gradient.

use webfusion_core::cpu;
use webfusion_core::kernels::gradient_smooth::GradientSmoothParams;
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;

/// Gradients are metres between neighbours (~1e-3..1e-1): 1e-8 m plus 2e-6 relative.
const TOL: Tolerance = Tolerance { absolute: 1e-8, relative: 2e-6 };

type Pair = (Vec<[f32; 4]>, Vec<[f32; 4]>);

fn run(p: &GradientSmoothParams, gx: &[[f32; 4]], gy: &[[f32; 4]]) -> (Pair, Pair) {
    let gpu = gpu();
    let n = gx.len();
    let out = run_kernel(&gpu, &gpu.kernels.gradient_smooth, p, &[bytemuck::cast_slice(gx), bytemuck::cast_slice(gy)], &[16 * n, 16 * n], [p.width_px, p.height_px, 1]);
    let (mut ox, mut oy) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
    cpu::gradient_smooth(p, gx, gy, &mut ox, &mut oy);
    finish(&gpu);
    ((cast(&out[0]), cast(&out[1])), (ox, oy))
}

#[test]
fn constant_gradients_stay_constant_and_holes_are_skipped() {
    let (w, h) = (16u32, 9u32);
    let mut gx = vec![[0.25f32, 0.0, -0.5, 0.0]; (w * h) as usize];
    let gy = vec![[0.0f32, 0.125, 0.75, 0.0]; (w * h) as usize];
    gx[20] = [f32::NAN; 4];
    for axis in 0..2 {
        let p = GradientSmoothParams { width_px: w, height_px: h, radius_px: 2, axis, sigma_px: 1.5, ..Default::default() };
        let ((ox, oy), (cx, cy)) = run(&p, &gx, &gy);
        compare_vec4("grad_x_out", &ox, &cx, TOL).unwrap();
        compare_vec4("grad_y_out", &oy, &cy, TOL).unwrap();
        assert!(ox[20][0].is_nan(), "invalid centre stays invalid");
        for (i, v) in ox.iter().enumerate().filter(|(i, _)| *i != 20) {
            assert!((v[0] - 0.25).abs() < 1e-6 && (v[2] + 0.5).abs() < 1e-6, "axis {axis} pixel {i}: {v:?}");
        }
        assert_negative_control_vec4("grad_x_out", &ox, &cx, TOL);
    }
}

#[test]
fn real_frame_matches_cpu_both_axes() {
    let chain = real_cpu_chain();
    let level = &chain.levels[0];
    let k = level.intrinsics;
    let ((raw_x, raw_y), _) = crate::preprocess::vertex_gradients::run(k.width_px, k.height_px, &level.vertex_in_camera);
    for axis in 0..2 {
        let p = GradientSmoothParams { width_px: k.width_px, height_px: k.height_px, radius_px: 2, axis, sigma_px: 1.5, ..Default::default() };
        let ((ox, oy), (cx, cy)) = run(&p, &raw_x, &raw_y);
        compare_vec4("grad_x_out", &ox, &cx, TOL).unwrap();
        compare_vec4("grad_y_out", &oy, &cy, TOL).unwrap();
        assert_negative_control_vec4("grad_y_out", &oy, &cy, TOL);
    }
}
