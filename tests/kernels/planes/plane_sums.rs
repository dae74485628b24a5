// SPDX-License-Identifier: MIT
//! `plane_sums`: per (plane, chunk) moments against the CPU twin, on a real frame's labelled
//! keys with raw points (and their noise) and on a synthetic scene's inner-loop keys with the
//! normal peaks' footprints. Tolerance per set of moments, scaled to its own size (fused
//! multiply-adds reorder nothing but round differently): counts exact; means within 1 µm (1e-6
//! for normals); each scatter entry within 2e-5 of its matrix's trace (for the cross scatter,
//! of √(trace S · count)); area and noise within 2e-5 relative. Negative controls move each
//! kind of value past its tolerance, and leave a sentinel.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_to_sums};
use webfusion_core::cpu::planes::plane_sums::plane_sums_chunks;
use webfusion_core::kernels::plane_sums::PlaneSumsParams;
use webfusion_core::planes::{MAX_DISTANCE_PEAKS, NO_LABEL, reference};
use webfusion_core::sim::plane_scenes::PlaneScene;
use webfusion_tests::{SENTINEL_F32, Slot, cast, finish, gpu, run_kernel_slots};

use super::plane_keys::{inner_fixture, inner_params, label_params, masks_of, real_fixture, twin_keys};

/// Compares sets of moments (see the module doc for the tolerances).
pub(crate) fn compare_moments(what: &str, g: &[[f32; 4]], c: &[[f32; 4]]) -> Result<(), String> {
    if g.len() != c.len() || !c.len().is_multiple_of(PLANE_MOMENT_VEC4S) {
        return Err(format!("{what}: {} vs {} vec4", g.len(), c.len()));
    }
    for (set, (gm, cm)) in g.chunks(PLANE_MOMENT_VEC4S).zip(c.chunks(PLANE_MOMENT_VEC4S)).enumerate() {
        let trace = |m: &[[f32; 4]], i: usize| m[i][0].abs() + m[i][1].abs() + m[i][2].abs();
        let s_scale = 2e-5 * trace(cm, 3) + 1e-9;
        let np_scale = 2e-5 * (trace(cm, 3) * cm[0][0]).sqrt() + 1e-9;
        let noise_scale = 2e-5 * trace(cm, 8) + 1e-12;
        for (i, (gv, cv)) in gm.iter().zip(cm).enumerate() {
            for j in 0..4 {
                let (a, b) = (gv[j], cv[j]);
                let tol = match (i, j) {
                    (0, 0) => 0.0,
                    (0, _) => 2e-5 * b.abs() + 1e-12,
                    (1, _) => 1e-6,
                    (2, _) => 1e-6,
                    (3 | 4, _) => s_scale,
                    (5..=7, _) => np_scale,
                    _ => noise_scale,
                };
                if !((a - b).abs() <= tol) {
                    return Err(format!("{what}: set {set}, vec4 {i}.{j}: GPU {a} vs CPU {b} (tolerance {tol})"));
                }
            }
        }
    }
    Ok(())
}

/// The comparison must fail when a count, a mean, a scatter or a cross-scatter entry, an area
/// or a noise entry moves past its tolerance, or a value is left at the sentinel; `set` is a
/// set of moments with pixels.
pub(crate) fn assert_moments_controls(what: &str, g: &[[f32; 4]], c: &[[f32; 4]], set: usize) {
    compare_moments(what, g, c).unwrap();
    let base = set * PLANE_MOMENT_VEC4S;
    assert!(c[base][0] >= 3.0, "{what}: the control's set has pixels");
    for (i, j, delta) in [(0, 0, 1.0), (1, 2, 1e-5), (3, 0, 1e-3 * (c[base + 3][0] + c[base + 3][1] + c[base + 3][2]).abs()), (5, 1, 1e-3 * (c[base + 3][0] * c[base][0]).sqrt()), (0, 1, 1e-3 * c[base][1].abs())] {
        let mut bad = g.to_vec();
        bad[base + i][j] += delta;
        assert!(compare_moments(what, &bad, c).is_err(), "{what}: moved entry {i}.{j} accepted");
    }
    let mut bad = g.to_vec();
    bad[base + 8][2] = SENTINEL_F32;
    assert!(compare_moments(what, &bad, c).is_err(), "{what}: a sentinel accepted");
}

