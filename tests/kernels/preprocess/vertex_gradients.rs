// SPDX-License-Identifier: MIT
//! `vertex_gradients`: central differences (plain subtractions, exact), then the along-x
//! Gaussian pass (GPU `exp` weights: a few ulp of the gradient).

use webfusion_core::cpu;
use webfusion_core::kernels::vertex_gradients::{self, VertexGradientsParams};
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel};

use crate::preprocess::chain::real_cpu_chain;

/// Gradients are metres between neighbours (~1e-3..1e-1): 1e-8 m plus 2e-6 relative.
pub(crate) const TOL: Tolerance = Tolerance { absolute: 1e-8, relative: 2e-6 };

type Pair = (Vec<[f32; 4]>, Vec<[f32; 4]>);

/// Both outputs, GPU then CPU.
pub(crate) fn run(p: &VertexGradientsParams, vertex: &[[f32; 4]]) -> (Pair, Pair) {
    let gpu = gpu();
    let n = vertex.len();
    let out = run_kernel(&gpu, &gpu.kernels.vertex_gradients, p, &[bytemuck::cast_slice(vertex)], &[16 * n, 16 * n], vertex_gradients::invocations(p.width_px, p.height_px));
    let (mut cx, mut cy) = (vec![[0.0; 4]; n], vec![[0.0; 4]; n]);
    cpu::vertex_gradients(p, vertex, &mut cx, &mut cy);
    finish(&gpu);
    ((cast(&out[0]), cast(&out[1])), (cx, cy))
}

#[test]
fn a_grid_has_exact_gradients_and_holes_are_skipped() {
    // Vertices on an exact grid: x = 0.25 * u, y = 0.5 * v, z = 3: gradients (0.5, 0, 0)
    // and (0, 1, 0) inside (smoothing averages equal values), invalid on the border and
    // around the hole at (4, 4); the smoothing's taps skip the hole. An odd width leaves the
    // last invocation of each row (two pixels each) one pixel.
    for (w, h, radius_px, exact) in [(12u32, 10u32, 0, 0.0), (12, 10, 2, 1e-6), (13, 11, 2, 1e-6)] {
        let mut vertex: Vec<[f32; 4]> = (0..w * h).map(|i| [0.25 * (i % w) as f32, 0.5 * (i / w) as f32, 3.0, 1.0]).collect();
        vertex[(4 * w + 4) as usize] = [f32::NAN; 4];
        let p = VertexGradientsParams { width_px: w, height_px: h, radius_px, sigma_px: 1.5 };
        let ((gx, gy), (cx, cy)) = run(&p, &vertex);
        compare_vec4("grad_x", &gx, &cx, TOL).unwrap();
        compare_vec4("grad_y", &gy, &cy, TOL).unwrap();
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let border = x == 0 || y == 0 || x == w - 1 || y == h - 1;
                let near_hole = (x as i32 - 4).abs() + (y as i32 - 4).abs() <= 1;
                if border || near_hole {
                    assert!(gx[i][0].is_nan() && gy[i][0].is_nan(), "radius {radius_px}: ({x}, {y}) must be invalid");
                } else {
                    let (a, b) = (gx[i], gy[i]);
                    assert!((a[0] - 0.5).abs() <= exact && a[1] == 0.0 && a[2] == 0.0 && a[3] == 0.0, "radius {radius_px}: grad_x at ({x}, {y}) {a:?}");
                    assert!(b[0] == 0.0 && (b[1] - 1.0).abs() <= exact && b[2] == 0.0, "radius {radius_px}: grad_y at ({x}, {y}) {b:?}");
                }
            }
        }
        assert_negative_control_vec4("grad_x", &gx, &cx, TOL);
    }
}

#[test]
fn real_frame_matches_cpu() {
    let level = &real_cpu_chain().levels[0];
    let k = level.intrinsics;
    for radius_px in [0, 2, 5] {
        let p = VertexGradientsParams { width_px: k.width_px, height_px: k.height_px, radius_px, sigma_px: 1.5 };
        let ((gx, gy), (cx, cy)) = run(&p, &level.vertex_in_camera);
        compare_vec4("grad_x", &gx, &cx, TOL).unwrap();
        let stats = compare_vec4("grad_y", &gy, &cy, TOL).unwrap();
        eprintln!("radius {radius_px}: {stats:?}");
        assert_negative_control_vec4("grad_y", &gy, &cy, TOL);
    }
}
