// SPDX-License-Identifier: MIT
//! `feature_guess`: an accepted feature estimate with enough inliers becomes the dense
//! tracker's guess, the last tracked frame's pose composed with the motion (reference ·
//! dst_from_src, within 1e-5 of the f64 product and of the twin); a rejected estimate, or one
//! with too few inliers, leaves the state as it was, a guess the host set included. The
//! negative control shows the comparison catches a guess written where none should be.

use glam::{DQuat, DVec3};
use webfusion_core::cpu;
use webfusion_core::fusion::tracker::initial_state;
use webfusion_core::kernels::feature_guess::{FeatureGuessParams, RigidEstimate, TrackState};
use webfusion_core::{Gpu, Se3};
use webfusion_tests::{Slot, finish, gpu, run_kernel_slots};

fn run(gpu: &Gpu, p: &FeatureGuessParams, estimate: &RigidEstimate, state: &TrackState) -> (TrackState, TrackState) {
    let out = run_kernel_slots(gpu, &gpu.kernels.feature_guess, p, &[Slot::In(bytemuck::bytes_of(estimate)), Slot::InOut(bytemuck::bytes_of(state))], [1, 1, 1]);
    let g: TrackState = bytemuck::pod_read_unaligned(&out[0]);
    let mut c = *state;
    cpu::feature_guess(p, estimate, &mut c);
    (g, c)
}

/// The two states agree: matrices within 1e-5, everything else bit for bit.
fn same(g: &TrackState, c: &TrackState) -> Result<(), String> {
    let close = g.guess.iter().flatten().zip(c.guess.iter().flatten()).all(|(a, b)| (a - b).abs() <= 1e-5);
    let (mut g_rest, mut c_rest) = (*g, *c);
    g_rest.guess = [[0.0; 4]; 4];
    c_rest.guess = [[0.0; 4]; 4];
    if close && bytemuck::bytes_of(&g_rest) == bytemuck::bytes_of(&c_rest) { Ok(()) } else { Err(format!("GPU {g:?}\nvs CPU {c:?}")) }
}

#[test]
fn an_accepted_estimate_becomes_the_guess_and_anything_else_leaves_the_state_alone() {
    let gpu = gpu();
    let p = FeatureGuessParams { min_inliers: 20, ..Default::default() };
    let reference = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, 0.2).normalize(), 0.7), DVec3::new(0.4, -0.2, 1.1));
    let motion = Se3::new(DQuat::from_axis_angle(DVec3::new(1.0, 0.1, 0.0).normalize(), 0.05), DVec3::new(0.02, 0.01, -0.03));
    let host_guess = Se3::new(DQuat::IDENTITY, DVec3::new(9.0, 9.0, 9.0));
    let state = TrackState { reference: reference.to_cols_f32(), guess: host_guess.to_cols_f32(), has_guess: 0, fused_frames: 7, frames: 9, ..initial_state() };
    let accepted = RigidEstimate { dst_from_src: motion.to_cols_f32(), pairs: 180, inliers: 150, accepted: 1, noise_scale: 1.3, rmse_m: 0.004, ..Default::default() };
    let cases = [
        ("accepted", accepted, state, true),
        ("accepted at the bar", RigidEstimate { inliers: 20, ..accepted }, state, true),
        ("too few inliers", RigidEstimate { inliers: 19, ..accepted }, state, false),
        ("rejected", RigidEstimate { accepted: 0, ..accepted }, state, false),
        ("rejected, a host guess kept", RigidEstimate { accepted: 0, ..accepted }, TrackState { has_guess: 1, ..state }, false),
    ];
    for (what, estimate, state, guessed) in cases {
        let (g, c) = run(&gpu, &p, &estimate, &state);
        same(&g, &c).unwrap_or_else(|e| panic!("{what}: {e}"));
        if guessed {
            assert_eq!(g.has_guess, 1, "{what}: guess flagged");
            let got = Se3::from_cols_f32(&g.guess);
            let want = reference * motion;
            assert!((got.translation_m - want.translation_m).length() < 1e-5 && (got.inverse() * want).rotation_angle_rad() < 1e-5, "{what}: guess {got:?}, want {want:?}");
        } else {
            assert_eq!(bytemuck::bytes_of(&g), bytemuck::bytes_of(&state), "{what}: the state was changed");
        }
    }
    // Negative control: the comparison catches a guess written where the twin wrote none.
    let rejected = RigidEstimate { accepted: 0, ..accepted };
    let (g, c) = run(&gpu, &p, &rejected, &state);
    let mut wrong = g;
    wrong.has_guess = 1;
    assert!(same(&wrong, &c).is_err(), "the comparison catches a flag set");
    wrong = g;
    wrong.guess[3][0] += 1e-4;
    assert!(same(&wrong, &c).is_err(), "the comparison catches a moved guess");
    finish(&gpu);
}
