// SPDX-License-Identifier: MIT
//! The preprocessing kernels on WebGPU in a real browser (headless Chromium, SwiftShader),
//! checked against the CPU reference on a real Kinect frame: the same WGSL as native.
#![cfg(target_arch = "wasm32")]

use wasm_bindgen_test::*;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_core::recording::RecordingReader;
use webfusion_core::source::FrameSource as _;
use webfusion_core::{Gpu, GpuOptions, RgbdCalibration, RgbdFrame};

wasm_bindgen_test_configure!(run_in_browser);

/// The bundled sample recording (real Kinect frames, TUM fr1/rpy), compiled into the test.
const SAMPLE_WFR: &[u8] = include_bytes!("../../data/sample/fr1_rpy.wfr");

/// Frame 0 of the sample, decoded by the same reader the app uses.
fn frame() -> RgbdFrame {
    let mut sample = RecordingReader::from_bytes(SAMPLE_WFR.to_vec()).expect("the bundled sample parses");
    sample.read_frame(0).expect("frame 0 decodes")
}

/// Largest |a - b| over valid entries, or an error if the NaN masks differ.
fn max_diff(what: &str, gpu: &[f32], cpu: &[f32]) -> Result<f32, String> {
    let mut worst = 0.0f32;
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        match (g.is_nan(), c.is_nan()) {
            (true, true) => {}
            (false, false) => worst = worst.max((g - c).abs()),
            _ => return Err(format!("{what}[{i}]: validity differs: GPU {g} vs CPU {c}")),
        }
    }
    Ok(worst)
}

#[wasm_bindgen_test]
async fn preprocessing_on_webgpu_matches_cpu_reference() {
    let gpu = Gpu::new(&GpuOptions::default()).await.expect("a WebGPU adapter (run Chromium with --enable-unsafe-webgpu)");
    assert_eq!(gpu.adapter_info.backend, wgpu::Backend::BrowserWebGpu, "this test must run on the browser's WebGPU");
    console_log!("adapter: {}", gpu.adapter_summary());
    let calibration = RgbdCalibration { intrinsics: webfusion_core::camera::TUM_FREIBURG1, depth_units_per_metre: 5000.0 };
    let config = PreprocessConfig::default();
    let frame = frame();
    let pre = DepthPreprocessor::new(&gpu, calibration, config).expect("preprocessor");
    // Sentinel: finite and far from any real value, so an unwritten output cannot pass.
    let sentinel = f32::from_bits(0xDEAD_BEEF);
    gpu.fill_buffer(&pre.levels[0].depth_m, sentinel);
    gpu.fill_buffer(&pre.levels[0].normal_in_camera, sentinel);
    pre.run(&gpu, &frame).await.expect("GPU preprocessing");
    let cpu = preprocess(&calibration, &config, &frame);
    let n = calibration.intrinsics.pixel_count();

    let depth: Vec<f32> = gpu.read_buffer(&pre.levels[0].depth_m, n).await.expect("readback");
    let d = max_diff("depth_m", &depth, &cpu.levels[0].depth_m).unwrap();
    // Tolerances: SwiftShader's exp() and division are within a few ulp like lavapipe's.
    assert!(d <= 5e-6, "filtered depth differs by {d} m");
    let normals: Vec<[f32; 4]> = gpu.read_buffer(&pre.levels[0].normal_in_camera, n).await.expect("readback");
    let nd = max_diff("normal", normals.as_flattened(), cpu.levels[0].normal_in_camera.as_flattened()).unwrap();
    assert!(nd <= 5e-4, "normals differ by {nd}");
    let coarse: Vec<f32> = gpu.read_buffer(&pre.levels[2].depth_m, calibration.intrinsics.pyramid_level(2).pixel_count()).await.expect("readback");
    let cd = max_diff("depth_m[2]", &coarse, &cpu.levels[2].depth_m).unwrap();
    assert!(cd <= 5e-6, "coarse depth differs by {cd} m");
    let valid = depth.iter().filter(|d| !d.is_nan()).count();
    assert!(valid > n / 2, "a real frame has mostly valid depth ({valid} of {n})");

    // Negative control: the same comparison rejects a perturbed and an unwritten result.
    let ix = depth.iter().position(|d| !d.is_nan()).expect("a valid pixel");
    let mut perturbed = depth.clone();
    perturbed[ix] += 1e-3;
    assert!(max_diff("depth_m", &perturbed, &cpu.levels[0].depth_m).unwrap() > 5e-6, "a 1 mm error is detected");
    let mut unwritten = depth.clone();
    unwritten[ix] = sentinel;
    assert!(max_diff("depth_m", &unwritten, &cpu.levels[0].depth_m).unwrap() > 5e-6, "a sentinel value is detected");
    let mut holed = depth.clone();
    holed[ix] = f32::NAN;
    assert!(max_diff("depth_m", &holed, &cpu.levels[0].depth_m).is_err(), "a mask difference is detected");

    // In the browser a pipeline is compiled when it is first used: preprocessing compiled its
    // own kernels and nothing else (the first frame waits for no kernel it does not run).
    let compiled = gpu.kernels.compiled_count();
    assert!(gpu.kernels.depth_to_metres.is_compiled() && gpu.kernels.bilateral_filter.is_compiled(), "the kernels that ran are compiled");
    assert!(!gpu.kernels.raycast.is_compiled() && !gpu.kernels.plane_label.is_compiled(), "kernels that did not run are not");
    assert!(compiled < webfusion_core::kernels::Kernels::COUNT / 3, "{compiled} pipelines compiled by preprocessing alone");
    gpu.kernels.compile_deferred();
    assert!(gpu.kernels.all_compiled(), "compile_deferred compiles the rest");

    let errors = gpu.take_errors();
    assert!(errors.is_empty(), "WebGPU reported errors: {errors:?}");
    console_log!("webgpu vs cpu: depth {d:e} m, normals {nd:e}, coarse depth {cd:e} m; {compiled} pipelines compiled by preprocessing");
}

