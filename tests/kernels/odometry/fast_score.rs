// SPDX-License-Identifier: MIT
//! `fast_score`: FAST-9 scores against the CPU twin, exactly (differences, min and max are
//! exact in f32), on a synthetic image with known corners and on the levels of a real frame.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::fast_score::FastScoreParams;
use webfusion_core::odometry::FeatureConfig;
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Slot, Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel_slots, sample_frame};

fn run(p: &FastScoreParams, intensity: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let out = run_kernel_slots(&gpu, &gpu.kernels.fast_score, p, &[Slot::In(bytemuck::cast_slice(intensity)), Slot::Out(4 * intensity.len())], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![0.0; intensity.len()];
    cpu::fast_score(p, intensity, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn a_bright_dot_and_a_square_score_as_fast_defines() {
    // A 64x48 image at 0.2 with a one-pixel dot of 1.0 at (20, 20) and a 10x10 square of 0.8
    // from (40, 20).
    let (w, h) = (64u32, 48u32);
    let mut image = vec![0.2f32; (w * h) as usize];
    image[(20 * w + 20) as usize] = 1.0;
    for y in 20..30 {
        for x in 40..50 {
            image[(y * w + x) as usize] = 0.8;
        }
    }
    let p = FastScoreParams { width_px: w, height_px: h, border_px: 4, threshold: 0.05 };
    let (g, c) = run(&p, &image);
    compare_f32("dot and square", &g, &c, Tolerance::EXACT).unwrap();
    assert_negative_control("dot and square", &g, &c, Tolerance::EXACT);
    // The dot: every circle pixel is 0.8 darker.
    assert!((g[(20 * w + 20) as usize] - 0.8).abs() < 1e-6, "dot {}", g[(20 * w + 20) as usize]);
    // The square's corner pixel: 11 of 16 circle pixels outside (0.6 darker): a corner. An
    // edge's middle has only 7 outside: none. Flat areas score 0.
    assert!(g[(20 * w + 40) as usize] > 0.5);
    assert_eq!(g[(25 * w + 40) as usize], 0.0);
    assert_eq!(g[(10 * w + 10) as usize], 0.0);
    // Border pixels score 0 even on a corner.
    assert_eq!(g[(2 * w + 2) as usize], 0.0);
}

#[test]
fn the_levels_of_a_real_frame_score_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let config = FeatureConfig::default();
    for level in config.layout(&calibration.intrinsics) {
        let (g, c) = run(&level.fast_params(&config), &pre.levels[level.level as usize].intensity);
        let what = format!("level {}", level.level);
        compare_f32(&what, &g, &c, Tolerance::EXACT).unwrap();
        let corners = c.iter().filter(|&&s| s > 0.0).count();
        eprintln!("{what}: {corners} corners");
        assert!(corners > 100, "{what}: a real frame has corners ({corners})");
        assert_negative_control(&what, &g, &c, Tolerance::EXACT);
    }
}
