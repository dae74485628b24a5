// SPDX-License-Identifier: MIT
//! `peak_realign`: normal peaks moved to their pixels' mean normal, against the CPU twin, on
//! the box scene's inner level (distance_histogram's twin gives the sums), with a peak no pixel
//! joined (kept) and empty slots past the count (copied). Tolerance 1e-6 per component; the
//! harness's four negative controls.

use webfusion_core::cpu;
use webfusion_core::kernels::distance_histogram::DistanceHistogramParams;
use webfusion_core::kernels::peak_realign::PeakRealignParams;
use webfusion_core::planes::{DISTANCE_BINS, MAX_NORMAL_PEAKS, NO_LABEL, PlaneConfig};
use webfusion_core::sim::plane_scenes::PlaneScene;
use webfusion_tests::{Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots};

use super::plane_keys::inner_fixture;

#[test]
fn peaks_move_to_their_pixels_mean_normal() {
    let f = inner_fixture(&PlaneScene::box_on_floor(), Some(3));
    let config = PlaneConfig::default();
    let k = f.level.intrinsics;
    // One more peak that no pixel is near: (1, 0, 0) seen edge-on.
    let mut peaks = f.peaks.clone();
    peaks.push([1.0, 0.0, 0.0, 5.0]);
    let count = peaks.len() as u32;
    let params = DistanceHistogramParams { width_px: k.width_px, height_px: k.height_px, full_width_px: k.width_px, cos_segment: config.normal_segment_deg.to_radians().cos(), bin_m: config.distance_bin_m, ..Default::default() };
    let (mut assignment, mut hist, mut sums) = (vec![0u32; k.pixel_count()], vec![0u32; peaks.len() * DISTANCE_BINS], vec![0i32; 4 * MAX_NORMAL_PEAKS]);
    cpu::distance_histogram(&params, &f.level.vertex_in_camera, &f.level.normal_in_camera, &[NO_LABEL], &peaks, &[count], &mut assignment, &mut hist, &mut sums);
    peaks.resize(MAX_NORMAL_PEAKS, [f32::NAN; 4]);
    let p = PeakRealignParams { peak_slots: MAX_NORMAL_PEAKS as u32, ..Default::default() };
    let gpu = gpu();
    let out = run_kernel_slots(&gpu, &gpu.kernels.peak_realign, &p, &[Slot::In(bytemuck::cast_slice(&peaks)), Slot::In(bytemuck::bytes_of(&count)), Slot::In(bytemuck::cast_slice(&sums)), Slot::Out(16 * MAX_NORMAL_PEAKS)], [MAX_NORMAL_PEAKS as u32, 1, 1]);
    finish(&gpu);
    let g: Vec<[f32; 4]> = cast(&out[0]);
    let mut c = vec![[0.0f32; 4]; MAX_NORMAL_PEAKS];
    cpu::peak_realign(&p, &peaks, &[count], &sums, &mut c);
    let tol = Tolerance { absolute: 1e-6, relative: 0.0 };
    compare_vec4("box", &g, &c, tol).unwrap();
    assert_negative_control_vec4("box", &g, &c, tol);
    for (i, (r, pk)) in c.iter().zip(&peaks).enumerate().take(count as usize) {
        let cos = r[0] * pk[0] + r[1] * pk[1] + r[2] * pk[2];
        let len = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        eprintln!("peak {i}: moved {:.2}°", cos.clamp(-1.0, 1.0).acos().to_degrees());
        assert!((len - 1.0).abs() < 1e-6 && cos > 5f32.to_radians().cos(), "peak {i}: unit and within the segmentation angle");
    }
    assert_eq!(&c[count as usize - 1][..3], &[1.0, 0.0, 0.0], "a peak without pixels stays");
    assert!(c[count as usize..].iter().all(|v| v.iter().all(|x| x.is_nan())), "empty slots copied");
}
