// SPDX-License-Identifier: MIT
//! The whole preprocessing chain (`DepthPreprocessor`) against its CPU twin
//! (`cpu::preprocess::preprocess`) on a real frame, every buffer of every level.
//!
//! Per-kernel differences are a few ulp (see each kernel's test); end to end they feed
//! through later stages, so these tolerances are wider, and stated per buffer.

use std::sync::OnceLock;

use webfusion_core::cpu::preprocess::chain::{CpuPreprocessed, preprocess};
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_tests::{Tolerance, assert_negative_control_vec4, compare_f32, compare_vec4, finish, gpu, sample_frame};

/// The CPU chain on frame 0 with the default configuration, computed once per test binary.
pub(crate) fn real_cpu_chain() -> &'static CpuPreprocessed {
    static CHAIN: OnceLock<CpuPreprocessed> = OnceLock::new();
    CHAIN.get_or_init(|| {
        let (calib, frame) = sample_frame(0);
        preprocess(&calib, &PreprocessConfig::default(), &frame)
    })
}

/// Depth at every level: bilateral ulp differences, averaged down.
const DEPTH_TOL: Tolerance = Tolerance { absolute: 2e-6, relative: 1e-6 };
/// Vertices: depth error times the ray slope (< 1 within the Kinect field of view).
const VERTEX_TOL: Tolerance = Tolerance { absolute: 3e-6, relative: 2e-6 };
/// Normals: micrometre vertex differences divided by millimetre gradients (6.6e-5 seen on
/// lavapipe at level 0).
const NORMAL_TOL: Tolerance = Tolerance { absolute: 2e-4, relative: 0.0 };
/// Colour and intensity in [0, 1].
const COLOR_TOL: Tolerance = Tolerance { absolute: 3e-7, relative: 0.0 };

fn check_chain(config: PreprocessConfig) {
    let gpu = gpu();
    let (calib, frame) = sample_frame(0);
    let pre = DepthPreprocessor::new(&gpu, calib, config).unwrap();
    for level in &pre.levels {
        gpu.fill_buffer(&level.depth_m, webfusion_tests::SENTINEL_F32);
        gpu.fill_buffer(&level.vertex_in_camera, webfusion_tests::SENTINEL_F32);
        gpu.fill_buffer(&level.normal_in_camera, webfusion_tests::SENTINEL_F32);
    }
    pollster::block_on(pre.run(&gpu, &frame)).unwrap();
    let cpu = if config == PreprocessConfig::default() { real_cpu_chain().clone() } else { preprocess(&calib, &config, &frame) };
    assert_eq!(pre.levels.len(), cpu.levels.len(), "pyramid depth");
    for (l, (g, c)) in pre.levels.iter().zip(&cpu.levels).enumerate() {
        let n = c.intrinsics.pixel_count();
        assert_eq!(g.intrinsics, c.intrinsics, "intrinsics of level {l}");
        let depth: Vec<f32> = pollster::block_on(gpu.read_buffer(&g.depth_m, n)).unwrap();
        let vertex: Vec<[f32; 4]> = pollster::block_on(gpu.read_buffer(&g.vertex_in_camera, n)).unwrap();
        let normal: Vec<[f32; 4]> = pollster::block_on(gpu.read_buffer(&g.normal_in_camera, n)).unwrap();
        let d = compare_f32(&format!("depth_m[{l}]"), &depth, &c.depth_m, DEPTH_TOL).unwrap();
        compare_vec4(&format!("vertex_in_camera[{l}]"), &vertex, &c.vertex_in_camera, VERTEX_TOL).unwrap();
        let nm = compare_vec4(&format!("normal_in_camera[{l}]"), &normal, &c.normal_in_camera, NORMAL_TOL).unwrap();
        eprintln!("level {l}: depth {d:?}; normals {nm:?}");
        assert!(d.compared - d.invalid > n / 2, "level {l} has mostly valid depth");
        assert_negative_control_vec4(&format!("normal_in_camera[{l}]"), &normal, &c.normal_in_camera, NORMAL_TOL);
    }
    let n0 = calib.intrinsics.pixel_count();
    let color: Vec<[f32; 4]> = pollster::block_on(gpu.read_buffer(&pre.color, n0)).unwrap();
    let intensity: Vec<f32> = pollster::block_on(gpu.read_buffer(&pre.intensity, n0)).unwrap();
    compare_vec4("color", &color, &cpu.color, COLOR_TOL).unwrap();
    compare_f32("intensity", &intensity, &cpu.intensity, COLOR_TOL).unwrap();
    finish(&gpu);
}

#[test]
fn default_chain_matches_cpu_on_real_frame() {
    check_chain(PreprocessConfig::default());
}

#[test]
fn unfiltered_unsmoothed_chain_matches_cpu_on_real_frame() {
    check_chain(PreprocessConfig { bilateral: None, gradient_smoothing: None, ..PreprocessConfig::default() });
}

#[test]
fn wrong_frame_size_is_a_typed_error() {
    let gpu = gpu();
    let (calib, mut frame) = sample_frame(0);
    let pre = DepthPreprocessor::new(&gpu, calib, PreprocessConfig::default()).unwrap();
    frame.depth.width_px = 320;
    let err = pre.upload(&gpu, &frame).unwrap_err();
    assert!(matches!(err, webfusion_core::Error::FrameSize { got_width: 320, want_width: 640, .. }), "{err}");
    assert!(err.to_string().contains("320x480"), "message names the size: {err}");
    // The colour alone (the depth rendered on the GPU) is checked the same way.
    frame.color.width_px = 320;
    let err = pre.upload_color(&gpu, &frame.color).unwrap_err();
    assert!(matches!(err, webfusion_core::Error::FrameSize { what: "colour image", got_width: 320, want_width: 640, .. }), "{err}");
    frame.color.width_px = 640;
    pre.upload_color(&gpu, &frame.color).expect("the right size uploads");
    finish(&gpu);
}

#[test]
fn invalid_config_is_rejected() {
    let bad = PreprocessConfig { min_depth_m: 2.0, max_depth_m: 1.0, ..PreprocessConfig::default() };
    assert!(matches!(bad.validate(), Err(webfusion_core::Error::InvalidConfig(_))), "empty depth range");
    let bad = PreprocessConfig { pyramid_levels: 0, ..PreprocessConfig::default() };
    assert!(bad.validate().is_err(), "zero pyramid levels");
}
