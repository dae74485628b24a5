// SPDX-License-Identifier: MIT
//! `track_reduce`, its point-to-plane rows (the photometric rows are tested in
//! `track_reduce_photometric.rs`, both together at the end): the GPU's per-workgroup normal
//! equations match the CPU reference on a real Kinect frame; on an exactly rendered scene the
//! residual vanishes at the true pose and Gauss-Newton on the GPU sums recovers a known
//! perturbation; the rejection thresholds reject.
//!
//! Tolerances: JᵀJ and Jᵀr add terms of both signs, so entries are compared against the scale
//! of the system (relative Frobenius difference of JᵀJ 1e-4, of Jᵀr 1e-3 of |JᵀJ|·1 mm), the
//! solved twists within 1e-5 (rad, m). Correspondence counts may differ by 0.05 %: a vertex
//! projecting within an ulp of a pixel boundary can pick the neighbouring prediction under
//! FMA contraction.

use glam::{DQuat, DVec3};
use webfusion_core::cpu;
use webfusion_core::cpu::fusion::track_reduce::TrackInputs;
use webfusion_core::fusion::tracker::{initial_state, track_params};
use webfusion_core::fusion::{IcpConfig, NormalEquations, twist_exp};
use webfusion_core::kernels::track_reduce::{MAX_WORKGROUPS, MAX_WORKGROUPS as WORKGROUPS, SUM_FLOATS, TrackParams, TrackState};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::{ColorImage, DepthImage, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Se3};
use webfusion_core::Gpu;
use webfusion_tests::{cast, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;
use crate::synthetic::{Room, UNITS_PER_M};

const PARTIALS: usize = WORKGROUPS as usize * SUM_FLOATS;

/// Current-frame maps (camera frame) and the prediction they imply at `world_from_camera_true`.
struct Maps {
    k: PinholeIntrinsics,
    vertex: Vec<[f32; 4]>,
    normal: Vec<[f32; 4]>,
    predicted_vertex: Vec<[f32; 4]>,
    predicted_normal: Vec<[f32; 4]>,
}

fn maps(k: PinholeIntrinsics, vertex: &[[f32; 4]], normal: &[[f32; 4]], world_from_camera_true: &Se3) -> Maps {
    let m = world_from_camera_true.to_mat4().to_cols_array_2d();
    let to_world = |v: &[f32; 4], w: f32| {
        if v[0].is_nan() {
            *v
        } else {
            let r = cpu::shared::mat4_mul_vec4(&m, [v[0], v[1], v[2], w]);
            [r[0], r[1], r[2], w]
        }
    };
    Maps {
        k,
        vertex: vertex.to_vec(),
        normal: normal.to_vec(),
        predicted_vertex: vertex.iter().map(|v| to_world(v, 1.0)).collect(),
        predicted_normal: normal.iter().map(|n| to_world(n, 0.0)).collect(),
    }
}

/// The tracker's parameters at level 0 of `k` with these thresholds, depth only (no
/// photometric rows), and the state holding `estimate` against the reference `reference`.
fn params(maps: &Maps, estimate: &Se3, reference: &Se3, dist_thresh_m: f32, angle_deg: f32) -> (TrackParams, TrackState) {
    let config = IcpConfig { dist_thresh_m, angle_thresh_rad: angle_deg.to_radians(), huber_delta_m: 0.01, rgb_weight: 0.0, ..IcpConfig::default() };
    (track_params(&config, 0, maps.k, 0, [MAX_WORKGROUPS; 4]), state_at(estimate, reference))
}

/// A `TrackState` with `estimate` and `reference` set (the rest as after a reset).
pub(crate) fn state_at(estimate: &Se3, reference: &Se3) -> TrackState {
    TrackState { estimate: estimate.to_cols_f32(), reference: reference.to_cols_f32(), previous_view: reference.to_cols_f32(), ..initial_state() }
}

/// All of `track_reduce`'s inputs, in binding order after the params and state.
pub(crate) struct ReduceInputs<'a> {
    pub(crate) vertex: &'a [[f32; 4]],
    pub(crate) normal: &'a [[f32; 4]],
    pub(crate) predicted_vertex: &'a [[f32; 4]],
    pub(crate) predicted_normal: &'a [[f32; 4]],
    pub(crate) intensity: &'a [f32],
    pub(crate) previous: &'a [[f32; 4]],
}

/// The GPU's partial sums (`WORKGROUPS` blocks of `SUM_FLOATS`).
pub(crate) fn reduce_gpu_with(gpu: &Gpu, p: &TrackParams, state: &TrackState, i: &ReduceInputs) -> Vec<f32> {
    let inputs: [&[u8]; 7] = [
        bytemuck::bytes_of(state),
        bytemuck::cast_slice(i.vertex),
        bytemuck::cast_slice(i.normal),
        bytemuck::cast_slice(i.predicted_vertex),
        bytemuck::cast_slice(i.predicted_normal),
        bytemuck::cast_slice(i.intensity),
        bytemuck::cast_slice(i.previous),
    ];
    cast(&run_kernel(gpu, &gpu.kernels.track_reduce, p, &inputs, &[4 * PARTIALS], [p.thread_count, 1, 1])[0])
}

