// SPDX-License-Identifier: MIT
//! `distance_peaks`: the planes of each normal peak's distance histogram, one workgroup per
//! histogram, against the CPU twin: the same intervals in the same order, exactly (the smoothing
//! of integer counts by quarters is exact in f32). Crafted histograms pin the rules: two modes
//! 4 bins apart with a valley are two planes, a plateau is one peak, a wide noisy mode is one,
//! the smallest mass and the 8 largest, most first.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::distance_histogram::DistanceHistogramParams;
use webfusion_core::kernels::distance_peaks::DistancePeaksParams;
use webfusion_core::planes::{DISTANCE_BINS, MAX_DISTANCE_PEAKS, MAX_NORMAL_PEAKS, NO_LABEL, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

type Found = (Vec<[u32; 4]>, Vec<u32>);

fn run(p: &DistancePeaksParams, histograms: &[u32], count: u32) -> (Found, Found) {
    let gpu = gpu();
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.distance_peaks,
        p,
        &[Slot::In(bytemuck::cast_slice(histograms)), Slot::In(bytemuck::bytes_of(&count)), Slot::Out(16 * MAX_NORMAL_PEAKS * MAX_DISTANCE_PEAKS), Slot::Out(4 * MAX_NORMAL_PEAKS)],
        [MAX_NORMAL_PEAKS as u32 * 256, 1, 1],
    );
    finish(&gpu);
    let (mut intervals, mut counts) = (vec![[0u32; 4]; MAX_NORMAL_PEAKS * MAX_DISTANCE_PEAKS], vec![0u32; MAX_NORMAL_PEAKS]);
    cpu::distance_peaks(p, histograms, &[count], &mut intervals, &mut counts);
    let mut g: Found = (cast(&out[0]), cast(&out[1]));
    // Workgroups past the peak count write nothing (the harness's sentinels stay): compare the
    // written part.
    g.0.truncate(count as usize * MAX_DISTANCE_PEAKS);
    g.1.truncate(count as usize);
    intervals.truncate(count as usize * MAX_DISTANCE_PEAKS);
    counts.truncate(count as usize);
    (g, (intervals, counts))
}

fn compare(what: &str, g: &Found, c: &Found) -> Result<(), String> {
    if g.1 != c.1 {
        return Err(format!("{what}: GPU counts {:?} vs CPU {:?}", g.1, c.1));
    }
    match g.0.iter().zip(&c.0).position(|(a, b)| a != b) {
        Some(i) => Err(format!("{what}: interval {i}: GPU {:?} vs CPU {:?}", g.0[i], c.0[i])),
        None if g.0.len() != c.0.len() => Err(format!("{what}: {} GPU intervals vs {} CPU", g.0.len(), c.0.len())),
        None => Ok(()),
    }
}

