// SPDX-License-Identifier: MIT
//! `distance_histogram`: the inner loop's assignment of pixels to normal peaks and their
//! distance histograms and fixed-point normal sums, GPU (integer atomics) against the CPU twin,
//! on the whiteboard scene (a wall and a board 2 cm in front of it: two distance peaks 4 bins
//! apart) and on a real frame. Tolerance: at least 99.9 % of the pixels get the same (peak,
//! bin); the rest may sit on a bin edge or at the segmentation angle (WGSL's dot may fuse), and
//! the histograms and sums may differ by exactly those pixels.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::distance_histogram::{NO_ASSIGNMENT, NORMAL_SUM_SCALE};
use webfusion_core::cpu::preprocess::chain::{CpuPyramidLevel, preprocess};
use webfusion_core::kernels::distance_histogram::DistanceHistogramParams;
use webfusion_core::planes::{DISTANCE_BINS, MAX_NORMAL_PEAKS, NO_LABEL, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration, RgbdFrame};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

struct Out {
    assignment: Vec<u32>,
    histogram: Vec<u32>,
    normal_sums: Vec<i32>,
}

/// The level-1 pixels of a frame, its full-resolution normal peaks, and `labels`.
fn setup(calibration: &RgbdCalibration, frame: &RgbdFrame) -> (CpuPyramidLevel, Vec<[f32; 4]>, u32) {
    let mut levels = preprocess(calibration, &PreprocessConfig::default(), frame).levels;
    let full = levels.remove(0);
    let hist = reference::normal_histogram(&full.normal_in_camera, &vec![NO_LABEL; full.normal_in_camera.len()]);
    let min = (800.0 / (640.0 * 480.0) * full.normal_in_camera.len() as f32).ceil() as u32;
    let peaks = reference::normal_peaks(&hist, min, 8.0, &[], 4.0);
    assert!(!peaks.is_empty(), "the frame has normal peaks");
    let mut p4: Vec<[f32; 4]> = peaks.iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    p4.resize(MAX_NORMAL_PEAKS, [f32::NAN; 4]);
    (levels.remove(0), p4, peaks.len() as u32)
}

fn run(level: &CpuPyramidLevel, labels: &[u32], full_width: u32, peaks: &[[f32; 4]], count: u32) -> (Out, Out) {
    let gpu = gpu();
    let (w, h) = (level.intrinsics.width_px, level.intrinsics.height_px);
    let p = DistanceHistogramParams { width_px: w, height_px: h, full_width_px: full_width, level_shift: 1, cos_segment: 5f32.to_radians().cos(), bin_m: 0.005, use_labels: 1, ..Default::default() };
    let (zeros_h, zeros_s) = (vec![0u32; MAX_NORMAL_PEAKS * DISTANCE_BINS], vec![0i32; 4 * MAX_NORMAL_PEAKS]);
    let n = level.vertex_in_camera.len();
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.distance_histogram,
        &p,
        &[
            Slot::In(bytemuck::cast_slice(&level.vertex_in_camera)),
            Slot::In(bytemuck::cast_slice(&level.normal_in_camera)),
            Slot::In(bytemuck::cast_slice(labels)),
            Slot::In(bytemuck::cast_slice(peaks)),
            Slot::In(bytemuck::bytes_of(&count)),
            Slot::Out(4 * n),
            Slot::InOut(bytemuck::cast_slice(&zeros_h)),
            Slot::InOut(bytemuck::cast_slice(&zeros_s)),
        ],
        [w, h, 1],
    );
    finish(&gpu);
    let g = Out { assignment: cast(&out[0]), histogram: cast(&out[1]), normal_sums: cast(&out[2]) };
    let mut c = Out { assignment: vec![0; n], histogram: zeros_h, normal_sums: zeros_s };
    cpu::distance_histogram(&p, &level.vertex_in_camera, &level.normal_in_camera, labels, peaks, &[count], &mut c.assignment, &mut c.histogram, &mut c.normal_sums);
    (g, c)
}

fn compare(what: &str, g: &Out, c: &Out) -> Result<usize, String> {
    if g.assignment.len() != c.assignment.len() {
        return Err(format!("{what}: {} GPU pixels vs {} CPU", g.assignment.len(), c.assignment.len()));
    }
    let differ = g.assignment.iter().zip(&c.assignment).filter(|(a, b)| a != b).count();
    if differ * 1000 > g.assignment.len() {
        return Err(format!("{what}: {differ} of {} pixels assigned differently", g.assignment.len()));
    }
    let moved: u64 = g.histogram.iter().zip(&c.histogram).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum();
    if moved > 2 * differ as u64 {
        return Err(format!("{what}: the histograms differ by {moved} counts, {differ} pixels differ"));
    }
    let slack = (differ as f32 + 1.0) * NORMAL_SUM_SCALE;
    if let Some(i) = (0..g.normal_sums.len()).find(|&i| ((g.normal_sums[i] - c.normal_sums[i]) as f32).abs() > slack) {
        return Err(format!("{what}: normal sum {i}: GPU {} vs CPU {}", g.normal_sums[i], c.normal_sums[i]));
    }
    Ok(differ)
}

