// SPDX-License-Identifier: MIT
//! `corner_candidates`: comparisons and the Kinect noise model's step on exact inputs, so the
//! candidate image must equal the CPU twin's exactly. On a synthetic image with known maxima,
//! a depth hole and a depth step, and on every level of a real frame.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::corner_candidates::CornerCandidatesParams;
use webfusion_core::odometry::FeatureConfig;
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel, sample_frame};

fn run(p: &CornerCandidatesParams, score: &[f32], depth_m: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let out = run_kernel(&gpu, &gpu.kernels.corner_candidates, p, &[bytemuck::cast_slice(score), bytemuck::cast_slice(depth_m)], &[4 * score.len()], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![0.0; score.len()];
    cpu::corner_candidates(p, score, depth_m, &mut c);
    (cast(&out[0]), c)
}

#[test]
fn local_maxima_on_clean_depth_are_the_candidates() {
    // 32x16 scores, depth 2 m everywhere but a hole and a step.
    let (w, h) = (32u32, 16u32);
    let mut score = vec![0.0f32; (w * h) as usize];
    let mut set = |x: u32, y: u32, s: f32| score[(y * w + x) as usize] = s;
    set(3, 3, 0.5); // a maximum
    set(4, 3, 0.4); // its weaker neighbour: suppressed
    set(8, 8, 0.7);
    set(9, 9, 0.7); // an equal neighbour after it: suppressed (the tie goes to the smaller index)
    set(20, 5, 0.6); // on a depth hole (3 missing): dropped
    set(24, 10, 0.9); // next to a depth step: dropped
    set(27, 4, 0.2);
    let mut depth = vec![2.0f32; (w * h) as usize];
    for (x, y) in [(19, 5), (20, 4), (21, 6)] {
        depth[(y * w + x) as usize] = f32::NAN;
    }
    depth[(11 * w + 25) as usize] = 2.5;
    let p = CornerCandidatesParams { width_px: w, height_px: h, level: 0, depth_width_px: w, depth_height_px: h, fx_px: 100.0, ..Default::default() };
    let (g, c) = run(&p, &score, &depth);
    compare_f32("candidate", &g, &c, Tolerance::EXACT).unwrap();
    let kept: Vec<(u32, u32, f32)> = g.iter().enumerate().filter(|(_, s)| **s > 0.0).map(|(i, s)| (i as u32 % w, i as u32 / w, *s)).collect();
    assert_eq!(kept, vec![(3, 3, 0.5), (27, 4, 0.2), (8, 8, 0.7)]);
    assert_negative_control("candidate", &g, &c, Tolerance::EXACT);
}

#[test]
fn a_real_frame_marks_like_the_twin_at_every_level() {
    let (calibration, frame) = sample_frame(0);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let config = FeatureConfig::default();
    let k0 = calibration.intrinsics;
    for level in &config.layout(&k0) {
        let image = &pre.levels[level.level as usize].intensity;
        let mut score = vec![0.0; image.len()];
        cpu::fast_score(&level.fast_params(&config), image, &mut score);
        let (g, c) = run(&level.candidates_params(&k0), &score, &pre.depth_unfiltered_m);
        let what = format!("level {}", level.level);
        compare_f32(&what, &g, &c, Tolerance::EXACT).unwrap();
        let (corners, candidates) = (score.iter().filter(|s| **s > 0.0).count(), g.iter().filter(|s| **s > 0.0).count());
        eprintln!("{what}: {candidates} candidates of {corners} corners");
        assert!(candidates > 100 && candidates < corners, "{what}: {candidates} candidates of {corners} corners");
        assert_negative_control(&what, &g, &c, Tolerance::EXACT);
    }
}
