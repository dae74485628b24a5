// SPDX-License-Identifier: MIT
//! `normal_peaks`: the normal histogram's peaks found by one workgroup (tree reductions for
//! the arg-max) against the CPU twin: the same peaks in the same order with the same counts,
//! normals within 1e-5 (WGSL's cos need not be correctly rounded); crafted histograms pin the
//! rules (highest first, the lowest bin among equals, the 3 x 3 centroid, the exclusion radius,
//! the minimum count, bins cleared around known normals).

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::normal_histogram::NormalHistogramParams;
use webfusion_core::kernels::normal_peaks::NormalPeaksParams;
use webfusion_core::planes::{MAX_NORMAL_PEAKS, NO_LABEL, NORMAL_BINS};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const TOL: f32 = 1e-5;

fn run(p: &NormalPeaksParams, hist: &[u32], known: &[[f32; 4]]) -> ((Vec<[f32; 4]>, u32), (Vec<[f32; 4]>, u32)) {
    let gpu = gpu();
    let known_buf: Vec<[f32; 4]> = if known.is_empty() { vec![[0.0; 4]] } else { known.to_vec() };
    let out = run_kernel_slots(&gpu, &gpu.kernels.normal_peaks, p, &[Slot::In(bytemuck::cast_slice(hist)), Slot::In(bytemuck::cast_slice(&known_buf)), Slot::In(bytemuck::bytes_of(&(known.len() as u32))), Slot::Out(16 * MAX_NORMAL_PEAKS), Slot::Out(4)], [1, 1, 1]);
    finish(&gpu);
    let (mut peaks, mut count) = (vec![[0.0f32; 4]; MAX_NORMAL_PEAKS], [0u32]);
    cpu::normal_peaks(p, hist, &known_buf, &[known.len() as u32], &mut peaks, &mut count);
    ((cast(&out[0]), cast::<u32>(&out[1])[0]), (peaks, count[0]))
}

fn compare(what: &str, g: &(Vec<[f32; 4]>, u32), c: &(Vec<[f32; 4]>, u32)) -> Result<(), String> {
    if g.1 != c.1 {
        return Err(format!("{what}: GPU found {} peaks, CPU {}", g.1, c.1));
    }
    for (i, (a, b)) in g.0.iter().zip(&c.0).enumerate() {
        if i < c.1 as usize {
            if (0..3).any(|k| (a[k] - b[k]).abs() > TOL) || a[3] != b[3] {
                return Err(format!("{what}: peak {i}: GPU {a:?} vs CPU {b:?}"));
            }
        } else if a.iter().any(|v| !v.is_nan()) {
            return Err(format!("{what}: slot {i} past the last peak holds {a:?}"));
        }
    }
    Ok(())
}

fn assert_same_with_controls(what: &str, g: &(Vec<[f32; 4]>, u32), c: &(Vec<[f32; 4]>, u32)) {
    compare(what, g, c).unwrap();
    assert!(c.1 >= 1, "{what}: a control needs a peak");
    let mut tilted = g.clone();
    tilted.0[0][0] += 10.0 * TOL;
    let mut recount = g.clone();
    recount.0[0][3] += 1.0;
    let mut fewer = g.clone();
    fewer.1 -= 1;
    let mut sentinel = g.clone();
    sentinel.0[0][1] = webfusion_tests::SENTINEL_F32;
    for (case, bad) in [("a tilted normal", tilted), ("another count", recount), ("a peak fewer", fewer), ("a sentinel", sentinel)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

fn params(min_count: u32) -> NormalPeaksParams {
    NormalPeaksParams { min_count, exclusion_bins: 8.0, clear_bins: 4.0, ..Default::default() }
}

#[test]
fn crafted_histograms_pin_the_rules() {
    let at = |x: usize, y: usize| y * NORMAL_BINS + x;
    let mut h = vec![0u32; NORMAL_BINS * NORMAL_BINS];
    // Two equal peaks far apart: the lower bin index first; a third lower; a fourth within the
    // exclusion radius of the first (cleared); a fifth below the minimum.
    h[at(20, 5)] = 500;
    h[at(21, 5)] = 100; // pulls the first centroid right by 100/600 bin
    h[at(3, 25)] = 500;
    h[at(16, 16)] = 300;
    h[at(23, 8)] = 400; // 4.2 bins from (20, 5): cleared
    h[at(30, 30)] = 20;
    let (g, c) = run(&params(50), &h, &[]);
    assert_same_with_controls("crafted", &g, &c);
    assert_eq!(c.1, 3, "{:?}", c.0);
    let counts: Vec<f32> = c.0[..3].iter().map(|p| p[3]).collect();
    assert_eq!(counts, [500.0, 500.0, 300.0]);
    let expect = cpu::planes::normal_peaks::bin_normal(20.5 + 100.0 / 600.0, 5.5);
    assert!((0..3).all(|k| (c.0[0][k] - expect[k]).abs() < 1e-6), "first peak {:?} = centroid normal {expect:?}", c.0[0]);
    // Known normals clear their surroundings: the (20, 5) peak is known, so (23, 8) (4.2 bins
    // away, past the clearing radius of 4) comes back.
    let known = cpu::planes::normal_peaks::bin_normal(20.5, 5.5);
    let (g, c) = run(&params(50), &h, &[[known[0], known[1], known[2], 0.0]]);
    assert_same_with_controls("known", &g, &c);
    let counts: Vec<f32> = c.0[..c.1 as usize].iter().map(|p| p[3]).collect();
    assert_eq!(counts, [500.0, 400.0, 300.0], "(3, 25), then (23, 8), then (16, 16)");
    // An empty histogram: no peak.
    let (g, c) = run(&params(1), &vec![0; NORMAL_BINS * NORMAL_BINS], &[]);
    compare("empty", &g, &c).unwrap();
    assert_eq!(c.1, 0);
}

#[test]
fn a_real_frame_peaks_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let normals = preprocess(&calibration, &PreprocessConfig::default(), &frame).levels.swap_remove(0).normal_in_camera;
    let mut h = vec![0u32; NORMAL_BINS * NORMAL_BINS];
    let labels = vec![NO_LABEL; normals.len()];
    cpu::normal_histogram(&NormalHistogramParams { pixel_count: normals.len() as u32, use_labels: 1, ..Default::default() }, &normals, &labels, &mut h);
    let (g, c) = run(&params(800), &h, &[]);
    assert_same_with_controls("real frame", &g, &c);
    assert!(c.1 >= 2, "the desk and the partition at least: {} peaks", c.1);
}