fn assert_same_with_controls(what: &str, g: Out, c: &Out) {
    let differ = compare(what, &g, c).unwrap();
    eprintln!("{what}: {differ} of {} pixels assigned differently", c.assignment.len());
    let first = c.assignment.iter().position(|&a| a != NO_ASSIGNMENT).expect("an assigned pixel");
    let (peak, bin) = ((c.assignment[first] >> 16) as usize, (c.assignment[first] & 0xffff) as usize);
    let mut dropped = Out { assignment: g.assignment.clone(), histogram: g.histogram.clone(), normal_sums: g.normal_sums.clone() };
    for a in dropped.assignment.iter_mut().filter(|a| **a != NO_ASSIGNMENT).take(c.assignment.len() / 500 + 1) {
        *a = NO_ASSIGNMENT;
    }
    let mut recounted = Out { assignment: g.assignment.clone(), histogram: g.histogram.clone(), normal_sums: g.normal_sums.clone() };
    recounted.histogram[peak * DISTANCE_BINS + bin] += 3;
    let mut tilted = Out { assignment: g.assignment.clone(), histogram: g.histogram.clone(), normal_sums: g.normal_sums.clone() };
    tilted.normal_sums[4 * peak] += (3.0 * NORMAL_SUM_SCALE * (c.assignment.len() as f32 / 1000.0 + 2.0)) as i32;
    let mut sentinel = g;
    sentinel.assignment[first] = webfusion_tests::SENTINEL_F32.to_bits();
    sentinel.assignment.iter_mut().take(c.assignment.len() / 500 + 1).for_each(|a| *a = webfusion_tests::SENTINEL_F32.to_bits());
    for (case, bad) in [("unassigned pixels", dropped), ("extra counts", recounted), ("a tilted normal sum", tilted), ("sentinels", sentinel)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

#[test]
fn a_wall_and_a_board_2_cm_apart_are_two_distance_peaks() {
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    let frame = PlaneScene::whiteboard().render(&K, None).frame;
    let (level, peaks, count) = setup(&calibration, &frame);
    let labels = vec![NO_LABEL; K.pixel_count()];
    let (g, c) = run(&level, &labels, K.width_px, &peaks, count);
    // The wall's peak (the most pixels): two well separated bins of the histogram hold most of
    // its pixels, 2 cm (4 bins) apart along the coarse normal.
    let wall = (0..count as usize).max_by_key(|&k| c.histogram[k * DISTANCE_BINS..(k + 1) * DISTANCE_BINS].iter().sum::<u32>()).expect("peaks");
    let h = &c.histogram[wall * DISTANCE_BINS..(wall + 1) * DISTANCE_BINS];
    assert!(h.iter().sum::<u32>() > 3000, "the wall and the board are assigned to one peak");
    assert_same_with_controls("whiteboard", g, &c);
    // Every assigned pixel's bin is its distance along its peak's normal.
    for (ix, &a) in c.assignment.iter().enumerate() {
        if a == NO_ASSIGNMENT {
            continue;
        }
        let (k, bin) = ((a >> 16) as usize, a & 0xffff);
        let (p, n) = (level.vertex_in_camera[ix], peaks[k]);
        let d = (p[0] * n[0] + p[1] * n[1] + p[2] * n[2]).abs();
        assert_eq!(bin, (d / 0.005) as u32);
    }
}

#[test]
fn labelled_pixels_and_a_real_frame() {
    let (calibration, frame) = sample_frame(0);
    let (level, peaks, count) = setup(&calibration, &frame);
    let k0 = calibration.intrinsics;
    let none = vec![NO_LABEL; k0.pixel_count()];
    let (g, c) = run(&level, &none, k0.width_px, &peaks, count);
    assert_same_with_controls("real frame", g, &c);
    // The top half labelled at full resolution: nothing assigned there at level 1.
    let labels: Vec<u32> = (0..k0.pixel_count()).map(|i| if (i as u32 / k0.width_px) < k0.height_px / 2 { 3 } else { NO_LABEL }).collect();
    let (g, c) = run(&level, &labels, k0.width_px, &peaks, count);
    compare("labelled", &g, &c).unwrap();
    let w = level.intrinsics.width_px as usize;
    assert!(g.assignment.iter().enumerate().filter(|(i, _)| i / w < level.intrinsics.height_px as usize / 2).all(|(_, &a)| a == NO_ASSIGNMENT));
    assert!(g.assignment.iter().any(|&a| a != NO_ASSIGNMENT), "the free half is assigned");
}
