// SPDX-License-Identifier: MIT
//! `plane_fit`: f32 plane fits (Jacobi, noise correction, bend) against the CPU twin, on a real
//! frame's planes, a small noise-free patch 3.5 m away (the ill-conditioned case: 10 cm of
//! extent against 3.5 m of offset) and sets too small to fit; and the twin against the f64
//! reference fit (`planes::reference::fit`) and, for the patch, against its exact plane.
//! Tolerances: counts and the valid flag exact; normals within 1e-5 per component, offsets and
//! centroids within 1e-5 m; in-plane axes parallel within 1e-5 (their sign is arbitrary);
//! variances 1e-4 relative; rms 1e-6 m; bend 1e-3°; area 1e-5 relative. Five negative
//! controls.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::moments::{PlaneMoments, plane_moments_combine, plane_moments_point, plane_moments_to_sums, plane_moments_zero};
use webfusion_core::cpu::planes::plane_fit::{PLANE_FIT_VEC4S, plane_fit_moments};
use webfusion_core::kernels::plane_fit::PlaneFitParams;
use webfusion_core::planes::reference;
use webfusion_tests::{SENTINEL_F32, Slot, cast, finish, gpu, run_kernel_slots};

use super::plane_sums_reduce::real_moments;

fn run(moments: &[PlaneMoments]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let params = PlaneFitParams { plane_count: moments.len() as u32, ..Default::default() };
    let flat: Vec<[f32; 4]> = moments.iter().flatten().copied().collect();
    let size = moments.len() * PLANE_FIT_VEC4S;
    let out = run_kernel_slots(&gpu, &gpu.kernels.plane_fit, &params, &[Slot::In(bytemuck::cast_slice(&flat)), Slot::Out(16 * size)], [moments.len() as u32, 1, 1]);
    finish(&gpu);
    let mut c = vec![[0.0f32; 4]; size];
    cpu::plane_fit(&params, &flat, &mut c);
    (cast(&out[0]), c)
}

fn compare_fits(what: &str, g: &[[f32; 4]], c: &[[f32; 4]]) -> Result<(), String> {
    if g.len() != c.len() {
        return Err(format!("{what}: {} vs {} vec4", g.len(), c.len()));
    }
    for (k, (gf, cf)) in g.chunks(PLANE_FIT_VEC4S).zip(c.chunks(PLANE_FIT_VEC4S)).enumerate() {
        let near = |a: f32, b: f32, tol: f32| (a - b).abs() <= tol;
        let err = |what_: &str| Err(format!("{what}: plane {k}: {what_}: GPU {gf:?} vs CPU {cf:?}"));
        if gf[4][3] != cf[4][3] || gf[1][3] != cf[1][3] {
            return err("valid flag or count");
        }
        if !(0..4).all(|i| near(gf[0][i], cf[0][i], 1e-5)) || !(0..3).all(|i| near(gf[1][i], cf[1][i], 1e-5)) {
            return err("normal, offset or centroid");
        }
        for a in 2..4 {
            let dot: f32 = (0..3).map(|i| gf[a][i] * cf[a][i]).sum();
            if cf[4][3] != 0.0 && !(dot.abs() >= 1.0 - 1e-5) || !near(gf[a][3], cf[a][3], 1e-4 * cf[a][3].abs() + 1e-12) {
                return err("in-plane axis or its variance");
            }
        }
        if !near(gf[4][0], cf[4][0], 1e-6) || !near(gf[4][1], cf[4][1], 1e-3) || !near(gf[4][2], cf[4][2], 1e-5 * cf[4][2].abs()) {
            return err("rms, bend or area");
        }
    }
    Ok(())
}

fn assert_fits_controls(what: &str, g: &[[f32; 4]], c: &[[f32; 4]]) {
    compare_fits(what, g, c).unwrap();
    let k = c.chunks(PLANE_FIT_VEC4S).position(|f| f[4][3] == 1.0).expect("a fitted plane") * PLANE_FIT_VEC4S;
    let mut cases: Vec<(&str, Vec<[f32; 4]>)> = Vec::new();
    let mut bad = g.to_vec();
    bad[k][0] += 1e-3;
    cases.push(("a tilted normal", bad));
    let mut bad = g.to_vec();
    bad[k][3] += 1e-3;
    cases.push(("a moved offset", bad));
    let mut bad = g.to_vec();
    bad.swap(k + 2, k + 3);
    cases.push(("swapped axes", bad));
    let mut bad = g.to_vec();
    bad[k + 4][3] = 0.0;
    cases.push(("an unfitted plane", bad));
    let mut bad = g.to_vec();
    bad[k + 4][1] = SENTINEL_F32;
    cases.push(("a sentinel", bad));
    for (case, bad) in cases {
        assert!(compare_fits(what, &bad, c).is_err(), "{what}: the comparison accepted {case}");
    }
}

