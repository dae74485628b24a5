// SPDX-License-Identifier: MIT
//! `ransac_hypotheses`: each workgroup's sample, Kabsch pose and MSAC cost against the CPU
//! twin (the same samples, f32 poses within 1e-4, costs within 1e-3 relative), with negative
//! controls; on a synthetic scene with an exact motion among 70 % outliers the cheapest
//! hypothesis is the motion (within 0.1 mm and 0.01°), a scene of too few pairs has no usable
//! hypothesis, and on two real frames the GPU agrees with the twin too.

use glam::{DQuat, DVec3};
use webfusion_core::Se3;
use webfusion_core::cpu;
use webfusion_core::cpu::odometry::estimate::{CHI2_3DOF_95, IDENTITY, RANSAC_MAX_HYPOTHESES, RANSAC_NO_COST};
use webfusion_core::cpu::shared::{Mat4, pcg_hash, transform_point};
use webfusion_core::kernels::gpu_data::{FeaturePair, RansacParams, RigidEstimate};
use webfusion_core::odometry::rigid::RansacConfig;
use webfusion_tests::{SENTINEL_F32, Slot, cast, finish, gpu, run_kernel_slots};

/// A scene of `n` pairs whose first `outliers` have a random reference point and the rest
/// `truth` · src exactly (f32); points 1-3 m in front of the camera.
pub(crate) fn scene(n: usize, truth: &Se3, outliers: usize, seed: u32) -> Vec<FeaturePair> {
    let mut state = seed;
    let mut u = || {
        state = pcg_hash(state);
        state as f32 / u32::MAX as f32
    };
    let m = truth.to_cols_f32();
    (0..n)
        .map(|i| {
            let src = [u() * 2.0 - 1.0, u() * 1.5 - 0.75, 1.0 + 2.0 * u()];
            let dst = if i < outliers { [u() * 2.0 - 1.0, u() - 0.5, 1.0 + 2.0 * u()] } else { transform_point(&m, src) };
            FeaturePair { src: [src[0], src[1], src[2], 0.0], dst: [dst[0], dst[1], dst[2], 0.0], slots: [i as u32, i as u32, 10, 0] }
        })
        .collect()
}

/// The motion most tests use: 8.6° about y and 13 cm.
pub(crate) fn truth() -> Se3 {
    Se3::new(DQuat::from_rotation_y(0.15), DVec3::new(-0.08, 0.02, 0.1))
}

/// The default settings for a 525 px camera with `seed`.
pub(crate) fn params(seed: u32) -> RansacParams {
    RansacConfig::default().params(525.0, seed)
}

/// An estimate holding `n` pairs, as match_select leaves it.
pub(crate) fn estimate_of(n: usize) -> RigidEstimate {
    RigidEstimate { dst_from_src: IDENTITY, pairs: n as u32, best_hypothesis: RANSAC_MAX_HYPOTHESES, noise_scale: 1.0, cost: RANSAC_NO_COST, ..Default::default() }
}

/// Runs ransac_hypotheses on the GPU and its twin: ((poses, costs) GPU, (poses, costs) twin).
pub(crate) fn run(p: &RansacParams, pairs: &[FeaturePair], estimate: &RigidEstimate) -> ((Vec<Mat4>, Vec<f32>), (Vec<Mat4>, Vec<f32>)) {
    let gpu = gpu();
    let h = p.hypotheses as usize;
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.ransac_hypotheses,
        p,
        &[Slot::In(bytemuck::cast_slice(pairs)), Slot::In(bytemuck::bytes_of(estimate)), Slot::Out(64 * h), Slot::Out(4 * h)],
        [64 * p.hypotheses, 1, 1],
    );
    finish(&gpu);
    let mut poses = vec![[[0.0f32; 4]; 4]; h];
    let mut costs = vec![0.0f32; h];
    cpu::ransac_hypotheses(p, pairs, estimate, &mut poses, &mut costs);
    ((cast(&out[0]), cast(&out[1])), (poses, costs))
}

