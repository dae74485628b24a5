// SPDX-License-Identifier: MIT
//! `depth_pyramid_down`: a mean of at most four values, same order on both sides.

use webfusion_core::cpu;
use webfusion_core::kernels::depth_pyramid_down::DepthPyramidDownParams;
use webfusion_tests::{Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel, sample_frame};

/// Sums of <= 4 values divided by the count; division may be 1 ulp apart on the GPU.
const TOL: Tolerance = Tolerance { absolute: 0.0, relative: 3e-7 };

fn run(src_w: u32, src_h: u32, depth_m: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let p = DepthPyramidDownParams {
        src_width_px: src_w,
        src_height_px: src_h,
        dst_width_px: src_w / 2,
        dst_height_px: src_h / 2,
        max_depth_diff_m: 0.09,
        ..Default::default()
    };
    let n = (p.dst_width_px * p.dst_height_px) as usize;
    let out = run_kernel(&gpu, &gpu.kernels.depth_pyramid_down, &p, &[bytemuck::cast_slice(depth_m)], &[4 * n], [p.dst_width_px, p.dst_height_px, 1]);
    let mut cpu_out = vec![0.0; n];
    cpu::depth_pyramid_down(&p, depth_m, &mut cpu_out);
    finish(&gpu);
    (cast(&out[0]), cpu_out)
}

#[test]
fn synthetic_blocks_have_exact_answers() {
    let nan = f32::NAN;
    // Four 2x2 blocks side by side in a 8x2 image (row 0 then row 1 of each block).
    // Block 0: 1.0 1.0 / 1.0 3.0 -> the 3.0 sample is 2 m behind: mean of the three 1.0.
    // Block 1: nan 2.0 / 2.04 nan -> (2.0 + 2.04) / 2.
    // Block 2: all invalid -> invalid.  Block 3: 0.5 0.5 / 0.5 0.5 -> 0.5.
    let depth_m = [1.0, 1.0, nan, 2.0, nan, nan, 0.5, 0.5, 1.0, 3.0, 2.04, nan, nan, nan, 0.5, 0.5];
    let (g, c) = run(8, 2, &depth_m);
    compare_f32("depth_coarse_m", &g, &c, TOL).unwrap();
    assert_eq!(g[0], 1.0, "far sample excluded");
    assert!((g[1] - 2.02).abs() < 1e-6, "mean of the two valid samples: {}", g[1]);
    assert!(g[2].is_nan(), "all-invalid block is invalid");
    assert_eq!(g[3], 0.5, "constant block");
    assert_negative_control("depth_coarse_m", &g, &c, TOL);
}

#[test]
fn real_frame_matches_cpu() {
    let (calib, frame) = sample_frame(0);
    let k = calib.intrinsics;
    let depth_m: Vec<f32> = frame.depth.units.iter().map(|&u| if u == 0 { f32::NAN } else { u as f32 * calib.metres_per_depth_unit() }).collect();
    let (g, c) = run(k.width_px, k.height_px, &depth_m);
    compare_f32("depth_coarse_m", &g, &c, TOL).unwrap();
    assert_negative_control("depth_coarse_m", &g, &c, TOL);
}
