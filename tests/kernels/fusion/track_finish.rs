// SPDX-License-Identifier: MIT
//! `track_finish`: every outcome (initialised, tracked, recovered, and lost for too few pairs,
//! an ill-conditioned system or an implausible jump) is decided as its CPU twin decides it,
//! with the reference, motion model, published pose and counters updated accordingly. The
//! matrices within 1e-5 (products and inverses under FMA contraction), the rest exact.

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, fusion::track_finish::outcome};
use webfusion_core::fusion::IcpConfig;
use webfusion_core::fusion::tracker::{initial_state, track_params};
use webfusion_core::kernels::track_reduce::MAX_WORKGROUPS;
use webfusion_core::kernels::track_finish::{TrackLevelStats, TrackParams, TrackState};
use webfusion_core::{Gpu, PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, finish, gpu, run_kernel_slots};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 517.3, fy_px: 516.5, cx_px: 318.6, cy_px: 255.3, width_px: 640, height_px: 480 };
const MIN_INLIERS: u32 = 15_360;

fn run(gpu: &Gpu, p: &TrackParams, state: &TrackState) -> (TrackState, TrackState) {
    let out = run_kernel_slots(gpu, &gpu.kernels.track_finish, p, &[Slot::InOut(bytemuck::bytes_of(state))], [1, 1, 1]);
    let g: TrackState = bytemuck::pod_read_unaligned(&out[0]);
    let mut c = *state;
    cpu::track_finish(p, &mut c);
    (g, c)
}

fn same(g: &TrackState, c: &TrackState) -> Result<(), String> {
    let mats = |s: &TrackState| [s.pose.world_from_camera, s.pose.camera_from_world, s.estimate, s.reference, s.previous_view, s.motion, s.guess];
    let close = mats(g).iter().flatten().flatten().zip(mats(c).iter().flatten().flatten()).all(|(a, b)| (a - b).abs() <= 1e-5);
    let floats = (g.jump_translation_m - c.jump_translation_m).abs() <= 1e-5 && (g.jump_rotation_rad - c.jump_rotation_rad).abs() <= 1e-3;
    let rest = (g.pose.enabled, g.outcome, g.frames, g.fused_frames, g.lost_streak, g.done_levels, g.has_guess, g.reseeded) == (c.pose.enabled, c.outcome, c.frames, c.fused_frames, c.lost_streak, c.done_levels, c.has_guess, c.reseeded);
    if close && floats && rest { Ok(()) } else { Err(format!("GPU {g:?}\nvs CPU {c:?}")) }
}

