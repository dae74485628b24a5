// SPDX-License-Identifier: MIT
//! `track_solve`: the tracker's Gauss-Newton step in f32 on the GPU, against its CPU twin
//! (statement by statement) and against the f64 host solve (`NormalEquations`), on real
//! systems (a Kinect frame off its true pose, point-to-plane plus photometric), on a poorly
//! conditioned system below the conditioning gate, one above it and a singular one (a single
//! plane); plus the convergence and done-level bookkeeping.
//!
//! Tolerances: the f32 update differs from the f64 one by at most ~κ·ε relative (κ the scaled
//! condition number, ε = 2⁻²³): 1e-4 relative to the update's size on real systems (κ ≈ 10²),
//! κ · 5e-6 on the ill-conditioned one. GPU vs CPU twin: the same f32 arithmetic up to FMA
//! contraction, 1e-5 relative on the estimate, 1e-3 relative on the condition number (Jacobi
//! sweeps may stop one rotation apart), counts exact.

use glam::DVec3;
use nalgebra::{Matrix6, Vector6};
use webfusion_core::cpu::{self, fusion::track_solve::CONDITION_SINGULAR};
use webfusion_core::fusion::tracker::{initial_state, track_params};
use webfusion_core::fusion::{IcpConfig, NormalEquations, twist_exp};
use webfusion_core::kernels::track_solve::{TrackDispatch, TrackParams, TrackState};
use webfusion_core::kernels::track_reduce::{MAX_WORKGROUPS, SUM_FLOATS};
use webfusion_core::{Gpu, PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 517.3, fy_px: 516.5, cx_px: 318.6, cy_px: 255.3, width_px: 640, height_px: 480 };

fn params(level: u32) -> TrackParams {
    track_params(&IcpConfig::default(), level as usize, K.pyramid_level(level as usize), 1000, [MAX_WORKGROUPS; 4])
}

/// Runs the kernel on the GPU and its twin on the CPU from the same state.
fn solve(gpu: &Gpu, p: &TrackParams, partials: &[f32], state: &TrackState) -> ((TrackState, TrackDispatch), (TrackState, TrackDispatch)) {
    let dispatch = TrackDispatch { reduce: [[MAX_WORKGROUPS, 1, 1, 0]; 4] };
    let out = run_kernel_slots(
        gpu,
        &gpu.kernels.track_solve,
        p,
        &[Slot::In(bytemuck::cast_slice(partials)), Slot::InOut(bytemuck::bytes_of(state)), Slot::InOut(bytemuck::bytes_of(&dispatch))],
        [32, 1, 1],
    );
    let g = (bytemuck::pod_read_unaligned::<TrackState>(&out[0]), bytemuck::pod_read_unaligned::<TrackDispatch>(&out[1]));
    let (mut cs, mut cd) = (*state, dispatch);
    cpu::track_solve(p, partials, &mut cs, &mut cd);
    (g, (cs, cd))
}

/// Partial sums (one workgroup holds the system, the others zero) of JᵀJ = `a`, Jᵀr = `b`.
fn partials_of(a: &Matrix6<f64>, b: &Vector6<f64>, inliers: f32) -> Vec<f32> {
    let mut p = vec![0.0f32; MAX_WORKGROUPS as usize * SUM_FLOATS];
    let mut k = 0;
    for i in 0..6 {
        for j in i..6 {
            p[k] = a[(i, j)] as f32;
            k += 1;
        }
    }
    for i in 0..6 {
        p[21 + i] = b[i] as f32;
    }
    p[27] = 1e-4 * inliers;
    p[28] = inliers;
    p
}

/// The twist that takes `before` to `after` (after = exp(ξ) before), as (ω, t).
fn applied_twist(before: &[[f32; 4]; 4], after: &[[f32; 4]; 4]) -> [f64; 6] {
    let d = Se3::from_cols_f32(after) * Se3::from_cols_f32(before).inverse();
    let (axis, angle) = d.rotation.to_axis_angle();
    let w = axis * angle;
    [w.x, w.y, w.z, d.translation_m.x, d.translation_m.y, d.translation_m.z]
}

