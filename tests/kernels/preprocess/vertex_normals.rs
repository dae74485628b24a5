// SPDX-License-Identifier: MIT
//! `vertex_normals`: cross product, sqrt and division after the central differences (radius 0)
//! or after `vertex_gradients` and the along-y Gaussian pass (GPU `exp` weights, a few ulp).
//! Components within 1e-5 of the CPU twin.

use webfusion_core::cpu;
use webfusion_core::kernels::{vertex_gradients::VertexGradientsParams, vertex_normals::VertexNormalsParams};
use webfusion_core::preprocess::{DEFAULT_MIN_CROSS_NORM_SQ, GradientSmoothingConfig, MAX_GRADIENT_SMOOTH_RADIUS_PX, PreprocessConfig};
use webfusion_core::{Error, cpu::preprocess::chain::CpuPyramidLevel};
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel, sample_frame};

use crate::preprocess::chain::real_cpu_chain;
use crate::synthetic::{K_SMALL, plane_depth_m};

/// Unit-vector components.
const TOL: Tolerance = Tolerance { absolute: 1e-5, relative: 0.0 };

fn params(w: u32, h: u32, radius_px: u32) -> VertexNormalsParams {
    VertexNormalsParams { width_px: w, height_px: h, radius_px, sigma_px: 1.5, min_cross_norm_sq: DEFAULT_MIN_CROSS_NORM_SQ, ..Default::default() }
}

/// The normals of `vertex`, GPU then CPU, each from its own gradients (`vertex_gradients` first
/// when smoothing).
fn run(p: &VertexNormalsParams, vertex: &[[f32; 4]]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let n = vertex.len();
    let ((gx, gy), (cx, cy)) = if p.radius_px > 0 {
        let gp = VertexGradientsParams { width_px: p.width_px, height_px: p.height_px, radius_px: p.radius_px, sigma_px: p.sigma_px };
        let (g, c) = crate::preprocess::vertex_gradients::run(&gp, vertex);
        compare_vec4("grad_x", &g.0, &c.0, crate::preprocess::vertex_gradients::TOL).unwrap();
        (g, c)
    } else {
        // Unread at radius 0: sentinels.
        let s = vec![[webfusion_tests::SENTINEL_F32; 4]; n];
        ((s.clone(), s.clone()), (s.clone(), s))
    };
    let gpu = gpu();
    let inputs: [&[u8]; 3] = [bytemuck::cast_slice(vertex), bytemuck::cast_slice(&gx), bytemuck::cast_slice(&gy)];
    let out = run_kernel(&gpu, &gpu.kernels.vertex_normals, p, &inputs, &[16 * n], [p.width_px, p.height_px, 1]);
    let mut c = vec![[0.0; 4]; n];
    cpu::vertex_normals(p, vertex, &cx, &cy, &mut c);
    finish(&gpu);
    (cast(&out[0]), c)
}

fn vertices(depth_m: &[f32]) -> Vec<[f32; 4]> {
    use webfusion_core::kernels::{GpuIntrinsics, vertex_map::VertexMapParams};
    let mut v = vec![[0.0; 4]; depth_m.len()];
    cpu::vertex_map(&VertexMapParams { intrinsics: GpuIntrinsics::from(K_SMALL) }, depth_m, &mut v);
    v
}

fn angle_error(n: &[f32; 4], want: [f32; 3]) -> f32 {
    ((n[0] - want[0]).powi(2) + (n[1] - want[1]).powi(2) + (n[2] - want[2]).powi(2)).sqrt()
}

#[test]
fn tilted_plane_has_its_exact_normal_facing_the_camera_at_every_radius() {
    // 80x60: the last row of 16x16 workgroups is partial.
    let k = K_SMALL;
    for radius in [0, 2, 5] {
        for normal in [[0.0f32, 0.0, -1.0], [0.6, 0.0, -0.8], [0.0, -0.28, -0.96], [-0.48, 0.36, -0.8]] {
            let v = vertices(&plane_depth_m(&k, 2.0, normal));
            let (g, c) = run(&params(k.width_px, k.height_px, radius), &v);
            compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
            let mut n_valid = 0;
            for n in g.iter().filter(|n| !n[0].is_nan()) {
                n_valid += 1;
                assert!(angle_error(n, normal) < 1e-3, "radius {radius}: plane normal {normal:?} estimated as {n:?}");
            }
            assert_eq!(n_valid, (k.width_px as usize - 2) * (k.height_px as usize - 2), "radius {radius}: every interior pixel gets a normal");
            assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
        }
    }
}

