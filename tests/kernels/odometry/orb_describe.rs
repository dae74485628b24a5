// SPDX-License-Identifier: MIT
//! `orb_describe`: orientations and descriptors against the CPU twin on a real frame's
//! keypoints, and on a synthetic corner whose orientation is known. WGSL's atan2, sin and cos
//! may differ from Rust's in the last bits, which moves a test point by ~1e-6 px and can flip
//! a test between two nearly equal intensities: at most 0.5 % of all bits may differ and no
//! descriptor by more than 8 of 256; orientations within 1e-4 rad.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::orb_describe::OrbDescribeParams;
use webfusion_core::odometry::{FeatureConfig, descriptor_pattern, slot_count};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots, sample_frame};

const ANGLE_TOL: Tolerance = Tolerance { absolute: 1e-4, relative: 1e-6 };

type Described = (Vec<u32>, Vec<[f32; 4]>);

fn run(p: &OrbDescribeParams, smoothed: &[f32], keypoints: &[[f32; 4]]) -> (Described, Described) {
    let gpu = gpu();
    let pattern = descriptor_pattern();
    let slots = keypoints.len();
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.orb_describe,
        p,
        &[Slot::In(bytemuck::cast_slice(smoothed)), Slot::In(bytemuck::cast_slice(keypoints)), Slot::In(bytemuck::cast_slice(&pattern)), Slot::Out(32 * slots), Slot::Out(16 * slots)],
        [p.slot_count, 1, 1],
    );
    finish(&gpu);
    let (mut dc, mut fc) = (vec![0u32; 8 * slots], vec![[0.0f32; 4]; slots]);
    cpu::orb_describe(p, smoothed, keypoints, &pattern, &mut dc, &mut fc);
    ((cast(&out[0]), cast(&out[1])), (dc, fc))
}

/// Differing bits between two descriptor arrays: (total, worst descriptor).
fn bit_differences(a: &[u32], b: &[u32]) -> (u32, u32) {
    let per: Vec<u32> = a.chunks(8).zip(b.chunks(8)).map(|(x, y)| x.iter().zip(y).map(|(p, q)| (p ^ q).count_ones()).sum()).collect();
    (per.iter().sum(), per.iter().copied().max().unwrap_or(0))
}

fn assert_descriptors_close(what: &str, g: &[u32], c: &[u32], keypoints: usize) -> (u32, u32) {
    let (total, worst) = bit_differences(g, c);
    assert!(total as usize * 200 <= 256 * keypoints.max(1) && worst <= 8, "{what}: {total} bits differ, worst descriptor {worst}");
    (total, worst)
}

#[test]
fn a_real_frame_describes_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let config = FeatureConfig::default();
    let k0 = calibration.intrinsics;
    let layout = config.layout(&k0);
    let mut keypoints = vec![[0.0f32; 4]; slot_count(&layout)];
    let mut points = keypoints.clone();
    for level in &layout {
        let image = &pre.levels[level.level as usize].intensity;
        let mut score = vec![0.0; image.len()];
        cpu::fast_score(&level.fast_params(&config), image, &mut score);
        cpu::keypoint_select(&level.select_params(&config, &k0), &score, &pre.levels[0].depth_m, &mut keypoints, &mut points);
    }
    for level in &layout {
        let image = &pre.levels[level.level as usize].intensity;
        let smoothed = cpu::odometry::feature_smooth::smooth_image(level.width_px, level.height_px, image);
        let ((dg, fg), (dc, fc)) = run(&level.describe_params(&config), &smoothed, &keypoints);
        let own = level.slot_offset as usize..(level.slot_offset + level.slot_count()) as usize;
        let what = format!("level {}", level.level);
        let kept = keypoints[own.clone()].iter().filter(|k| k[3] > 0.0).count();
        compare_vec4(&what, &fg[own.clone()], &fc[own.clone()], ANGLE_TOL).unwrap();
        assert_negative_control_vec4(&what, &fg[own.clone()], &fc[own.clone()], ANGLE_TOL);
        let words = 8 * own.start..8 * own.end;
        let (total, worst) = assert_descriptors_close(&what, &dg[words.clone()], &dc[words.clone()], kept);
        eprintln!("{what}: {kept} keypoints, {total} descriptor bits differ (worst {worst})");
        // Negative controls: a descriptor complemented, and descriptors shifted by a slot.
        let mut flipped = dg[words.clone()].to_vec();
        let first = keypoints[own.clone()].iter().position(|k| k[3] > 0.0).expect("a keypoint");
        for w in &mut flipped[8 * first..8 * first + 8] {
            *w = !*w;
        }
        let (_, worst) = bit_differences(&flipped, &dc[words.clone()]);
        assert!(worst > 8, "{what}: a complemented descriptor passed");
        let shifted: Vec<u32> = dg[words.clone()].iter().skip(8).copied().chain([0; 8]).collect();
        let (total, _) = bit_differences(&shifted, &dc[words]);
        assert!(total as usize * 200 > 256 * kept, "{what}: shifted descriptors passed");
        // Descriptors of keypoints far apart in the image (half the slots away) are unrelated:
        // near half the bits differ (a quarter to three quarters).
        let live: Vec<usize> = (own.start..own.end).filter(|&i| keypoints[i][3] > 0.0).collect();
        let half = live.len() / 2;
        let mean: f64 = (0..half).map(|i| f64::from(bit_differences(&dc[8 * live[i]..8 * live[i] + 8], &dc[8 * live[i + half]..8 * live[i + half] + 8]).0)).sum::<f64>() / half as f64;
        eprintln!("{what}: unrelated keypoints differ by {mean:.1} bits on average");
        assert!((64.0..192.0).contains(&mean), "{what}: unrelated keypoints' descriptors differ by {mean} bits on average");
    }
}

#[test]
fn a_corner_points_its_orientation_at_its_bright_side() {
    // A bright quadrant x >= 40, y >= 30 in a 80x60 image: the centroid of the disc around
    // the corner (40, 30) lies at 45° (down-right in image coordinates). A faint texture (±0.01)
    // keeps the binary tests from comparing exactly equal values, whose outcome rounding decides.
    let (w, h) = (80u32, 60u32);
    let texture = |i: u32| (webfusion_core::cpu::shared::pcg_hash(i) >> 8) as f32 / 16_777_216.0 * 0.02 - 0.01;
    let image: Vec<f32> = (0..w * h).map(|i| if i % w >= 40 && i / w >= 30 { 0.9 } else { 0.1 } + texture(i)).collect();
    let keypoints = vec![[40.0, 30.0, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0]];
    let p = OrbDescribeParams { width_px: w, height_px: h, slot_offset: 0, slot_count: 2, patch_radius_px: 15 };
    let ((dg, fg), (dc, fc)) = run(&p, &image, &keypoints);
    compare_vec4("corner", &fg, &fc, ANGLE_TOL).unwrap();
    assert_descriptors_close("corner", &dg, &dc, 1);
    // The pixel (40, 30) is inside the bright quadrant, so the disc's centroid is a little
    // past 45°; within 2°.
    assert!((fg[0][2].to_degrees() - 45.0).abs() < 2.0, "orientation {}", fg[0][2].to_degrees());
    assert_eq!(&fg[0][..2], &[40.0, 30.0]);
    // The empty slot: no feature, a zero descriptor.
    assert!(fg[1][0].is_nan() && dg[8..].iter().all(|&w| w == 0));
}
