// SPDX-License-Identifier: MIT
//! `vertex_map`: (u - cx) * z / fx; GPU division may be up to 2.5 ulp off (Vulkan).

use webfusion_core::cpu;
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::vertex_map::VertexMapParams;
use webfusion_core::PinholeIntrinsics;
use webfusion_tests::{Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel, sample_frame};

use crate::synthetic::{K_SMALL, plane_depth_m};

/// 1e-6 relative (a micrometre at 1 m) plus 1e-7 m absolute for x, y near the optical axis.
const TOL: Tolerance = Tolerance { absolute: 1e-7, relative: 1e-6 };

fn run(k: PinholeIntrinsics, depth_m: &[f32]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let p = VertexMapParams { intrinsics: GpuIntrinsics::from(k) };
    let n = depth_m.len();
    let out = run_kernel(&gpu, &gpu.kernels.vertex_map, &p, &[bytemuck::cast_slice(depth_m)], &[16 * n], [k.width_px, k.height_px, 1]);
    let mut cpu_out = vec![[0.0; 4]; n];
    cpu::vertex_map(&p, depth_m, &mut cpu_out);
    finish(&gpu);
    (cast(&out[0]), cpu_out)
}

#[test]
fn fronto_parallel_plane_back_projects_exactly() {
    let k = K_SMALL;
    let mut depth_m = plane_depth_m(&k, 2.0, [0.0, 0.0, -1.0]);
    depth_m[5] = f32::NAN;
    let (g, c) = run(k, &depth_m);
    compare_vec4("vertex_in_camera", &g, &c, TOL).unwrap();
    assert!(g[5].iter().all(|v| v.is_nan()), "invalid depth gives an all-NaN vertex");
    for (i, v) in g.iter().enumerate().filter(|(i, _)| *i != 5) {
        let (u, vv) = ((i as u32 % k.width_px) as f32, (i as u32 / k.width_px) as f32);
        assert_eq!(v[2], 2.0, "z of pixel {i}");
        assert!((v[0] - (u - k.cx_px) * 2.0 / k.fx_px).abs() < 1e-5, "x of pixel {i}");
        assert!((v[1] - (vv - k.cy_px) * 2.0 / k.fy_px).abs() < 1e-5, "y of pixel {i}");
        assert_eq!(v[3], 1.0, "w of pixel {i}");
    }
    assert_negative_control_vec4("vertex_in_camera", &g, &c, TOL);
}

#[test]
fn real_frame_matches_cpu() {
    let (calib, frame) = sample_frame(3);
    let depth_m: Vec<f32> = frame.depth.units.iter().map(|&u| if u == 0 { f32::NAN } else { u as f32 * calib.metres_per_depth_unit() }).collect();
    let (g, c) = run(calib.intrinsics, &depth_m);
    compare_vec4("vertex_in_camera", &g, &c, TOL).unwrap();
    assert_negative_control_vec4("vertex_in_camera", &g, &c, TOL);
}
