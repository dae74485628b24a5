// SPDX-License-Identifier: MIT
//! `keypoint_select`: per-cell keypoints against the CPU twin, from `corner_candidates`'
//! candidates (computed by its twin). The selection is order-based on exact scores, so
//! keypoints must be identical; the back-projected points within 1e-6 relative. On a synthetic
//! image with known maxima and depth holes, and on a real frame.

use webfusion_core::cpu;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::kernels::{corner_candidates::CornerCandidatesParams, keypoint_select::KeypointSelectParams};
use webfusion_core::odometry::{FeatureConfig, slot_count};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_tests::{Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots, sample_frame};

const POINT_TOL: Tolerance = Tolerance { absolute: 1e-7, relative: 1e-6 };

/// Selects among the candidates of `score` (marked by `corner_candidates`' twin), GPU and CPU.
fn run(p: &KeypointSelectParams, score: &[f32], depth_m: &[f32], slots: usize) -> ([Vec<[f32; 4]>; 2], [Vec<[f32; 4]>; 2]) {
    let candidates_params = CornerCandidatesParams {
        width_px: p.width_px,
        height_px: p.height_px,
        level: p.level,
        depth_width_px: p.depth_width_px,
        depth_height_px: p.depth_height_px,
        fx_px: p.fx_px,
        ..Default::default()
    };
    let mut candidate = vec![0.0; score.len()];
    cpu::corner_candidates(&candidates_params, score, depth_m, &mut candidate);
    let score = candidate.as_slice();
    let gpu = gpu();
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.keypoint_select,
        p,
        &[Slot::In(bytemuck::cast_slice(score)), Slot::In(bytemuck::cast_slice(depth_m)), Slot::Out(16 * slots), Slot::Out(16 * slots)],
        [p.cells_x * p.cells_y, 1, 1],
    );
    finish(&gpu);
    // The CPU fills only the level's slots; the GPU left the others at the sentinel.
    let sentinel = [webfusion_tests::SENTINEL_F32; 4];
    let (mut kc, mut pc) = (vec![sentinel; slots], vec![sentinel; slots]);
    cpu::keypoint_select(p, score, depth_m, &mut kc, &mut pc);
    ([cast(&out[0]), kc], [cast(&out[1]), pc])
}

fn params(w: u32, h: u32, level: u32, cell_px: u32, per_cell: u32, slot_offset: u32, k0: (u32, u32, f32)) -> KeypointSelectParams {
    KeypointSelectParams {
        width_px: w,
        height_px: h,
        level,
        cell_px,
        cells_x: w.div_ceil(cell_px),
        cells_y: h.div_ceil(cell_px),
        per_cell,
        slot_offset,
        depth_width_px: k0.0,
        depth_height_px: k0.1,
        fx_px: k0.2,
        fy_px: k0.2,
        cx_px: (k0.0 as f32 - 1.0) / 2.0,
        cy_px: (k0.1 as f32 - 1.0) / 2.0,
    }
}

#[test]
fn the_best_local_maxima_with_depth_are_kept_per_cell() {
    // 32x16 scores in two 16x16 cells, depth 2 m everywhere but a hole and a step.
    let (w, h) = (32u32, 16u32);
    let mut score = vec![0.0f32; (w * h) as usize];
    let mut set = |x: u32, y: u32, s: f32| score[(y * w + x) as usize] = s;
    set(3, 3, 0.5); // cell 0: kept second
    set(4, 3, 0.4); // its neighbour: suppressed
    set(8, 8, 0.7); // kept first
    set(12, 12, 0.3); // third best: dropped with per_cell 2
    set(20, 5, 0.6); // cell 1: on a depth hole (3 missing): dropped
    set(24, 10, 0.9); // on a depth step: dropped
    set(27, 4, 0.2); // kept
    set(28, 12, 0.2); // equal score, later pixel: kept second
    let mut depth = vec![2.0f32; (w * h) as usize];
    for (x, y) in [(19, 5), (20, 4), (21, 6)] {
        depth[(y * w + x) as usize] = f32::NAN;
    }
    depth[(11 * w + 25) as usize] = 2.5;
    let p = params(w, h, 0, 16, 2, 1, (w, h, 100.0));
    let ([kg, kc], [pg, pc]) = run(&p, &score, &depth, 6);
    compare_vec4("keypoints", &kg, &kc, Tolerance::EXACT).unwrap();
    compare_vec4("points", &pg, &pc, POINT_TOL).unwrap();
    assert_negative_control_vec4("points", &pg[1..5], &pc[1..5], POINT_TOL);
    let got: Vec<[f32; 2]> = kg[1..5].iter().map(|k| [k[0], k[1]]).collect();
    assert_eq!(got, vec![[8.0, 8.0], [3.0, 3.0], [27.0, 4.0], [28.0, 12.0]]);
    assert_eq!(kg[1][3], 0.7);
    // (8, 8) at 2 m with f = 100, c = (15.5, 7.5): x = (8 - 15.5) / 100 * 2.
    assert!((pg[1][0] - (-0.15)).abs() < 1e-6 && (pg[1][1] - 0.01).abs() < 1e-6 && pg[1][2] == 2.0);
    // The slot before the level's and after it are untouched.
    assert_eq!(kg[0][0].to_bits(), webfusion_tests::SENTINEL_F32.to_bits());
    assert_eq!(kg[5][0].to_bits(), webfusion_tests::SENTINEL_F32.to_bits());
}

#[test]
fn a_real_frame_selects_like_the_twin() {
    let (calibration, frame) = sample_frame(0);
    let pre = preprocess(&calibration, &PreprocessConfig::default(), &frame);
    let config = FeatureConfig::default();
    let k0 = calibration.intrinsics;
    let layout = config.layout(&k0);
    let slots = slot_count(&layout);
    for level in &layout {
        let image = &pre.levels[level.level as usize].intensity;
        let mut score = vec![0.0; image.len()];
        cpu::fast_score(&level.fast_params(&config), image, &mut score);
        let ([kg, kc], [pg, pc]) = run(&level.select_params(&config, &k0), &score, &pre.levels[0].depth_m, slots);
        let what = format!("level {}", level.level);
        compare_vec4(&what, &kg, &kc, Tolerance::EXACT).unwrap();
        compare_vec4(&what, &pg, &pc, POINT_TOL).unwrap();
        let kept = kc.iter().filter(|k| k[3] > 0.0).count();
        eprintln!("{what}: {kept} keypoints of {} slots", level.slot_count());
        assert!(kept * 3 > level.slot_count() as usize, "{what}: most cells of a real frame have keypoints");
        let own = level.slot_offset as usize..(level.slot_offset + level.slot_count()) as usize;
        assert_negative_control_vec4(&what, &kg[own.clone()], &kc[own.clone()], Tolerance::EXACT);
        assert_negative_control_vec4(&what, &pg[own.clone()], &pc[own], POINT_TOL);
    }
}
