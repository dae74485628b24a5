// SPDX-License-Identifier: MIT
//! `vertex_gradients`: plain subtractions, correctly rounded on both sides: exact.

use webfusion_core::cpu;
use webfusion_core::kernels::vertex_gradients::VertexGradientsParams;
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;

const TOL: Tolerance = Tolerance::EXACT;

pub(crate) fn run(w: u32, h: u32, vertex: &[[f32; 4]]) -> ((Vec<[f32; 4]>, Vec<[f32; 4]>), (Vec<[f32; 4]>, Vec<[f32; 4]>)) {
    let gpu = gpu();
    let p = VertexGradientsParams { width_px: w, height_px: h, ..Default::default() };
    let n = vertex.len();
    let out = run_kernel(&gpu, &gpu.kernels.vertex_gradients, &p, &[bytemuck::cast_slice(vertex)], &[16 * n, 16 * n], [w, h, 1]);
    let (mut cx, mut cy) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
    cpu::vertex_gradients(&p, vertex, &mut cx, &mut cy);
    finish(&gpu);
    ((cast(&out[0]), cast(&out[1])), (cx, cy))
}

#[test]
fn synthetic_grid_has_exact_gradients() {
    // Vertices on an exact grid: x = 0.25 * u, y = 0.5 * v, z = 3: gradients (0.5, 0, 0)
    // and (0, 1, 0) inside, invalid on the border and around the hole at (4, 4).
    let (w, h) = (12u32, 10u32);
    let mut vertex: Vec<[f32; 4]> = (0..w * h).map(|i| [0.25 * (i % w) as f32, 0.5 * (i / w) as f32, 3.0, 1.0]).collect();
    vertex[(4 * w + 4) as usize] = [f32::NAN; 4];
    let ((gx, gy), (cx, cy)) = run(w, h, &vertex);
    compare_vec4("grad_x", &gx, &cx, TOL).unwrap();
    compare_vec4("grad_y", &gy, &cy, TOL).unwrap();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            let border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
            let near_hole = (x as i32 - 4).abs() + (y as i32 - 4).abs() <= 1;
            if border || near_hole {
                assert!(gx[i][0].is_nan() && gy[i][0].is_nan(), "({x}, {y}) must be invalid");
            } else {
                assert_eq!(gx[i], [0.5, 0.0, 0.0, 0.0], "grad_x at ({x}, {y})");
                assert_eq!(gy[i], [0.0, 1.0, 0.0, 0.0], "grad_y at ({x}, {y})");
            }
        }
    }
    assert_negative_control_vec4("grad_x", &gx, &cx, TOL);
}

#[test]
fn real_frame_matches_cpu() {
    let chain = real_cpu_chain();
    let level = &chain.levels[0];
    let k = level.intrinsics;
    let ((gx, gy), (cx, cy)) = run(k.width_px, k.height_px, &level.vertex_in_camera);
    compare_vec4("grad_x", &gx, &cx, TOL).unwrap();
    compare_vec4("grad_y", &gy, &cy, TOL).unwrap();
    assert_negative_control_vec4("grad_y", &gy, &cy, TOL);
}
