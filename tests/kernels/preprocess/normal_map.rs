// SPDX-License-Identifier: MIT
//! `normal_map`: cross product, sqrt and division; components within 2e-6.

use webfusion_core::cpu;
use webfusion_core::kernels::normal_map::NormalMapParams;
use webfusion_core::preprocess::DEFAULT_MIN_CROSS_NORM_SQ;
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;
use crate::synthetic::{K_SMALL, plane_depth_m};

/// Unit-vector components: 2e-6 absolute.
const TOL: Tolerance = Tolerance { absolute: 2e-6, relative: 0.0 };

fn run(w: u32, h: u32, vertex: &[[f32; 4]], gx: &[[f32; 4]], gy: &[[f32; 4]]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let p = NormalMapParams { width_px: w, height_px: h, min_cross_norm_sq: DEFAULT_MIN_CROSS_NORM_SQ, ..Default::default() };
    let n = vertex.len();
    let inputs: [&[u8]; 3] = [bytemuck::cast_slice(vertex), bytemuck::cast_slice(gx), bytemuck::cast_slice(gy)];
    let out = run_kernel(&gpu, &gpu.kernels.normal_map, &p, &inputs, &[16 * n], [w, h, 1]);
    let mut c = vec![[0.0; 4]; n];
    cpu::normal_map(&p, vertex, gx, gy, &mut c);
    finish(&gpu);
    (cast(&out[0]), c)
}

fn cpu_vertices_and_gradients(depth_m: &[f32]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<[f32; 4]>) {
    use webfusion_core::kernels::{GpuIntrinsics, vertex_gradients::VertexGradientsParams, vertex_map::VertexMapParams};
    let k = K_SMALL;
    let n = k.pixel_count();
    let mut v = vec![[0.0; 4]; n];
    cpu::vertex_map(&VertexMapParams { intrinsics: GpuIntrinsics::from(k) }, depth_m, &mut v);
    let (mut gx, mut gy) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
    cpu::vertex_gradients(&VertexGradientsParams { width_px: k.width_px, height_px: k.height_px, ..Default::default() }, &v, &mut gx, &mut gy);
    (v, gx, gy)
}

#[test]
fn tilted_plane_has_its_exact_normal_facing_the_camera() {
    let k = K_SMALL;
    for normal in [[0.0f32, 0.0, -1.0], [0.6, 0.0, -0.8], [0.0, -0.28, -0.96], [-0.48, 0.36, -0.8]] {
        let depth_m = plane_depth_m(&k, 2.0, normal);
        let (v, gx, gy) = cpu_vertices_and_gradients(&depth_m);
        let (g, c) = run(k.width_px, k.height_px, &v, &gx, &gy);
        compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
        let mut n_valid = 0;
        for n in g.iter().filter(|n| !n[0].is_nan()) {
            n_valid += 1;
            let err = ((n[0] - normal[0]).powi(2) + (n[1] - normal[1]).powi(2) + (n[2] - normal[2]).powi(2)).sqrt();
            assert!(err < 1e-3, "plane normal {normal:?} estimated as {n:?}");
        }
        assert_eq!(n_valid, (k.width_px as usize - 2) * (k.height_px as usize - 2), "every interior pixel gets a normal");
        assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
    }
}

#[test]
fn real_frame_matches_cpu() {
    let chain = real_cpu_chain();
    let level = &chain.levels[0];
    let k = level.intrinsics;
    let (g, c) = run(k.width_px, k.height_px, &level.vertex_in_camera, &level.grad_x, &level.grad_y);
    compare_vec4("normal_in_camera", &g, &c, TOL).unwrap();
    assert_negative_control_vec4("normal_in_camera", &g, &c, TOL);
}