/// The angle between two directions, degrees (atan2 of the cross and dot products: acos of a
/// dot product near 1 turns f32 rounding of the lengths into a hundredth of a degree).
pub(crate) fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    let cross = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let sin = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    sin.atan2(a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).to_degrees()
}

/// A 10 cm x 10 cm patch of the plane through (0.3, -0.2, 3.5) with normal `n`, 21 x 21 points,
/// noise-free.
fn far_patch(n: [f32; 3]) -> PlaneMoments {
    let (t, b) = {
        let t = [n[1], -n[0], 0.0];
        let l = (t[0] * t[0] + t[1] * t[1]).sqrt();
        let t = t.map(|x| x / l);
        (t, [n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]])
    };
    let mut m = plane_moments_zero();
    for i in 0..21 {
        for j in 0..21 {
            let (u, v) = ((i as f32 - 10.0) * 0.005, (j as f32 - 10.0) * 0.005);
            let p = [0.3 + u * t[0] + v * b[0], -0.2 + u * t[1] + v * b[1], 3.5 + u * t[2] + v * b[2]];
            m = plane_moments_combine(&m, &plane_moments_point(p, n, 1e-4, 0.0));
        }
    }
    m
}

#[test]
fn real_planes_fit_like_the_twin_and_like_f64() {
    let (_, _, sets) = real_moments();
    let (g, c) = run(&sets);
    assert_fits_controls("real frame", &g, &c);
    for (k, m) in sets.iter().enumerate() {
        let f32fit = plane_fit_moments(m);
        let f64fit = reference::fit(&plane_moments_to_sums(m)).unwrap();
        let angle = angle_deg([0, 1, 2].map(|i| f64::from(f32fit[0][i])), f64fit.normal);
        let offset = (f64::from(f32fit[0][3]) - f64fit.offset_m).abs();
        eprintln!("plane {k}: f32 vs f64 fit: normal {angle:.5}°, offset {:.4} mm, bend {:.3} vs {:.3}°, rms {:.3} vs {:.3} mm", offset * 1e3, f32fit[4][1], f64fit.bend_deg, f32fit[4][0] * 1e3, f64fit.rms_m * 1e3);
        assert!(angle < 0.01 && offset < 1e-4, "plane {k}: normal and offset");
        assert!((f64::from(f32fit[4][1]) - f64fit.bend_deg).abs() < 0.05, "plane {k}: bend");
        assert!((f64::from(f32fit[4][0]) - f64fit.rms_m).abs() < 1e-3 * f64fit.rms_m + 1e-6, "plane {k}: rms");
    }
}

#[test]
fn a_small_far_patch_fits_exactly_and_tiny_sets_do_not_fit() {
    let n = {
        let n = [0.2f32, -0.3, -0.9];
        let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        n.map(|x| x / l)
    };
    let patch = far_patch(n);
    let two = plane_moments_combine(&plane_moments_point([0.0, 0.0, 1.0], n, 1e-4, 0.0), &plane_moments_point([0.1, 0.0, 1.0], n, 1e-4, 0.0));
    let (g, c) = run(&[patch, two, plane_moments_zero()]);
    assert_fits_controls("far patch", &g, &c);
    let angle = angle_deg([0, 1, 2].map(|i| f64::from(g[0][i])), n.map(f64::from));
    let d = -(n[0] * 0.3 - n[1] * 0.2 + n[2] * 3.5);
    eprintln!("far patch: normal {angle:.5}° off, offset {:.4} mm off, rms {:.4} mm", (g[0][3] - d).abs() * 1e3, g[4][0] * 1e3);
    assert!(angle < 0.01 && (g[0][3] - d).abs() < 1e-4 && g[4][0] < 1e-4, "the patch's plane");
    assert!(g[4][1] < 0.01, "a plane does not bend");
    assert_eq!(&g[PLANE_FIT_VEC4S..], &[[0.0f32; 4]; 2 * PLANE_FIT_VEC4S][..], "two points and none fit nothing");
}