fn rel_diff(a: &[f64; 6], b: &Vector6<f64>) -> f64 {
    let diff = (0..6).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>().sqrt();
    diff / b.norm().max(1e-12)
}

/// GPU vs CPU twin on everything the kernel writes.
fn compare_states(g: &(TrackState, TrackDispatch), c: &(TrackState, TrackDispatch), level: usize) -> Result<(), String> {
    let (gs, cs) = (&g.0, &c.0);
    let rel = |a: f32, b: f32| (a - b).abs() / b.abs().max(1e-30);
    for col in 0..4 {
        for row in 0..4 {
            let (a, b) = (gs.estimate[col][row], cs.estimate[col][row]);
            if !((a - b).abs() <= 1e-5 * b.abs().max(1.0)) {
                return Err(format!("estimate[{col}][{row}]: GPU {a} vs CPU {b}"));
            }
        }
    }
    let (gl, cl) = (gs.levels[level], cs.levels[level]);
    if (gl.iterations, gl.inliers, gl.rgb_pairs) != (cl.iterations, cl.inliers, cl.rgb_pairs) {
        return Err(format!("level counts: GPU {gl:?} vs CPU {cl:?}"));
    }
    if !(rel(gl.condition, cl.condition) <= 1e-3) || !(rel(gl.rms_residual_m, cl.rms_residual_m) <= 1e-5) {
        return Err(format!("level statistics: GPU {gl:?} vs CPU {cl:?}"));
    }
    if !((gl.last_update_m - cl.last_update_m).abs() <= 1e-5 * cl.last_update_m.abs().max(1e-6)) {
        return Err(format!("last update: GPU {} vs CPU {}", gl.last_update_m, cl.last_update_m));
    }
    if gs.done_levels != cs.done_levels || g.1 != c.1 {
        return Err(format!("done levels {} vs {}, dispatch {:?} vs {:?}", gs.done_levels, cs.done_levels, g.1, c.1));
    }
    Ok(())
}

/// A real system: TUM frame 0's maps against themselves, the estimate 1° and 1 cm off
/// (point-to-plane and photometric rows, the tracker's weights).
fn real_system() -> (Vec<f32>, TrackState) {
    use crate::fusion::track_reduce::{ReduceInputs, reduce_cpu_with, state_at};
    let chain = crate::preprocess::chain::real_cpu_chain();
    let l = &chain.levels[0];
    let truth = Se3::IDENTITY;
    let estimate = twist_exp(DVec3::new(0.01, -0.012, 0.006), DVec3::new(0.008, -0.004, 0.006));
    let mut previous = vec![[0.0; 4]; l.intrinsics.pixel_count()];
    let kp = webfusion_core::kernels::keep_previous::KeepPreviousParams { width_px: l.intrinsics.width_px, height_px: l.intrinsics.height_px, ..Default::default() };
    cpu::keep_previous(&kp, &cpu::shared::camera_pose(&cpu::shared::IDENTITY, 1), &l.intensity, &l.depth_m, &mut previous);
    let p = track_params(&IcpConfig::default(), 0, l.intrinsics, 0, [MAX_WORKGROUPS; 4]);
    let state = state_at(&estimate, &truth);
    let i = ReduceInputs { vertex: &l.vertex_in_camera, normal: &l.normal_in_camera, predicted_vertex: &l.vertex_in_camera, predicted_normal: &l.normal_in_camera, intensity: &l.intensity, previous: &previous };
    (reduce_cpu_with(&p, &state, &i), state)
}