/// Runs plane_sums for `planes` planes on the GPU and its twin (with the chunk masks of
/// `keys`); returns (GPU, twin) partials.
pub(crate) fn run(params: &PlaneSumsParams, keys: &[u32], vertex: &[[f32; 4]], normal: &[[f32; 4]], raw: &[f32], normals: &[[f32; 4]], planes: u32) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let masks = masks_of(keys);
    let chunks = plane_sums_chunks((params.width_px * params.height_px) as usize);
    let size = planes as usize * chunks * PLANE_MOMENT_VEC4S;
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_sums,
        params,
        &[Slot::In(bytemuck::cast_slice(keys)), Slot::In(bytemuck::cast_slice(vertex)), Slot::In(bytemuck::cast_slice(normal)), Slot::In(bytemuck::cast_slice(raw)), Slot::In(bytemuck::cast_slice(normals)), Slot::Out(16 * size), Slot::In(bytemuck::cast_slice(&masks))],
        [(64 * chunks) as u32, planes, 1],
    );
    finish(&gpu);
    let mut c = vec![[0.0f32; 4]; size];
    cpu::plane_sums(params, keys, vertex, normal, raw, normals, &mut c, &masks, planes);
    (cast(&out[0]), c)
}

pub(crate) fn sums_params(keys: &webfusion_core::kernels::plane_keys::PlaneKeysParams, use_raw: bool, normal_shift: u32) -> PlaneSumsParams {
    PlaneSumsParams { width_px: keys.width_px, height_px: keys.height_px, use_raw: u32::from(use_raw), normal_shift, fx_px: keys.fx_px, fy_px: keys.fy_px, cx_px: keys.cx_px, cy_px: keys.cy_px }
}

/// The real frame's labelled keys (twin) with raw points: (params, keys).
pub(crate) fn real_keys(pre: &webfusion_core::cpu::preprocess::chain::CpuPreprocessed, planes: &[[f32; 4]], labels: &[u32]) -> (PlaneSumsParams, Vec<u32>) {
    let kp = label_params(&pre.levels[0], true);
    let (keys, _) = twin_keys(&kp, labels, &[[0; 4]], &[0], &pre.depth_unfiltered_m, planes);
    (sums_params(&kp, true, 0), keys)
}

/// The first set of moments with pixels.
pub(crate) fn first_full(c: &[[f32; 4]]) -> usize {
    c.chunks(PLANE_MOMENT_VEC4S).position(|m| m[0][0] >= 3.0).expect("some set has pixels")
}

#[test]
fn a_real_frame_sums_like_the_twin() {
    let (pre, planes, labels) = real_fixture();
    let (params, keys) = real_keys(&pre, &planes, &labels);
    let full = &pre.levels[0];
    let (g, c) = run(&params, &keys, &full.vertex_in_camera, &full.normal_in_camera, &pre.depth_unfiltered_m, &planes, planes.len() as u32);
    assert_moments_controls("real frame", &g, &c, first_full(&c));
    // Every keyed pixel is counted once.
    let counted: f32 = c.chunks(PLANE_MOMENT_VEC4S).map(|m| m[0][0]).sum();
    assert_eq!(counted as usize, keys.iter().filter(|&&k| k != NO_LABEL).count());
    let with_noise = c.chunks(PLANE_MOMENT_VEC4S).filter(|m| m[0][0] > 0.0).all(|m: &[[f32; 4]]| m[8][2] > 0.0);
    assert!(with_noise, "raw points carry their model noise");
}

#[test]
fn inner_loop_sums_use_the_peaks_footprints() {
    let f = inner_fixture(&PlaneScene::box_on_floor(), Some(3));
    let kp = inner_params(&f.level);
    let (keys, _) = twin_keys(&kp, &f.assignment, &f.intervals, &f.interval_count, &[0.0], &[[0.0; 4]]);
    let params = sums_params(&kp, false, MAX_DISTANCE_PEAKS.trailing_zeros());
    let planes = (f.peaks.len() * MAX_DISTANCE_PEAKS) as u32;
    let (g, c) = run(&params, &keys, &f.level.vertex_in_camera, &f.level.normal_in_camera, &[0.0], &f.peaks, planes);
    assert_moments_controls("box, inner loop", &g, &c, first_full(&c));
    // No raw points, no noise; each set is one surface (the box's faces and the floor, noisy
    // by 1.5 cm at most: its points within 2 cm RMS of their fit).
    for m in c.chunks(PLANE_MOMENT_VEC4S).filter(|m| m[0][0] >= 3.0) {
        let m: PlaneMoments = m.try_into().unwrap();
        assert_eq!(m[8], [0.0; 4]);
        assert!(m[0][1] > 0.0, "area");
        let fit = reference::fit(&plane_moments_to_sums(&m)).expect("a fit");
        assert!(fit.rms_m < 0.02, "rms {} m", fit.rms_m);
    }
}
