// SPDX-License-Identifier: MIT
//! `plane_keys`: which plane's sums each pixel joins, against the CPU twin. Inner-loop keys
//! (mode 0) on the box scene's inner level, from the twins of the stages before it (integer
//! work only: identical); labelled keys (mode 1) on a real frame with the reference's planes
//! and its raw depth (at most 1 ‰ different: a raw point at the distance limit may fall either
//! way when WGSL fuses a multiply-add). Four negative controls each; each side's chunk masks
//! must be exactly those of its own keys. The fixtures here feed the
//! plane_sums, plane_sums_reduce and plane_fit tests.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::plane_sums::{CHUNK_MASK_WORDS, PLANE_SUMS_CHUNK_PX, plane_sums_chunks};
use webfusion_core::cpu::preprocess::chain::{CpuPreprocessed, CpuPyramidLevel, preprocess};
use webfusion_core::kernels::distance_histogram::DistanceHistogramParams;
use webfusion_core::kernels::distance_peaks::DistancePeaksParams;
use webfusion_core::kernels::plane_keys::PlaneKeysParams;
use webfusion_core::kernels::plane_label::PlaneLabelParams;
use webfusion_core::planes::gpu::plane_keys_params;
use webfusion_core::planes::{DISTANCE_BINS, MAX_DISTANCE_PEAKS, MAX_NORMAL_PEAKS, NO_LABEL, PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::plane_scenes::{PlaneScene, UNITS_PER_METRE};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 262.5, fy_px: 262.5, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };

/// The inputs of mode 0 at the inner level of a synthetic scene: the level, its assignment
/// (distance_histogram's twin), the normal peaks, the intervals and their counts.
pub(crate) struct InnerFixture {
    pub level: CpuPyramidLevel,
    pub assignment: Vec<u32>,
    pub peaks: Vec<[f32; 4]>,
    pub intervals: Vec<[u32; 4]>,
    pub interval_count: Vec<u32>,
}

pub(crate) fn inner_fixture(scene: &PlaneScene, noise: Option<u32>) -> InnerFixture {
    let config = PlaneConfig::default();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE as f32 };
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &scene.render(&K, noise).frame);
    let full = &pre.levels[0];
    let inner_l = config.inner_level_for(K.width_px, pre.levels.len());
    let level = pre.levels[inner_l].clone();
    let labels = vec![NO_LABEL; full.vertex_in_camera.len()];
    let hist = reference::normal_histogram(&full.normal_in_camera, &labels);
    let min_peak = (config.min_normal_peak_fraction * full.vertex_in_camera.len() as f32).ceil() as u32;
    let peaks: Vec<[f32; 4]> = reference::normal_peaks(&hist, min_peak, config.normal_peak_exclusion_bins, &[], 0.0).iter().map(|p| [p[0], p[1], p[2], 0.0]).collect();
    assert!(peaks.len() >= 2 && peaks.len() <= MAX_NORMAL_PEAKS, "{}: {} normal peaks", scene.name, peaks.len());
    let k = level.intrinsics;
    let n = level.vertex_in_camera.len();
    let params = DistanceHistogramParams {
        width_px: k.width_px,
        height_px: k.height_px,
        full_width_px: K.width_px,
        level_shift: inner_l as u32,
        cos_segment: config.normal_segment_deg.to_radians().cos(),
        bin_m: config.distance_bin_m,
        use_labels: 1,
        ..Default::default()
    };
    let mut assignment = vec![0u32; n];
    let mut hist = vec![0u32; peaks.len() * DISTANCE_BINS];
    let mut normal_sums = vec![0i32; 4 * peaks.len()];
    cpu::distance_histogram(&params, &level.vertex_in_camera, &level.normal_in_camera, &labels, &peaks, &[peaks.len() as u32], &mut assignment, &mut hist, &mut normal_sums);
    let min_mass = (config.min_plane_fraction * n as f32).ceil() as u32;
    let dp = DistancePeaksParams { min_mass, reach_bins: (config.distance_reach_m / config.distance_bin_m).round() as u32, ..Default::default() };
    let mut intervals = vec![[0u32; 4]; MAX_NORMAL_PEAKS * MAX_DISTANCE_PEAKS];
    let mut interval_count = vec![0u32; MAX_NORMAL_PEAKS];
    cpu::distance_peaks(&dp, &hist, &[peaks.len() as u32], &mut intervals, &mut interval_count);
    InnerFixture { level, assignment, peaks, intervals, interval_count }
}