/// The CPU twin's partial sums.
pub(crate) fn reduce_cpu_with(p: &TrackParams, state: &TrackState, i: &ReduceInputs) -> Vec<f32> {
    let mut out = vec![0.0; PARTIALS];
    let inputs = TrackInputs {
        vertex_in_camera: i.vertex,
        normal_in_camera: i.normal,
        predicted_vertex_in_world: i.predicted_vertex,
        predicted_normal_in_world: i.predicted_normal,
        intensity: i.intensity,
        previous: i.previous,
    };
    cpu::track_reduce(p, state, &inputs, &mut out);
    out
}

fn depth_only_inputs(maps: &Maps) -> (Vec<f32>, Vec<[f32; 4]>) {
    let n = maps.k.pixel_count();
    (vec![0.5; n], vec![[0.5, 0.0, 0.0, f32::NAN]; n])
}

fn reduce_gpu(gpu: &Gpu, maps: &Maps, p: &(TrackParams, TrackState)) -> Vec<f32> {
    let (intensity, previous) = depth_only_inputs(maps);
    let i = ReduceInputs { vertex: &maps.vertex, normal: &maps.normal, predicted_vertex: &maps.predicted_vertex, predicted_normal: &maps.predicted_normal, intensity: &intensity, previous: &previous };
    reduce_gpu_with(gpu, &p.0, &p.1, &i)
}

fn reduce_cpu(maps: &Maps, p: &(TrackParams, TrackState)) -> Vec<f32> {
    let (intensity, previous) = depth_only_inputs(maps);
    let i = ReduceInputs { vertex: &maps.vertex, normal: &maps.normal, predicted_vertex: &maps.predicted_vertex, predicted_normal: &maps.predicted_normal, intensity: &intensity, previous: &previous };
    reduce_cpu_with(&p.0, &p.1, &i)
}

/// Compares two sets of partial sums by the system they add up to (see the tolerances above).
fn compare_systems(gpu: &[f32], cpu: &[f32]) -> Result<(), String> {
    let (g, c) = (NormalEquations::from_partial_sums(gpu), NormalEquations::from_partial_sums(cpu));
    let count_diff = g.inliers.abs_diff(c.inliers);
    if count_diff as f64 > 5e-4 * c.inliers as f64 {
        return Err(format!("inliers: GPU {} vs CPU {}", g.inliers, c.inliers));
    }
    let jtj_rel = (g.jtj - c.jtj).norm() / c.jtj.norm().max(1e-30);
    if !(jtj_rel <= 1e-4) {
        return Err(format!("JᵀJ differs by {jtj_rel:e} relative"));
    }
    let jtr_scale = c.jtj.norm() * 1e-3;
    let jtr_rel = (g.jtr - c.jtr).norm() / jtr_scale.max(1e-30);
    if !(jtr_rel <= 1e-3) {
        return Err(format!("Jᵀr differs by {jtr_rel:e} of |JᵀJ|·1 mm"));
    }
    if let (Some(xg), Some(xc)) = (g.solve(), c.solve()) {
        let d = (xg - xc).amax();
        if !(d <= 1e-5) {
            return Err(format!("solved twists differ by {d:e}"));
        }
    }
    if gpu.chunks(SUM_FLOATS).any(|b| b[29..].iter().any(|&v| v != 0.0)) {
        return Err("photometric statistics or padding written by a depth-only reduction".into());
    }
    Ok(())
}

fn perturbed(truth: &Se3, angle_deg: f64, translation_mm: f64) -> Se3 {
    let delta = Se3::new(DQuat::from_axis_angle(DVec3::new(0.4, -0.7, 0.3).normalize(), angle_deg.to_radians()), DVec3::new(0.6, 0.3, -0.5).normalize() * translation_mm * 1e-3);
    delta * *truth
}

#[test]
fn real_frame_partial_sums_match_cpu_and_the_comparison_can_fail() {
    let chain = real_cpu_chain();
    let level = &chain.levels[0];
    let truth = Se3::new(DQuat::from_axis_angle(DVec3::Y, 0.3), DVec3::new(0.1, -0.05, 0.2));
    let m = maps(level.intrinsics, &level.vertex_in_camera, &level.normal_in_camera, &truth);
    let gpu = gpu();
    for (angle, mm) in [(0.0, 0.0), (1.0, 10.0)] {
        let p = params(&m, &perturbed(&truth, angle, mm), &truth, 0.1, 20.0);
        let (g, c) = (reduce_gpu(&gpu, &m, &p), reduce_cpu(&m, &p));
        compare_systems(&g, &c).unwrap_or_else(|e| panic!("{angle}° {mm} mm: {e}"));
        let system = NormalEquations::from_partial_sums(&g);
        assert!(system.inliers > 100_000, "most pixels pair up ({})", system.inliers);
        // Negative controls: a JᵀJ diagonal entry 1 % off, a Jᵀr entry moved, 1 % of the pairs lost.
        let mut bad = g.clone();
        bad[0] *= 1.0 + 64.0 * 0.01;
        assert!(compare_systems(&bad, &c).is_err(), "a JᵀJ entry 1 % off (in sum) is caught");
        let mut bad = g.clone();
        bad[21] += (NormalEquations::from_partial_sums(&c).jtj.norm() * 1e-5) as f32 * 10.0;
        assert!(compare_systems(&bad, &c).is_err(), "a moved Jᵀr entry is caught");
        let mut bad = g.clone();
        bad[28] += (system.inliers as f32) * 0.01;
        assert!(compare_systems(&bad, &c).is_err(), "lost pairs are caught");
        let mut bad = g.clone();
        bad[30] = 1.0;
        assert!(compare_systems(&bad, &c).is_err(), "a written padding float is caught");
    }
    finish(&gpu);
}