#[test]
fn holes_are_skipped_not_smeared() {
    // A fronto-parallel plane with a hole over the corner where four 16x16 workgroups meet (a
    // tilted plane on the right, beyond every tap of the checked pixels, keeps the comparison
    // with the twin from being one of constants): smoothing must skip the hole's missing
    // gradients, so the plane's normal stays exact right up to them, and a pixel whose own
    // gradient is missing gets no normal from its neighbours'.
    let k = K_SMALL;
    let flat = plane_depth_m(&k, 2.0, [0.0, 0.0, -1.0]);
    let tilted = plane_depth_m(&k, 2.0, [0.6, 0.0, -0.8]);
    let w = k.width_px as usize;
    let mut depth: Vec<f32> = (0..flat.len()).map(|i| if i % w < 48 { flat[i] } else { tilted[i] }).collect();
    for y in 14..18 {
        for x in 14..19 {
            depth[y * w + x] = f32::NAN;
        }
    }
    let v = vertices(&depth);
    let (g, c) = run(&params(k.width_px, k.height_px, 2), &v);
    compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
    for y in 1..k.height_px as usize - 1 {
        for x in 1..45 {
            let i = y * w + x;
            // A gradient reads the 4-neighbourhood: invalid next to the hole.
            let near_hole = (13..=18).contains(&y) && (13..=19).contains(&x) && !((y == 13 || y == 18) && (x == 13 || x == 19));
            if near_hole {
                assert!(g[i][0].is_nan(), "({x}, {y}) lacks a gradient and must have no normal, got {:?}", g[i]);
            } else {
                assert!(angle_error(&g[i], [0.0, 0.0, -1.0]) < 1e-5, "({x}, {y}): {:?}", g[i]);
            }
        }
    }
    assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
}

#[test]
fn real_frame_matches_cpu_at_every_level_and_radius() {
    let chain = real_cpu_chain();
    for level in &chain.levels {
        let CpuPyramidLevel { intrinsics: k, vertex_in_camera, .. } = level;
        for radius in [0, 2, MAX_GRADIENT_SMOOTH_RADIUS_PX] {
            let (g, c) = run(&params(k.width_px, k.height_px, radius), vertex_in_camera);
            let stats = compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
            eprintln!("{}x{} radius {radius}: {stats:?}", k.width_px, k.height_px);
            assert!((stats.compared - stats.invalid) / 4 > k.pixel_count() / 2, "mostly valid normals");
            assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
        }
    }
}

#[test]
fn odd_sizes_match_cpu() {
    // Each invocation of `vertex_gradients` takes two pixels along x: an odd width leaves the
    // last of each row one pixel, whose smoothed gradients the normals read.
    let level = &real_cpu_chain().levels[0];
    let (w, h) = (77u32, 41u32);
    let crop: Vec<[f32; 4]> = (0..h).flat_map(|y| (0..w).map(move |x| ((y + 200) * level.intrinsics.width_px + x + 300) as usize)).map(|i| level.vertex_in_camera[i]).collect();
    for radius in [0, 2] {
        let (g, c) = run(&params(w, h, radius), &crop);
        let stats = compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
        assert!((stats.compared - stats.invalid) / 4 > (w * h) as usize / 2, "radius {radius}: mostly valid normals");
        assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
    }
}

#[test]
fn a_radius_beyond_the_limit_is_refused() {
    let gpu = gpu();
    let (calib, _) = sample_frame(0);
    let config = PreprocessConfig { gradient_smoothing: Some(GradientSmoothingConfig { radius_px: MAX_GRADIENT_SMOOTH_RADIUS_PX + 1, sigma_px: 2.0 }), ..PreprocessConfig::default() };
    match webfusion_core::preprocess::DepthPreprocessor::new(&gpu, calib, config) {
        Err(Error::InvalidConfig(m)) => assert!(m.contains("radius"), "{m}"),
        other => panic!("expected InvalidConfig, got {other:?}"),
    }
    finish(&gpu);
}
