// SPDX-License-Identifier: MIT
//! `feature_smooth`: the binomial smoothing along each axis against the CPU twin (1e-6 relative:
//! the sums may be reassociated), on an impulse (whose two passes give the 5x5 kernel itself)
//! and a real frame.

use webfusion_core::cpu;
use webfusion_core::kernels::feature_smooth::{self, FeatureSmoothParams};
use webfusion_tests::{Slot, Tolerance, assert_negative_control, cast, compare_f32, finish, gpu, run_kernel_slots, sample_frame};

const TOL: Tolerance = Tolerance { absolute: 1e-7, relative: 1e-6 };

fn run(p: &FeatureSmoothParams, intensity: &[f32]) -> (Vec<f32>, Vec<f32>) {
    let gpu = gpu();
    let out = run_kernel_slots(&gpu, &gpu.kernels.feature_smooth, p, &[Slot::In(bytemuck::cast_slice(intensity)), Slot::Out(4 * intensity.len())], feature_smooth::invocations(p.width_px, p.height_px, p.axis));
    finish(&gpu);
    let mut c = vec![0.0; intensity.len()];
    cpu::feature_smooth(p, intensity, &mut c);
    (cast(&out[0]), c)
}

/// The x pass on the GPU, then the y pass on the GPU's x output, each against the twin on the
/// same input; returns the GPU's final image.
fn both_passes(what: &str, w: u32, h: u32, image: &[f32]) -> Vec<f32> {
    let mut input = image.to_vec();
    for axis in [0, 1] {
        let (g, c) = run(&FeatureSmoothParams { width_px: w, height_px: h, axis, ..Default::default() }, &input);
        let what = format!("{what}, axis {axis}");
        compare_f32(&what, &g, &c, TOL).unwrap();
        assert_negative_control(&what, &g, &c, TOL);
        input = g;
    }
    let c = cpu::odometry::feature_smooth::smooth_image(w, h, image);
    compare_f32(&format!("{what}, both passes"), &input, &c, TOL).unwrap();
    input
}

#[test]
fn an_impulse_spreads_into_the_binomial_kernel() {
    let (w, h) = (16u32, 12u32);
    let mut image = vec![0.0f32; (w * h) as usize];
    image[(6 * w + 8) as usize] = 256.0;
    let g = both_passes("impulse", w, h, &image);
    let b = [1.0, 4.0, 6.0, 4.0, 1.0];
    for dy in -2i32..=2 {
        for dx in -2i32..=2 {
            let at = ((6 + dy) as u32 * w + (8 + dx) as u32) as usize;
            assert_eq!(g[at], b[(dy + 2) as usize] * b[(dx + 2) as usize], "({dx}, {dy})");
        }
    }
    assert_eq!(g.iter().sum::<f32>(), 256.0);
    // At a corner the clamped taps fold onto the edge pixel: (6 + 4 + 1) / 16 of it along each
    // axis, (5 + 1) / 16 from a pixel beside it, 1 / 16 from the next.
    let mut corner = vec![0.0f32; (w * h) as usize];
    corner[0] = 256.0;
    let g = both_passes("corner impulse", w, h, &corner);
    assert_eq!((g[0], g[1], g[2], g[w as usize]), (11.0 * 11.0, 5.0 * 11.0, 11.0, 11.0 * 5.0));
}

#[test]
fn sizes_the_invocations_do_not_divide_smooth_like_the_twin() {
    // Four pixels per invocation along the pass's axis: 4k + 1, 4k + 2 and 4k + 3 pixels leave
    // the last invocation of a row (x pass) or column (y pass) one to three.
    let (calibration, frame) = sample_frame(0);
    let pre = webfusion_core::cpu::preprocess::chain::preprocess(&calibration, &Default::default(), &frame);
    let k = calibration.intrinsics;
    for (w, h) in [(33u32, 18u32), (18, 35), (7, 5)] {
        let crop: Vec<f32> = (0..h).flat_map(|y| (0..w).map(move |x| ((y + 100) * k.width_px + x + 200) as usize)).map(|i| pre.intensity[i]).collect();
        both_passes(&format!("{w}x{h} crop"), w, h, &crop);
    }
}

#[test]
fn a_real_frame_smooths_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let pre = webfusion_core::cpu::preprocess::chain::preprocess(&calibration, &Default::default(), &frame);
    let k = calibration.intrinsics;
    both_passes("real frame", k.width_px, k.height_px, &pre.intensity);
}