pub(crate) fn inner_params(level: &CpuPyramidLevel) -> PlaneKeysParams {
    plane_keys_params(&level.intrinsics, 0, &PlaneConfig::default())
}

/// A real frame's preprocessing, the reference's planes (normal, offset) and the labels the
/// plane_label twin gives them.
pub(crate) fn real_fixture() -> (CpuPreprocessed, Vec<[f32; 4]>, Vec<u32>) {
    let (calibration, frame) = sample_frame(0);
    let config = PlaneConfig::default();
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
    assert!(seg.planes.len() >= 2, "the reference finds the desk and the partition");
    let planes: Vec<[f32; 4]> = seg.planes.iter().map(|p| [p.normal[0], p.normal[1], p.normal[2], p.offset_m]).collect();
    let full = &pre.levels[0];
    let n = full.vertex_in_camera.len();
    let lp = PlaneLabelParams { pixel_count: n as u32, cos_label: config.label_angle_deg.to_radians().cos(), min_distance_m: config.label_min_distance_m, ..Default::default() };
    let mut labels = vec![NO_LABEL; n];
    cpu::plane_label(&lp, &full.vertex_in_camera, &full.normal_in_camera, &planes, &[planes.len() as u32], &mut labels);
    (pre, planes, labels)
}

pub(crate) fn label_params(level: &CpuPyramidLevel, use_raw: bool) -> PlaneKeysParams {
    PlaneKeysParams { use_raw: u32::from(use_raw), ..plane_keys_params(&level.intrinsics, 1, &PlaneConfig::default()) }
}

/// The chunk masks of `keys` (a bit per key present in each chunk), as plane_keys sets them.
pub(crate) fn masks_of(keys: &[u32]) -> Vec<u32> {
    let mut masks = vec![0u32; plane_sums_chunks(keys.len()) * CHUNK_MASK_WORDS];
    for (ix, &k) in keys.iter().enumerate() {
        if k != NO_LABEL {
            masks[(ix / PLANE_SUMS_CHUNK_PX) * CHUNK_MASK_WORDS + k as usize / 32] |= 1 << (k % 32);
        }
    }
    masks
}

/// The twin's keys and chunk masks.
pub(crate) fn twin_keys(params: &PlaneKeysParams, source: &[u32], intervals: &[[u32; 4]], interval_count: &[u32], raw_depth_m: &[f32], planes: &[[f32; 4]]) -> (Vec<u32>, Vec<u32>) {
    let n = (params.width_px * params.height_px) as usize;
    let (mut keys, mut masks) = (vec![0u32; n], vec![0u32; plane_sums_chunks(n) * CHUNK_MASK_WORDS]);
    cpu::plane_keys(params, source, intervals, interval_count, raw_depth_m, planes, &mut keys, &mut masks);
    (keys, masks)
}

/// Runs plane_keys on the GPU and its twin; returns (GPU, twin) keys, after checking that each
/// side's chunk masks are those of its keys.
pub(crate) fn run(params: &PlaneKeysParams, source: &[u32], intervals: &[[u32; 4]], interval_count: &[u32], raw_depth_m: &[f32], planes: &[[f32; 4]]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let n = (params.width_px * params.height_px) as usize;
    let zeros = vec![0u32; plane_sums_chunks(n) * CHUNK_MASK_WORDS];
    let planes_buf: Vec<[f32; 4]> = if planes.is_empty() { vec![[0.0; 4]] } else { planes.to_vec() };
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_keys,
        params,
        &[
            Slot::In(bytemuck::cast_slice(source)),
            Slot::In(bytemuck::cast_slice(intervals)),
            Slot::In(bytemuck::cast_slice(interval_count)),
            Slot::In(bytemuck::cast_slice(raw_depth_m)),
            Slot::In(bytemuck::cast_slice(&planes_buf)),
            Slot::Out(4 * n),
            Slot::InOut(bytemuck::cast_slice(&zeros)),
        ],
        [params.width_px, params.height_px, 1],
    );
    finish(&gpu);
    let (g, g_masks): (Vec<u32>, Vec<u32>) = (cast(&out[0]), cast(&out[1]));
    let (c, c_masks) = twin_keys(params, source, intervals, interval_count, raw_depth_m, &planes_buf);
    assert_eq!(g_masks, masks_of(&g), "the GPU's chunk masks are its keys'");
    assert_eq!(c_masks, masks_of(&c), "the twin's chunk masks are its keys'");
    let mut missing = g_masks.clone();
    missing[g_masks.iter().position(|&m| m != 0).expect("a keyed chunk")] = 0;
    assert_ne!(missing, masks_of(&g), "the mask comparison can fail");
    (g, c)
}