/// The analytic room at 320x240 through the CPU preprocessing chain.
fn room_maps(truth: &Se3) -> Maps {
    let k = PinholeIntrinsics { fx_px: 258.65, fy_px: 258.25, cx_px: 159.3, cy_px: 127.65, width_px: 320, height_px: 240 };
    let frame = RgbdFrame {
        index: 0,
        depth_timestamp_ns: 0,
        color_timestamp_ns: 0,
        depth: DepthImage::new(k.width_px, k.height_px, Room::render_depth_units(&k, truth)).expect("depth"),
        color: ColorImage::new(k.width_px, k.height_px, vec![128; 3 * k.pixel_count()]).expect("colour"),
    };
    let calibration = RgbdCalibration { intrinsics: k, depth_units_per_metre: UNITS_PER_M };
    let chain = cpu::preprocess::chain::preprocess(&calibration, &PreprocessConfig::default(), &frame);
    maps(k, &chain.levels[0].vertex_in_camera, &chain.levels[0].normal_in_camera, truth)
}

#[test]
fn gauss_newton_on_gpu_sums_recovers_a_known_perturbation() {
    let truth = Se3::new(DQuat::from_axis_angle(DVec3::new(0.2, 1.0, 0.1).normalize(), 0.2), DVec3::new(0.05, -0.02, 0.1));
    let m = room_maps(&truth);
    let gpu = gpu();
    // At the true pose every pair is the same point: no residual, no update.
    let at_truth = NormalEquations::from_partial_sums(&reduce_gpu(&gpu, &m, &params(&m, &truth, &truth, 0.1, 20.0)));
    assert!(at_truth.rms_residual_m() < 1e-6, "residual at the true pose {:e} m", at_truth.rms_residual_m());
    let x = at_truth.solve().expect("a well-conditioned room");
    assert!(x.amax() < 1e-6, "no update at the true pose: {x:?}");
    // From 1.5° and 15 mm off, five Gauss-Newton steps on the GPU sums return to the truth.
    let mut estimate = perturbed(&truth, 1.5, 15.0);
    for _ in 0..5 {
        let p = params(&m, &estimate, &truth, 0.1, 20.0);
        let g = reduce_gpu(&gpu, &m, &p);
        compare_systems(&g, &reduce_cpu(&m, &p)).unwrap_or_else(|e| panic!("GPU vs CPU during Gauss-Newton: {e}"));
        let x = NormalEquations::from_partial_sums(&g).solve().expect("solvable");
        estimate = twist_exp(DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5])) * estimate;
    }
    let error = truth.inverse() * estimate;
    let (mm, deg) = (error.translation_m.length() * 1e3, error.rotation_angle_rad().to_degrees());
    assert!(mm < 0.05 && deg < 0.005, "recovered to {mm:.4} mm / {deg:.5}°");
    finish(&gpu);
}

#[test]
fn rejection_thresholds_reject() {
    let truth = Se3::new(DQuat::from_axis_angle(DVec3::X, 0.1), DVec3::new(0.0, 0.02, 0.05));
    let m = room_maps(&truth);
    let gpu = gpu();
    let off = perturbed(&truth, 5.0, 30.0);
    let count = |p: &(TrackParams, TrackState)| {
        let (g, c) = (reduce_gpu(&gpu, &m, p), reduce_cpu(&m, p));
        compare_systems(&g, &c).unwrap_or_else(|e| panic!("{e}"));
        NormalEquations::from_partial_sums(&g).inliers
    };
    let loose = count(&params(&m, &off, &truth, 0.5, 60.0));
    let tight_distance = count(&params(&m, &off, &truth, 1e-4, 60.0));
    let tight_angle = count(&params(&m, &off, &truth, 0.5, 1.0));
    assert!(loose > 30_000, "loose thresholds pair most pixels ({loose})");
    assert!(tight_distance < loose / 100, "0.1 mm distance threshold rejects ({tight_distance} of {loose})");
    // Planes rotated 5° never match within 1°; only a few sphere pixels can meet a
    // neighbouring sphere normal.
    assert!(tight_angle < loose / 1000, "a 1° normal threshold rejects pairs 5° apart ({tight_angle} of {loose})");
    finish(&gpu);
}