#[test]
fn every_outcome_is_decided_as_the_twin_decides() {
    let gpu = gpu();
    let p = track_params(&IcpConfig::default(), 0, K, MIN_INLIERS, [MAX_WORKGROUPS; 4]);
    let reference = Se3::new(DQuat::from_axis_angle(DVec3::Y, 0.3), DVec3::new(0.1, 0.0, 0.2));
    let small = Se3::new(DQuat::from_axis_angle(DVec3::X, 0.02), DVec3::new(0.01, 0.0, 0.0)) * reference;
    let good = TrackLevelStats { iterations: 3, inliers: 100_000, condition: 50.0, translation_condition: 8.0, ..Default::default() };
    let tracking = TrackState { reference: reference.to_cols_f32(), estimate: small.to_cols_f32(), fused_frames: 4, frames: 6, levels: [good; 4], ..initial_state() };
    let cases = [
        ("first frame", TrackState { estimate: reference.to_cols_f32(), ..initial_state() }, outcome::INITIALISED),
        ("tracked", tracking, outcome::TRACKED),
        ("recovered", TrackState { lost_streak: 2, ..tracking }, outcome::RECOVERED),
        ("too few pairs", TrackState { levels: [TrackLevelStats { inliers: MIN_INLIERS - 1, ..good }; 4], ..tracking }, outcome::LOST_TOO_FEW_INLIERS),
        ("ill-conditioned", TrackState { levels: [TrackLevelStats { condition: 2e5, ..good }; 4], ..tracking }, outcome::LOST_ILL_CONDITIONED),
        ("a translation unobserved", TrackState { levels: [TrackLevelStats { translation_condition: 300.0, ..good }; 4], ..tracking }, outcome::LOST_ILL_CONDITIONED),
        ("jump", TrackState { estimate: (Se3::new(DQuat::IDENTITY, DVec3::new(0.3, 0.0, 0.0)) * reference).to_cols_f32(), ..tracking }, outcome::LOST_IMPLAUSIBLE_JUMP),
        ("reseeded, refined", TrackState { reseeded: 1, lost_streak: 1, estimate: (Se3::new(DQuat::IDENTITY, DVec3::new(0.03, 0.0, 0.0)) * reference).to_cols_f32(), ..tracking }, outcome::RECOVERED),
        ("reseeded, moved", TrackState { reseeded: 1, lost_streak: 1, estimate: (Se3::new(DQuat::IDENTITY, DVec3::new(0.08, 0.0, 0.0)) * reference).to_cols_f32(), ..tracking }, outcome::LOST_IMPLAUSIBLE_JUMP),
        ("reseeded, turned", TrackState { reseeded: 1, estimate: (Se3::new(DQuat::from_axis_angle(DVec3::Z, 0.1), DVec3::ZERO) * reference).to_cols_f32(), ..tracking }, outcome::LOST_IMPLAUSIBLE_JUMP),
        ("turn", TrackState { estimate: (Se3::new(DQuat::from_axis_angle(DVec3::Z, 0.5), DVec3::ZERO) * reference).to_cols_f32(), ..tracking }, outcome::LOST_IMPLAUSIBLE_JUMP),
    ];
    for (what, state, want) in cases {
        let (g, c) = run(&gpu, &p, &state);
        same(&g, &c).unwrap_or_else(|e| panic!("{what}: {e}"));
        assert_eq!(g.outcome, want, "{what}: outcome");
        assert_eq!(g.frames, state.frames + 1, "{what}: frame counted");
        assert_eq!(g.reseeded, 0, "{what}: a reseed holds for one frame");
        let lost = want >= outcome::LOST_TOO_FEW_INLIERS;
        if lost {
            assert_eq!(g.pose.enabled, 0, "{what}: a lost frame is neither fused nor predicted");
            assert_eq!(g.pose.world_from_camera, state.reference, "{what}: and keeps the last good pose");
            assert_eq!((g.reference, g.previous_view, g.fused_frames, g.lost_streak), (state.reference, state.previous_view, state.fused_frames, state.lost_streak + 1), "{what}: reference and previous view kept");
        } else {
            assert_eq!(g.pose.enabled, 1, "{what}: fused and predicted");
            assert_eq!((g.pose.world_from_camera, g.reference, g.previous_view), (state.estimate, state.estimate, state.estimate), "{what}: the estimate becomes the pose, reference and previous view");
            assert_eq!((g.fused_frames, g.lost_streak), (state.fused_frames + 1, 0), "{what}: counted as fused");
        }
    }
    // The motion model learns estimate · reference⁻¹.
    let (g, _) = run(&gpu, &p, &tracking);
    let learned = Se3::from_cols_f32(&g.motion);
    let want = small * reference.inverse();
    assert!((learned.translation_m - want.translation_m).length() < 1e-6 && (learned.inverse() * want).rotation_angle_rad() < 1e-5, "motion model");
    finish(&gpu);
    let (_, c) = run(&gpu_for_control(), &p, &tracking);
    let mut bad = c;
    bad.lost_streak = 1;
    assert!(same(&bad, &c).is_err(), "the comparison catches a wrong counter");
}

fn gpu_for_control() -> Gpu {
    gpu()
}