/// Swapping on WebGPU: the synthetic room fused at its path's poses into half the pool it
/// needs moves blocks to wasm memory and back, and ends with exactly the map (every block, word
/// for word) that a pool large enough for the room builds, as it does natively.
#[wasm_bindgen_test]
async fn a_swapping_map_on_webgpu_equals_the_large_pools_map() {
    use webfusion_core::fusion::pose_driven::PoseDrivenMapper;
    use webfusion_core::sim::room::SyntheticRoom;
    use webfusion_core::tsdf::TsdfConfig;
    let gpu = Gpu::new(&GpuOptions::default()).await.expect("a WebGPU adapter");
    let k = webfusion_core::PinholeIntrinsics { fx_px: 65.6, fy_px: 65.6, cx_px: 39.5, cy_px: 29.5, width_px: 80, height_px: 60 };
    let calibration = RgbdCalibration { intrinsics: k, depth_units_per_metre: 5000.0 };
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let path = room.path(72);
    let frames: Vec<RgbdFrame> = (0..path.len()).map(|i| room.frame(&k, &path, i)).collect();
    let fuse = async |pool_blocks: u32| {
        let mut mapper = PoseDrivenMapper::new(&gpu, calibration, PreprocessConfig::default(), TsdfConfig::sparse(0.04, pool_blocks), &path[0], false).expect("mapper");
        for (frame, pose) in frames.iter().zip(&path) {
            mapper.submit_frame(&gpu, frame, pose).await.expect("fuse");
            // Let the page's event loop deliver this frame's readbacks (the app polls them on a
            // timer between frames; this loop would otherwise never yield).
            mapper.flush(&gpu).await.expect("flush");
        }
        mapper.flush(&gpu).await.expect("flush");
        let stats = mapper.map_stats().expect("a sparse map reports");
        (mapper.download_blocks(&gpu).await.expect("download"), stats)
    };
    let (reference, _) = fuse(8192).await;
    // The swap kernels were bound (the map's swapper is built with it) but, never dispatched,
    // never compiled: in the browser a deferred kernel costs nothing until it runs.
    assert!(!gpu.kernels.block_swap_out.is_compiled() && !gpu.kernels.block_swap_in.is_compiled(), "binding a deferred kernel does not compile it");
    let pool = reference.len() as u32 / 2;
    let (swapped, stats) = fuse(pool).await;
    web_sys::console::log_1(&format!("room: {} blocks, pool {pool}: {} swapped out, {} in, {} on the host", reference.len(), stats.swapped_out_total, stats.swapped_in_total, stats.blocks_on_host).into());
    assert!(stats.swapped_out_total > 0 && stats.swapped_in_total > 0, "blocks went to wasm memory and came back");
    assert_eq!((stats.pool_full, stats.hash_full, stats.swapped_hits), (0, 0, 0), "no exhaustion, no block missed");
    assert_eq!(swapped.len(), reference.len(), "the same blocks");
    assert!(swapped == reference, "every block equals the large pool's");
    assert!(gpu.kernels.block_swap_out.is_compiled() && gpu.kernels.block_swap_in.is_compiled(), "dispatching compiled them");
    assert!(gpu.take_errors().is_empty(), "no WebGPU errors");
}
