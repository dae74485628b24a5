// SPDX-License-Identifier: MIT
//! `keep_previous`: a fused frame's intensity, its central-difference gradient and its depth
//! are kept per pixel exactly as the CPU twin keeps them (the same two subtractions and one
//! multiplication: exact), the gradient of a ramp is exactly its slope, and a lost frame (pose
//! disabled) keeps nothing.

use webfusion_core::cpu;
use webfusion_core::kernels::keep_previous::{CameraPose, KeepPreviousParams};
use webfusion_tests::{SENTINEL_F32, Slot, Tolerance, assert_negative_control_vec4, cast, compare_vec4, finish, gpu, run_kernel_slots};

use crate::preprocess::chain::real_cpu_chain;

fn keep(pose: &CameraPose, p: &KeepPreviousParams, intensity: &[f32], depth: &[f32]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let gpu = gpu();
    let n = (p.width_px * p.height_px) as usize;
    let out = run_kernel_slots(&gpu, &gpu.kernels.keep_previous, p, &[Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(intensity)), Slot::In(bytemuck::cast_slice(depth)), Slot::Out(16 * n)], [p.width_px, p.height_px, 1]);
    finish(&gpu);
    let mut c = vec![[SENTINEL_F32; 4]; n];
    cpu::keep_previous(p, pose, intensity, depth, &mut c);
    (cast(&out[0]), c)
}

fn enabled() -> CameraPose {
    cpu::shared::camera_pose(&cpu::shared::IDENTITY, 1)
}

#[test]
fn a_real_frame_is_kept_exactly() {
    let chain = real_cpu_chain();
    for level in &chain.levels {
        let k = level.intrinsics;
        let p = KeepPreviousParams { width_px: k.width_px, height_px: k.height_px, ..Default::default() };
        let (g, c) = keep(&enabled(), &p, &level.intensity, &level.depth_m);
        compare_vec4("previous", &g, &c, Tolerance::EXACT).unwrap();
        assert_negative_control_vec4("previous", &g, &c, Tolerance::EXACT);
    }
}

#[test]
fn a_ramp_has_its_slope_and_a_lost_frame_keeps_nothing() {
    let (w, h) = (40u32, 30u32);
    let intensity: Vec<f32> = (0..w * h).map(|i| 0.01 * (i % w) as f32 + 0.02 * (i / w) as f32).collect();
    let depth = vec![1.5f32; (w * h) as usize];
    let p = KeepPreviousParams { width_px: w, height_px: h, ..Default::default() };
    let (g, _) = keep(&enabled(), &p, &intensity, &depth);
    let interior = g[(10 * w + 10) as usize];
    assert!((interior[1] - 0.01).abs() < 1e-6 && (interior[2] - 0.02).abs() < 1e-6 && interior[3] == 1.5, "gradient of the ramp: {interior:?}");
    assert_eq!((g[0][1], g[0][2]), (0.0, 0.0), "no gradient on the border");
    let lost = CameraPose { enabled: 0, ..enabled() };
    let (g, c) = keep(&lost, &p, &intensity, &depth);
    assert!(g.iter().flatten().all(|v| v.to_bits() == SENTINEL_F32.to_bits()), "nothing written for a lost frame");
    assert!(c.iter().flatten().all(|v| v.to_bits() == SENTINEL_F32.to_bits()), "nor by the twin");
}