#[test]
fn a_real_system_solves_like_the_f64_host_and_the_twin() {
    let (partials, state) = real_system();
    let system = NormalEquations::from_partial_sums(&partials);
    let host = system.solve().expect("a real frame constrains all six degrees of freedom");
    let gpu = gpu();
    let p = params(0);
    let (g, c) = solve(&gpu, &p, &partials, &state);
    finish(&gpu);
    compare_states(&g, &c, 0).unwrap_or_else(|e| panic!("GPU vs CPU twin: {e}"));
    let applied = applied_twist(&state.estimate, &g.0.estimate);
    let d = rel_diff(&applied, &host);
    let kappa = system.scaled_condition(1.0);
    eprintln!("real system: {} pairs, scaled κ {kappa:.1} (GPU {:.1}), f32 vs f64 update {d:e} relative", system.inliers, g.0.levels[0].condition);
    assert!(d < 1e-4, "the f32 solve's update is {d:e} (relative) off the f64 one");
    assert!((f64::from(g.0.levels[0].condition) - kappa).abs() < 1e-3 * kappa, "condition number: GPU {} vs f64 {kappa}", g.0.levels[0].condition);
    assert_eq!(g.0.levels[0].iterations, 1, "one iteration counted");
    assert_eq!(u64::from(g.0.levels[0].inliers), system.inliers, "pairs counted");
    // Negative control: a 1e-3 relative error in the update is caught.
    let mut bad = g;
    bad.0.estimate[3][0] += 1e-4;
    assert!(compare_states(&bad, &c, 0).is_err(), "a moved estimate is caught");
}

/// JᵀJ = M diag(λ) Mᵀ in mixed units, with eigenvalues spread by `spread`, and Jᵀr for a
/// known twist.
fn spread_system(spread: f64) -> (Matrix6<f64>, Vector6<f64>) {
    let q = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
    let mut basis = Matrix6::zeros();
    basis.fixed_view_mut::<3, 3>(0, 0).copy_from(q.matrix());
    basis.fixed_view_mut::<3, 3>(3, 3).copy_from(&q.matrix().transpose());
    let mix = Matrix6::from_fn(|i, j| if i == j { 1.0 } else { 0.05 * ((i * 7 + j * 3) % 5) as f64 - 0.1 });
    let m = basis * mix;
    let lambdas = Vector6::new(4e4, 2e4, 9e3, 1.2e3, 4e4 / spread.sqrt(), 4e4 / spread);
    let a = m * Matrix6::from_diagonal(&lambdas) * m.transpose();
    let b = a * Vector6::new(-1e-3, 2e-3, 5e-4, 4e-3, -2e-3, 1e-3);
    (a, b)
}

#[test]
fn a_poorly_conditioned_system_is_solved_within_its_condition_and_measured() {
    let (a, b) = spread_system(300.0);
    let partials = partials_of(&a, &b, 5e4);
    let system = NormalEquations::from_partial_sums(&partials);
    let host = system.solve().expect("positive definite");
    let kappa = system.scaled_condition(1.0);
    let gpu = gpu();
    let (g, c) = solve(&gpu, &params(0), &partials, &initial_state());
    finish(&gpu);
    compare_states(&g, &c, 0).unwrap_or_else(|e| panic!("GPU vs CPU twin: {e}"));
    let d = rel_diff(&applied_twist(&initial_state().estimate, &g.0.estimate), &host);
    eprintln!("poorly conditioned: scaled κ {kappa:.3e} (GPU {:.3e}), f32 vs f64 update {d:e}", g.0.levels[0].condition);
    assert!(kappa > 100.0 && kappa < f64::from(IcpConfig::default().max_condition), "the test system is poorly conditioned but below the gate ({kappa:e})");
    assert!(g.0.levels[0].translation_condition < IcpConfig::default().max_translation_condition, "its translations are observed ({})", g.0.levels[0].translation_condition);
    assert!(d < kappa * 5e-6, "the f32 update is {d:e} off the f64 one (κ = {kappa:e})");
    assert!((f64::from(g.0.levels[0].condition) - kappa).abs() < 1e-2 * kappa, "condition {} vs {kappa}", g.0.levels[0].condition);
}

/// JᵀJ = blockdiag(rotation block, translation block) from the eigenvalues of each (in axes
/// rotated by fixed angles), and Jᵀr for a known twist.
fn block_system(rotation: [f64; 3], translation: [f64; 3]) -> (Matrix6<f64>, Vector6<f64>) {
    let qr = nalgebra::Rotation3::from_euler_angles(0.4, 0.2, -0.5);
    let qt = nalgebra::Rotation3::from_euler_angles(-0.3, 0.9, 0.1);
    let r = qr.matrix() * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from(rotation)) * qr.matrix().transpose();
    let t = qt.matrix() * nalgebra::Matrix3::from_diagonal(&nalgebra::Vector3::from(translation)) * qt.matrix().transpose();
    let mut a = Matrix6::zeros();
    a.fixed_view_mut::<3, 3>(0, 0).copy_from(&r);
    a.fixed_view_mut::<3, 3>(3, 3).copy_from(&t);
    let b = a * Vector6::new(-1e-3, 2e-3, 5e-4, 4e-3, -2e-3, 1e-3);
    (a, b)
}

