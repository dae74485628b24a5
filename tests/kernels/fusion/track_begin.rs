// SPDX-License-Identifier: MIT
//! `track_begin`: the first frame only initialises (every level done, no reduction
//! dispatched), later frames start from the reference, the constant-velocity prediction or a
//! guess, and get `reduce_workgroups` per level in use (0 beyond). GPU against its CPU twin;
//! the matrices within 1e-6 (one product under FMA contraction), everything else exact.

use glam::{DQuat, DVec3};
use webfusion_core::cpu;
use webfusion_core::fusion::IcpConfig;
use webfusion_core::fusion::tracker::{initial_state, track_params};
use webfusion_core::kernels::track_begin::{TrackDispatch, TrackLevelStats, TrackParams, TrackState};
use webfusion_core::kernels::track_reduce::{MAX_WORKGROUPS, MIN_PIXELS_PER_THREAD_CPU, MIN_PIXELS_PER_THREAD_GPU, reduce_workgroups};
use webfusion_core::{Gpu, PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, finish, gpu, run_kernel_slots};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 517.3, fy_px: 516.5, cx_px: 318.6, cy_px: 255.3, width_px: 640, height_px: 480 };

fn begin(gpu: &Gpu, p: &TrackParams, state: &TrackState) -> ((TrackState, TrackDispatch), (TrackState, TrackDispatch)) {
    let dispatch = TrackDispatch { reduce: [[7, 7, 7, 7]; 4] };
    let out = run_kernel_slots(gpu, &gpu.kernels.track_begin, p, &[Slot::InOut(bytemuck::bytes_of(state)), Slot::InOut(bytemuck::bytes_of(&dispatch))], [1, 1, 1]);
    let g = (bytemuck::pod_read_unaligned(&out[0]), bytemuck::pod_read_unaligned(&out[1]));
    let (mut cs, mut cd) = (*state, dispatch);
    cpu::track_begin(p, &mut cs, &mut cd);
    (g, (cs, cd))
}

fn same(g: &(TrackState, TrackDispatch), c: &(TrackState, TrackDispatch)) -> Result<(), String> {
    let close = g.0.estimate.iter().flatten().zip(c.0.estimate.iter().flatten()).all(|(a, b)| (a - b).abs() <= 1e-6);
    let exact = TrackState { estimate: c.0.estimate, ..g.0 } == c.0 && g.1 == c.1;
    if close && exact { Ok(()) } else { Err(format!("GPU {g:?}\nvs CPU {c:?}")) }
}

fn pose(angle: f64, t: DVec3) -> Se3 {
    Se3::new(DQuat::from_axis_angle(DVec3::new(0.2, 1.0, -0.3).normalize(), angle), t)
}

#[test]
fn begins_each_kind_of_frame_as_the_twin_does() {
    let gpu = gpu();
    let config = IcpConfig::default();
    // Each level its own workgroup count (as the tracker sizes them), one unused level.
    const LEVEL_WORKGROUPS: [u32; 4] = [MAX_WORKGROUPS, 17, 3, 9];
    let p = track_params(&config, 0, K, 1000, LEVEL_WORKGROUPS);
    let stale = TrackLevelStats { iterations: 9, inliers: 9, rgb_pairs: 9, rms_residual_m: 9.0, condition: 9.0, last_update_m: 9.0, ..Default::default() };
    let reference = pose(0.3, DVec3::new(0.1, 0.2, 0.3));
    let motion = pose(0.02, DVec3::new(0.01, 0.0, -0.005));
    let guess = pose(-0.1, DVec3::new(-0.2, 0.0, 0.4));
    let tracking = TrackState {
        reference: reference.to_cols_f32(),
        motion: motion.to_cols_f32(),
        guess: guess.to_cols_f32(),
        fused_frames: 5,
        done_levels: 0b101,
        levels: [stale; 4],
        ..initial_state()
    };

    // The first frame: nothing to track against.
    let (g, c) = begin(&gpu, &p, &initial_state());
    same(&g, &c).unwrap();
    assert_eq!(g.0.done_levels, 0b1111, "every level done");
    assert!(g.1.reduce.iter().all(|d| d[0] == 0), "no reduction dispatched: {:?}", g.1);

    // A tracked frame starts at the reference, every used level gets its workgroups.
    let (g, c) = begin(&gpu, &p, &tracking);
    same(&g, &c).unwrap();
    assert_eq!(g.0.estimate, reference.to_cols_f32(), "starts at the reference");
    assert_eq!(g.0.done_levels, 0, "no level done yet");
    assert_eq!(g.0.levels, [TrackLevelStats::default(); 4], "statistics cleared");
    let used = config.iterations_per_level.len();
    for (l, d) in g.1.reduce.iter().enumerate() {
        let want = if l < used { LEVEL_WORKGROUPS[l] } else { 0 };
        assert_eq!(*d, [want, 1, 1, 0], "level {l} dispatch");
    }

    // Constant velocity: motion · reference.
    let cv = track_params(&IcpConfig { constant_velocity: true, ..config.clone() }, 0, K, 1000, [MAX_WORKGROUPS; 4]);
    let (g, c) = begin(&gpu, &cv, &tracking);
    same(&g, &c).unwrap();
    let predicted = Se3::from_cols_f32(&g.0.estimate);
    let want = motion * reference;
    assert!((predicted.translation_m - want.translation_m).length() < 1e-6 && (predicted.inverse() * want).rotation_angle_rad() < 1e-5, "constant velocity");

    // A guess wins over both, once.
    let guessed = TrackState { has_guess: 1, ..tracking };
    let (g, c) = begin(&gpu, &cv, &guessed);
    same(&g, &c).unwrap();
    assert_eq!((g.0.estimate, g.0.has_guess), (guess.to_cols_f32(), 0), "the guess is used and consumed");
    finish(&gpu);

    // Negative control of the comparison.
    let mut bad = g;
    bad.1.reduce[2][0] += 1;
    assert!(same(&bad, &c).is_err(), "a wrong dispatch size is caught");
}

#[test]
fn each_level_gets_workgroups_for_its_pixels() {
    // 640x480 and its pyramid on a GPU (16 px per thread of 128) and a CPU adapter (128 px).
    let gpu_counts: Vec<u32> = [307_200, 76_800, 19_200].map(|n| reduce_workgroups(n, MIN_PIXELS_PER_THREAD_GPU)).to_vec();
    assert_eq!(gpu_counts, vec![MAX_WORKGROUPS, 38, 10], "GPU: capped, then 16 px per thread");
    let cpu_counts: Vec<u32> = [307_200, 76_800, 19_200].map(|n| reduce_workgroups(n, MIN_PIXELS_PER_THREAD_CPU)).to_vec();
    assert_eq!(cpu_counts, vec![19, 5, 2], "CPU adapter: 128 px per thread");
    assert_eq!(reduce_workgroups(1, MIN_PIXELS_PER_THREAD_GPU), 1, "at least one workgroup");
    assert_eq!(reduce_workgroups(0, 0), 1, "degenerate input still dispatches one");
}