fn assert_same_with_controls(what: &str, g: &[u32], c: &[u32], per_mille: usize) {
    webfusion_tests::compare_u32_mostly(what, g, c, per_mille).unwrap();
    let keyed: Vec<usize> = (0..c.len()).filter(|&i| c[i] != NO_LABEL).take(c.len() / 500 + 1).collect();
    assert!(!keyed.is_empty(), "{what}: a control needs keyed pixels");
    let (mut unkeyed, mut rekeyed, mut sentinel) = (g.to_vec(), g.to_vec(), g.to_vec());
    for &i in &keyed {
        unkeyed[i] = NO_LABEL;
        rekeyed[i] = c[i] + 1;
        sentinel[i] = webfusion_tests::SENTINEL_F32.to_bits();
    }
    let mut keyed_free = g.to_vec();
    let free: Vec<usize> = (0..c.len()).filter(|&i| c[i] == NO_LABEL).take(c.len() / 500 + 1).collect();
    for &i in &free {
        keyed_free[i] = 0;
    }
    for (case, bad) in [("dropped keys", unkeyed), ("other planes", rekeyed), ("sentinels", sentinel), ("keys on free pixels", keyed_free)] {
        assert!(webfusion_tests::compare_u32_mostly(what, &bad, c, per_mille).is_err(), "{what}: the comparison accepted {case}");
    }
}

#[test]
fn inner_loop_keys_follow_the_intervals() {
    for scene in [PlaneScene::box_on_floor(), PlaneScene::stairs()] {
        let f = inner_fixture(&scene, Some(3));
        let p = inner_params(&f.level);
        let (g, c) = run(&p, &f.assignment, &f.intervals, &f.interval_count, &[0.0], &[]);
        assert_same_with_controls(scene.name, &g, &c, 0);
        // Every key names a present interval that holds the pixel's bin.
        for (ix, &key) in g.iter().enumerate() {
            if key == NO_LABEL {
                continue;
            }
            let (k, j) = (key as usize / MAX_DISTANCE_PEAKS, key as usize % MAX_DISTANCE_PEAKS);
            let bin = f.assignment[ix] & 0xffff;
            assert!((f.assignment[ix] >> 16) as usize == k && j < f.interval_count[k] as usize, "{}: pixel {ix} key {key}", scene.name);
            assert!(f.intervals[key as usize][0] <= bin && bin <= f.intervals[key as usize][1]);
        }
        let keyed = g.iter().filter(|&&k| k != NO_LABEL).count();
        eprintln!("{}: {keyed} of {} inner pixels keyed", scene.name, g.len());
        assert!(keyed * 2 > g.len(), "{}: most pixels lie on a plane", scene.name);
    }
}

#[test]
fn labelled_keys_keep_interior_pixels_whose_raw_point_fits() {
    let (pre, planes, labels) = real_fixture();
    let full = &pre.levels[0];
    for use_raw in [false, true] {
        let p = label_params(full, use_raw);
        let (g, c) = run(&p, &labels, &[[0; 4]], &[0], &pre.depth_unfiltered_m, &planes);
        let what = if use_raw { "real frame, raw points" } else { "real frame" };
        assert_same_with_controls(what, &g, &c, 1);
        let (labelled, keyed) = (labels.iter().filter(|&&l| l != NO_LABEL).count(), g.iter().filter(|&&k| k != NO_LABEL).count());
        eprintln!("{what}: {keyed} of {labelled} labelled pixels keyed");
        assert!(keyed < labelled && keyed * 2 > labelled, "{what}: the margin drops the borders only");
        assert!(g.iter().zip(&labels).all(|(&k, &l)| k == NO_LABEL || k == l), "{what}: a key is the pixel's label");
    }
}