/// Solves `a`, `b` on the GPU from the reset state; checks it against the twin and returns the
/// result.
fn solve_block(a: &Matrix6<f64>, b: &Vector6<f64>) -> (TrackState, TrackDispatch) {
    let partials = partials_of(a, b, 5e4);
    let gpu = gpu();
    let (g, c) = solve(&gpu, &params(0), &partials, &initial_state());
    finish(&gpu);
    compare_states(&g, &c, 0).unwrap_or_else(|e| panic!("GPU vs CPU twin: {e}"));
    g
}

#[test]
fn a_direction_of_translation_without_information_is_not_stepped_along() {
    // Normals spread over two directions, the third with 1/300 of the best's information: a
    // corridor.
    let (a, b) = block_system([3e4, 2e4, 1.5e4], [1e4, 5e3, 1e4 / 300.0]);
    let full = NormalEquations::from_partial_sums(&partials_of(&a, &b, 5e4)).scaled_condition(1.0);
    let g = solve_block(&a, &b);
    let s = g.0.levels[0];
    eprintln!("corridor-like: full κ {:.3e} (f64 {full:.3e}), translation κ {:.3e}", s.condition, s.translation_condition);
    assert!(f64::from(s.condition) < f64::from(IcpConfig::default().max_condition), "the full system passes the numerical gate");
    assert!((f64::from(s.translation_condition) - 300.0).abs() < 3.0, "translation block condition {} (300 built in)", s.translation_condition);
    assert_eq!(g.0.estimate, initial_state().estimate, "no step along the unobserved translation");
    assert_eq!((g.0.done_levels & 1, g.1.reduce[0][0]), (1, 0), "and the level ends");
    // The same system with the third direction at 1/50: observed, the step is taken.
    let (a, b) = block_system([3e4, 2e4, 1.5e4], [1e4, 5e3, 1e4 / 50.0]);
    let g = solve_block(&a, &b);
    assert_ne!(g.0.estimate, initial_state().estimate, "a weakly but truly observed direction is stepped along (κ {})", g.0.levels[0].translation_condition);
}

#[test]
fn a_numerically_rank_deficient_system_is_not_stepped_along() {
    // Rotation about one axis (a lone sphere's) with 1e-6 of the information of the others.
    let (a, b) = block_system([1e4, 1e4, 1e-2], [1e4, 1e4, 1e4]);
    let kappa = NormalEquations::from_partial_sums(&partials_of(&a, &b, 5e4)).scaled_condition(1.0);
    let g = solve_block(&a, &b);
    let s = g.0.levels[0];
    eprintln!("rank-deficient: full κ {:.3e} (f64 {kappa:.3e}), translation κ {:.3e}", s.condition, s.translation_condition);
    assert!(kappa > f64::from(IcpConfig::default().max_condition), "the system fails the numerical gate (f64 κ {kappa:e})");
    assert!(f64::from(s.condition) > f64::from(IcpConfig::default().max_condition), "and the f32 measure says so ({})", s.condition);
    assert!(s.translation_condition < 2.0, "its translations are fine ({})", s.translation_condition);
    assert_eq!(g.0.estimate, initial_state().estimate, "no step");
}