/// Poses within 1e-4 (rotation entries and metres), costs within 1e-3 relative (+0.01);
/// unusable hypotheses (cost RANSAC_NO_COST, a zero pose) must agree exactly.
pub(crate) fn compare(what: &str, g: &(Vec<Mat4>, Vec<f32>), c: &(Vec<Mat4>, Vec<f32>)) -> Result<usize, String> {
    let mut usable = 0;
    for (h, ((gp, gc), (cp, cc))) in g.0.iter().zip(&g.1).zip(c.0.iter().zip(&c.1)).enumerate() {
        if (*gc == RANSAC_NO_COST) != (*cc == RANSAC_NO_COST) {
            return Err(format!("{what}: hypothesis {h}: usable on one side only (GPU cost {gc:e}, twin {cc:e})"));
        }
        if *cc == RANSAC_NO_COST {
            if gp.as_flattened().iter().any(|v| *v != 0.0) {
                return Err(format!("{what}: hypothesis {h}: an unusable pose is not zero: {gp:?}"));
            }
            continue;
        }
        usable += 1;
        if let Some(k) = (0..16).find(|&k| !((gp.as_flattened()[k] - cp.as_flattened()[k]).abs() <= 1e-4)) {
            return Err(format!("{what}: hypothesis {h}: pose entry {k}: {} vs twin {}", gp.as_flattened()[k], cp.as_flattened()[k]));
        }
        if !((gc - cc).abs() <= 1e-3 * cc.abs() + 0.01) {
            return Err(format!("{what}: hypothesis {h}: cost {gc} vs twin {cc}"));
        }
    }
    if g.0.len() != c.0.len() {
        return Err(format!("{what}: {} vs {} hypotheses", g.0.len(), c.0.len()));
    }
    Ok(usable)
}

/// compare() passes, and fails for a moved pose, a moved cost, a sentinel and hypotheses
/// out of order.
fn assert_close_with_controls(what: &str, g: &(Vec<Mat4>, Vec<f32>), c: &(Vec<Mat4>, Vec<f32>)) -> usize {
    let usable = compare(what, g, c).unwrap();
    let h = c.1.iter().position(|&v| v != RANSAC_NO_COST).expect("a usable hypothesis");
    let mut moved = g.clone();
    moved.0[h][3][0] += 1e-3;
    let mut cost = g.clone();
    cost.1[h] *= 1.01;
    let mut sentinel = g.clone();
    sentinel.0[h][0][0] = SENTINEL_F32;
    let mut swapped = g.clone();
    swapped.0.rotate_left(1);
    swapped.1.rotate_left(1);
    for (case, bad) in [("a moved pose", moved), ("a moved cost", cost), ("a sentinel", sentinel), ("hypotheses out of order", swapped)] {
        assert!(compare(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
    usable
}

#[test]
fn the_cheapest_hypothesis_among_70_percent_outliers_is_the_motion() {
    let pairs = scene(200, &truth(), 140, 7);
    let p = params(11);
    let (g, c) = run(&p, &pairs, &estimate_of(pairs.len()));
    let usable = assert_close_with_controls("scene", &g, &c);
    let best = (0..g.1.len()).min_by(|&a, &b| g.1[a].total_cmp(&g.1[b])).unwrap();
    let error = truth().inverse().compose(&Se3::from_cols_f32(&g.0[best]));
    let (t_mm, r_deg) = (error.translation_m.length() * 1e3, error.rotation_angle_rad().to_degrees());
    eprintln!("{usable} of {} usable; best {best}: cost {}, error {t_mm:.4} mm {r_deg:.5}°", p.hypotheses, g.1[best]);
    assert!(t_mm < 0.1 && r_deg < 0.01, "best hypothesis {t_mm} mm, {r_deg}° from the motion");
    // The 140 outliers each cost at most the loose bound, the 60 inliers nearly nothing.
    let loose = CHI2_3DOF_95 * p.max_noise_scale * p.max_noise_scale;
    assert!(g.1[best] <= 140.0 * loose + 1.0, "cost {}", g.1[best]);
    assert!(usable > 200, "most samples are usable: {usable}");
}

#[test]
fn too_few_pairs_give_no_usable_hypothesis() {
    let pairs = scene(19, &truth(), 0, 3);
    let p = RansacParams { hypotheses: 32, ..params(1) };
    let (g, c) = run(&p, &pairs, &estimate_of(pairs.len()));
    assert_eq!(compare("19 pairs", &g, &c).unwrap(), 0);
    assert!(g.1.iter().all(|&v| v == RANSAC_NO_COST));
}

#[test]
fn two_real_frames_hypothesise_like_the_twin() {
    let (pairs, estimate) = super::ransac_refine::real_pairs(1, 0);
    let (g, c) = run(&params(1), &pairs, &estimate);
    let usable = assert_close_with_controls("frames 1 -> 0", &g, &c);
    eprintln!("{usable} usable hypotheses of {} pairs", estimate.pairs);
}