fn assert_same_with_controls(what: &str, g: &Found, c: &Found) {
    compare(what, g, c).unwrap();
    let mut wider = g.clone();
    wider.0[0][1] += 1;
    let mut fewer = g.clone();
    fewer.1[0] -= 1;
    let mut sentinel = g.clone();
    sentinel.0[0][2] = webfusion_tests::SENTINEL_F32.to_bits();
    for (case, bad) in [("a wider interval", wider), ("an interval fewer", fewer), ("a sentinel", sentinel)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

fn bump(h: &mut [u32], centre: f32, sigma: f32, height: f32) {
    for (i, v) in h.iter_mut().enumerate() {
        *v += (height * (-0.5 * ((i as f32 - centre) / sigma).powi(2)).exp()) as u32;
    }
}

#[test]
fn crafted_histograms_pin_the_rules() {
    let mut hists = vec![0u32; 4 * DISTANCE_BINS];
    let (a, rest) = hists.split_at_mut(DISTANCE_BINS);
    let (b, rest) = rest.split_at_mut(DISTANCE_BINS);
    let (c, d) = rest.split_at_mut(DISTANCE_BINS);
    // a: two modes 4 bins apart (a wall and a board 2 cm in front, at 5 mm bins).
    bump(a, 300.0, 0.8, 400.0);
    bump(a, 304.0, 0.8, 300.0);
    // b: a plateau of two equal bins (one plane), and a small mode below the smallest mass.
    b[150] = 316;
    b[151] = 316;
    b[600] = 20;
    // c: one wide mode with counting noise.
    bump(c, 500.0, 3.0, 200.0);
    let mut state = 9u32;
    for v in c.iter_mut() {
        *v = (*v as f32 * (0.8 + 0.4 * cpu::shared::random_uniform(&mut state))) as u32;
    }
    // d: twelve separated modes of growing mass: the 8 largest, most first.
    for m in 0..12 {
        bump(d, 40.0 + 70.0 * m as f32, 1.0, 60.0 + 10.0 * m as f32);
    }
    let p = DistancePeaksParams { min_mass: 50, reach_bins: 6, ..Default::default() };
    let (g, c) = run(&p, &hists, 4);
    assert_same_with_controls("crafted", &g, &c);
    let at = |k: usize| &c.0[k * MAX_DISTANCE_PEAKS..k * MAX_DISTANCE_PEAKS + c.1[k] as usize];
    assert_eq!(c.1[0], 2, "two modes 4 bins apart: {:?}", at(0));
    assert!(at(0)[0][0] <= 300 && 300 <= at(0)[0][1] && at(0)[1][0] <= 304 && 304 <= at(0)[1][1] && at(0)[0][1] < at(0)[1][0], "{:?}", at(0));
    assert_eq!(at(1), [[144, 153, 632, 0]], "the plateau is one plane of both bins, from 6 below bin 150 to the first empty bin");
    assert_eq!(c.1[2], 1, "a noisy mode is one plane: {:?}", at(2));
    assert_eq!(c.1[3], 8);
    let masses: Vec<u32> = at(3).iter().map(|i| i[2]).collect();
    assert!(masses.windows(2).all(|w| w[0] > w[1]), "most first: {masses:?}");
    assert!(at(3)[0][0] > 40 + 70 * 10, "the largest is the last mode: {:?}", at(3)[0]);
}

#[test]
fn a_real_frames_histograms_peak_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let mut levels = preprocess(&calibration, &PreprocessConfig::default(), &frame).levels;
    let full = levels.remove(0);
    let level = levels.remove(0);
    let labels = vec![NO_LABEL; full.normal_in_camera.len()];
    let hist = reference::normal_histogram(&full.normal_in_camera, &labels);
    let peaks = reference::normal_peaks(&hist, 800, 8.0, &[], 4.0);
    let mut p4: Vec<[f32; 4]> = peaks.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    p4.resize(MAX_NORMAL_PEAKS, [0.0; 4]);
    let k = level.intrinsics;
    let dp = DistanceHistogramParams { width_px: k.width_px, height_px: k.height_px, full_width_px: full.intrinsics.width_px, level_shift: 1, cos_segment: 5f32.to_radians().cos(), bin_m: 0.005, use_labels: 1, ..Default::default() };
    let n = k.pixel_count();
    let (mut assignment, mut histograms, mut sums) = (vec![0u32; n], vec![0u32; MAX_NORMAL_PEAKS * DISTANCE_BINS], vec![0i32; 4 * MAX_NORMAL_PEAKS]);
    cpu::distance_histogram(&dp, &level.vertex_in_camera, &level.normal_in_camera, &labels, &p4, &[peaks.len() as u32], &mut assignment, &mut histograms, &mut sums);
    let p = DistancePeaksParams { min_mass: (0.01 * n as f32).ceil() as u32, reach_bins: 6, ..Default::default() };
    let (g, c) = run(&p, &histograms, peaks.len() as u32);
    assert_same_with_controls("real frame", &g, &c);
    assert!(c.1.iter().sum::<u32>() >= 2, "the desk and the partition at least: {:?}", c.1);
}
