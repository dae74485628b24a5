// SPDX-License-Identifier: MIT
//! `normal_histogram`: the 32 x 32 normal histogram of plane segmentation, GPU (integer
//! atomics) against the CPU twin, on a synthetic scene with exact planes and on a real Kinect
//! frame, with and without earlier labels. Tolerance: the same total, and bins may differ only
//! by normals whose acos lands within rounding of a bin edge (WGSL's acos need not be correctly
//! rounded): at most 1 in 1000 counted normals moved.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::normal_histogram::NormalHistogramParams;
use webfusion_core::planes::{NO_LABEL, NORMAL_BINS};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

fn run(normals: &[[f32; 4]], labels: &[u32], use_labels: bool) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let p = NormalHistogramParams { pixel_count: normals.len() as u32, use_labels: u32::from(use_labels), ..Default::default() };
    let zeros = vec![0u32; NORMAL_BINS * NORMAL_BINS];
    let out = run_kernel_slots(&gpu, &gpu.kernels.normal_histogram, &p, &[Slot::In(bytemuck::cast_slice(normals)), Slot::In(bytemuck::cast_slice(labels)), Slot::InOut(bytemuck::cast_slice(&zeros))], [normals.len() as u32, 1, 1]);
    finish(&gpu);
    let mut c = zeros;
    cpu::normal_histogram(&p, normals, labels, &mut c);
    (cast(&out[0]), c)
}

/// Same total and at most 1 in 1000 normals in another bin.
fn compare(what: &str, g: &[u32], c: &[u32]) -> Result<(), String> {
    let (tg, tc) = (g.iter().map(|&v| u64::from(v)).sum::<u64>(), c.iter().map(|&v| u64::from(v)).sum::<u64>());
    if g.len() != c.len() || tg != tc {
        return Err(format!("{what}: GPU counted {tg} normals in {} bins, CPU {tc} in {}", g.len(), c.len()));
    }
    let moved: u64 = g.iter().zip(c).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum::<u64>() / 2;
    if moved * 1000 > tc {
        return Err(format!("{what}: {moved} of {tc} normals in another bin"));
    }
    Ok(())
}

fn assert_same_with_controls(what: &str, g: &[u32], c: &[u32]) {
    compare(what, g, c).unwrap();
    let i = c.iter().enumerate().max_by_key(|(_, v)| **v).map(|(i, _)| i).expect("bins");
    let mut moved = g.to_vec();
    let shift = c[i] / 2;
    moved[i] -= shift;
    let next = (i + 1) % moved.len();
    moved[next] += shift;
    let mut lost = g.to_vec();
    lost[i] -= 1;
    let mut sentinel = g.to_vec();
    sentinel[i] = webfusion_tests::SENTINEL_F32.to_bits();
    for (case, bad) in [("half a peak moved", moved), ("a normal lost", lost), ("a sentinel", sentinel)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

fn scene_normals() -> Vec<[f32; 4]> {
    let r = PlaneScene::box_on_floor().render(&K, Some(2));
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    preprocess(&calibration, &PreprocessConfig::default(), &r.frame).levels.swap_remove(0).normal_in_camera
}

#[test]
fn synthetic_planes_bin_like_the_twin() {
    let normals = scene_normals();
    let none = vec![NO_LABEL; normals.len()];
    let (g, c) = run(&normals, &none, true);
    assert_same_with_controls("box on a floor", &g, &c);
    let valid = normals.iter().filter(|n| n[0].is_finite()).count() as u32;
    assert_eq!(c.iter().sum::<u32>(), valid, "every valid normal is counted once");
    // The floor (normal (0, -1, 0) in the world, the camera pitched 28° down) fills one bin.
    let top = *c.iter().max().expect("bins");
    assert!(top > valid / 10, "the floor's bin holds {top} of {valid}");
}

#[test]
fn labelled_pixels_are_skipped_unless_labels_are_off() {
    let normals = scene_normals();
    // The left half of the image labelled by an earlier round.
    let labels: Vec<u32> = (0..normals.len()).map(|i| if (i as u32 % K.width_px) < K.width_px / 2 { 0 } else { NO_LABEL }).collect();
    let (g, c) = run(&normals, &labels, true);
    assert_same_with_controls("labelled", &g, &c);
    let free = normals.iter().zip(&labels).filter(|(n, l)| n[0].is_finite() && **l == NO_LABEL).count() as u32;
    assert_eq!(g.iter().sum::<u32>(), free);
    let (g_all, c_all) = run(&normals, &labels, false);
    compare("labels off", &g_all, &c_all).unwrap();
    assert!(g_all.iter().sum::<u32>() > free, "with labels off every valid normal counts");
}

#[test]
fn a_real_frame_bins_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let normals = preprocess(&calibration, &PreprocessConfig::default(), &frame).levels.swap_remove(0).normal_in_camera;
    let none = vec![NO_LABEL; normals.len()];
    let (g, c) = run(&normals, &none, true);
    assert_same_with_controls("real frame", &g, &c);
}
