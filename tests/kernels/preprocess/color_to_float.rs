// SPDX-License-Identifier: MIT
//! `color_to_float`: byte / 255 (GPU division within 2.5 ulp) and a 3-term dot product.

use webfusion_core::cpu;
use webfusion_core::cpu::shared::pack_bytes;
use webfusion_core::kernels::color_to_float::ColorToFloatParams;
use webfusion_tests::{Tolerance, assert_negative_control, assert_negative_control_vec4, cast, compare_f32, compare_vec4, finish, gpu, run_kernel, sample_frame};

/// Values in [0, 1]: 3e-7 absolute (a few ulp at 1.0).
const TOL: Tolerance = Tolerance { absolute: 3e-7, relative: 0.0 };

fn run(w: u32, h: u32, rgb8: &[u8]) -> ((Vec<[f32; 4]>, Vec<f32>), (Vec<[f32; 4]>, Vec<f32>)) {
    let gpu = gpu();
    let p = ColorToFloatParams { width_px: w, height_px: h, ..Default::default() };
    let packed = pack_bytes(rgb8);
    let n = (w * h) as usize;
    let out = run_kernel(&gpu, &gpu.kernels.color_to_float, &p, &[bytemuck::cast_slice(&packed)], &[16 * n, 4 * n], [w, h, 1]);
    let (mut c, mut i) = (vec![[0.0; 4]; n], vec![0.0; n]);
    cpu::color_to_float(&p, &packed, &mut c, &mut i);
    finish(&gpu);
    ((cast(&out[0]), cast(&out[1])), (c, i))
}

#[test]
fn every_byte_value_converts_exactly() {
    // 256 x 1 pixels: pixel i = (i, 255 - i, i / 2); odd byte count per row exercises packing.
    let rgb8: Vec<u8> = (0..256u32).flat_map(|i| [i as u8, (255 - i) as u8, (i / 2) as u8]).collect();
    let ((gc, gi), (cc, ci)) = run(256, 1, &rgb8);
    compare_vec4("color", &gc, &cc, TOL).unwrap();
    compare_f32("intensity", &gi, &ci, TOL).unwrap();
    for (i, c) in gc.iter().enumerate() {
        assert!((c[0] - i as f32 / 255.0).abs() < 1e-6 && (c[1] - (255 - i) as f32 / 255.0).abs() < 1e-6, "pixel {i}: {c:?}");
        assert_eq!(c[3], 1.0, "alpha of pixel {i}");
    }
    assert!((gi[255] - (0.299 + 0.114 * 127.0 / 255.0)).abs() < 1e-6, "BT.601 luma of (255, 0, 127)");
    assert_negative_control_vec4("color", &gc, &cc, TOL);
    assert_negative_control("intensity", &gi, &ci, TOL);
}

#[test]
fn real_frame_matches_cpu() {
    let (calib, frame) = sample_frame(0);
    let k = calib.intrinsics;
    let ((gc, gi), (cc, ci)) = run(k.width_px, k.height_px, &frame.color.rgb8);
    compare_vec4("color", &gc, &cc, TOL).unwrap();
    compare_f32("intensity", &gi, &ci, TOL).unwrap();
    assert_negative_control("intensity", &gi, &ci, TOL);
}