#[test]
fn a_single_plane_is_singular_and_leaves_the_estimate() {
    // Rows of a plane z = 1 seen head-on: n = (0, 0, -1) everywhere, J = [v × n, n]. Three
    // directions (two translations in the plane, the rotation about its normal) have no
    // information at all.
    let mut a = Matrix6::zeros();
    let mut b = Vector6::zeros();
    for y in -20..20 {
        for x in -20..20 {
            let v = nalgebra::Vector3::new(f64::from(x) * 0.02, f64::from(y) * 0.02, 1.0);
            let n = nalgebra::Vector3::new(0.0, 0.0, -1.0);
            let j = Vector6::from_iterator(v.cross(&n).iter().chain(n.iter()).copied());
            a += j * j.transpose();
            b += j * 0.003;
        }
    }
    let partials = partials_of(&a, &b, 1600.0);
    let gpu = gpu();
    let state = initial_state();
    let (g, c) = solve(&gpu, &params(0), &partials, &state);
    finish(&gpu);
    compare_states(&g, &c, 0).unwrap_or_else(|e| panic!("GPU vs CPU twin: {e}"));
    let cond = g.0.levels[0].condition;
    eprintln!("single plane: condition {cond:e}");
    let tcond = g.0.levels[0].translation_condition;
    assert!(cond > IcpConfig::default().max_condition || tcond > IcpConfig::default().max_translation_condition, "a single plane fails the conditioning checks ({cond:e}, {tcond:e})");
    assert_eq!(g.0.estimate, state.estimate, "no step along the plane's unconstrained directions");
    assert_eq!(g.0.done_levels & 1, 1, "and the level ends");
    assert_eq!(g.1.reduce[0][0], 0, "its remaining reductions get no workgroup");
    let _ = CONDITION_SINGULAR;
}

#[test]
fn a_zero_system_ends_the_level_and_a_done_level_is_left_alone() {
    let gpu = gpu();
    let zeros = vec![0.0f32; MAX_WORKGROUPS as usize * SUM_FLOATS];
    let (g, c) = solve(&gpu, &params(1), &zeros, &initial_state());
    compare_states(&g, &c, 1).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((g.0.levels[1].condition, g.0.levels[1].translation_condition), (CONDITION_SINGULAR, CONDITION_SINGULAR), "no pairs: singular");
    assert_eq!((g.0.done_levels, g.1.reduce[1][0], g.1.reduce[0][0]), (2, 0, MAX_WORKGROUPS), "level 1 done, level 0 untouched");
    // Once done, another solve of the level changes nothing at all.
    let (partials, state) = real_system();
    let done = TrackState { done_levels: 1, ..state };
    let (g, c) = solve(&gpu, &params(0), &partials, &done);
    finish(&gpu);
    assert_eq!(g.0, done, "a done level is skipped on the GPU");
    assert_eq!(c.0, done, "and by the twin");
}

#[test]
fn an_update_below_the_threshold_converges_the_level() {
    // JᵀJ = I, Jᵀr = -ξ: the update is ξ itself, 10 µm, below the level-0 threshold.
    let a = Matrix6::identity() * 1e4;
    let xi = Vector6::new(1e-6, -2e-6, 1e-6, 1e-5, 0.0, -5e-6);
    let partials = partials_of(&a, &(-(a * xi)), 1e4);
    let gpu = gpu();
    let p = params(0);
    let (g, c) = solve(&gpu, &p, &partials, &initial_state());
    compare_states(&g, &c, 0).unwrap_or_else(|e| panic!("{e}"));
    let s = g.0.levels[0];
    assert!(s.last_update_m < p.converged_update_m, "update {} m below {} m", s.last_update_m, p.converged_update_m);
    assert_eq!((g.0.done_levels & 1, g.1.reduce[0][0]), (1, 0), "converged: done, no more reductions");
    // Fifty times larger (about twice the threshold): not converged, the level goes on.
    let partials = partials_of(&a, &(-(a * xi * 50.0)), 1e4);
    let (g, _) = solve(&gpu, &p, &partials, &initial_state());
    finish(&gpu);
    assert_eq!((g.0.done_levels & 1, g.1.reduce[0][0]), (0, MAX_WORKGROUPS), "a larger update keeps the level going ({} m)", g.0.levels[0].last_update_m);
    let t = Se3::from_cols_f32(&g.0.estimate).translation_m;
    assert!((t - DVec3::new(5e-4, 0.0, -2.5e-4)).length() < 1e-7, "the update is applied: {t:?}");
    let _ = cast::<u8>;
}
