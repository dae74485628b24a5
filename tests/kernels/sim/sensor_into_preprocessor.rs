// SPDX-License-Identifier: MIT
//! `VirtualSensor::encode_into`: the fused map's depth rendered straight into a preprocessor's
//! raw depth on the GPU (`webfusion planes --from-model`, the page's planes of the fused map)
//! is, word for word, the depth a render read back gives; the preprocessor's old depth (a
//! sentinel) is gone everywhere; another pose gives other words (the comparison can fail); a
//! preprocessor of another image size, focal length or depth scale is refused with a typed
//! error.

use glam::DVec3;
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_core::sim::sensor::{SensorOptions, VirtualSensor};
use webfusion_core::tsdf::{DenseTsdfVolume, TsdfConfig, TsdfStore};
use webfusion_core::{Error, Gpu, RgbdCalibration, Se3};
use webfusion_tests::{finish, gpu};

use crate::fusion::raycast_range::{K, scene};

const UNITS_PER_METRE: f32 = 5000.0;
/// A raw depth no render gives (13.4 m at 5000 units per metre, past the sensor's range).
const SENTINEL: u16 = 0xBEEF;

/// The raycast-range test's sphere (0.2 m at (0.3, 0.1, 1.0), 4 cm voxels) in a dense store.
fn sphere_store(gpu: &Gpu) -> DenseTsdfVolume {
    let (desc, voxels) = scene();
    let store = DenseTsdfVolume::new(gpu, TsdfConfig::cube(64, 0.04), [desc.origin_x_m, desc.origin_y_m, desc.origin_z_m]).expect("allocate volume");
    gpu.write_buffer(store.voxels(), &voxels);
    // The bricks integration would have marked (the raycast skips the others).
    gpu.write_buffer(store.surface_bricks(), &webfusion_core::cpu::shared::surface_bricks(&desc, &voxels));
    store
}

/// The preprocessor's raw depth after `encode_into` at `pose`, over a sentinel.
fn rendered_into(gpu: &Gpu, sensor: &mut VirtualSensor, store: &DenseTsdfVolume, pose: &Se3, pre: &DepthPreprocessor) -> Vec<u16> {
    gpu.write_buffer(&pre.depth_raw, &vec![SENTINEL; K.pixel_count()]);
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.encode_into") });
    sensor.encode_into(gpu, &mut encoder, store, pose, 0, pre).expect("same size and scale");
    pollster::block_on(gpu.submit_and_wait(encoder)).expect("submit");
    pollster::block_on(gpu.read_buffer(&pre.depth_raw, K.pixel_count())).expect("read back")
}

#[test]
fn the_model_depth_lands_in_the_preprocessor_as_a_render_reads_it() {
    let gpu = gpu();
    let store = sphere_store(&gpu);
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_METRE };
    let pre = DepthPreprocessor::new(&gpu, calibration, PreprocessConfig::default()).expect("preprocessor");
    let mut sensor = VirtualSensor::new(&gpu, &store, K, SensorOptions { units_per_metre: UNITS_PER_METRE, ..SensorOptions::default() }).expect("sensor");
    // Off the origin, looking at the sphere from 10 cm to the left.
    let pose = Se3 { translation_m: DVec3::new(-0.1, 0.02, 0.0), ..Se3::IDENTITY };
    let read_back = pollster::block_on(sensor.render(&gpu, &store, &pose, 0)).expect("render").depth_units;
    let hit = read_back.iter().filter(|&&u| u > 0).count();
    assert!(hit > K.pixel_count() / 10, "the sphere fills part of the view: {hit} of {} pixels", K.pixel_count());
    let into = rendered_into(&gpu, &mut sensor, &store, &pose, &pre);
    assert!(into.iter().all(|&u| u != SENTINEL), "every pixel of the preprocessor's depth was written");
    let differ = into.iter().zip(&read_back).filter(|(a, b)| a != b).count();
    assert_eq!(differ, 0, "{differ} pixels differ from the render read back");
    // Negative control: 5 cm to the side, the same comparison fails.
    let moved = Se3 { translation_m: pose.translation_m + DVec3::new(0.05, 0.0, 0.0), ..pose };
    let other = rendered_into(&gpu, &mut sensor, &store, &moved, &pre);
    let differ = other.iter().zip(&read_back).filter(|(a, b)| a != b).count();
    assert!(differ > hit / 10, "another pose must give other depth: {differ} pixels differ");
    finish(&gpu);
}

#[test]
fn a_preprocessor_of_another_size_focal_length_or_scale_is_refused() {
    let gpu = gpu();
    let store = sphere_store(&gpu);
    let mut sensor = VirtualSensor::new(&gpu, &store, K, SensorOptions { units_per_metre: UNITS_PER_METRE, ..SensorOptions::default() }).expect("sensor");
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.encode_into.refused") });
    let half = webfusion_core::PinholeIntrinsics { width_px: K.width_px / 2, height_px: K.height_px / 2, ..K };
    let small = DepthPreprocessor::new(&gpu, RgbdCalibration { intrinsics: half, depth_units_per_metre: UNITS_PER_METRE }, PreprocessConfig::default()).expect("preprocessor");
    let err = sensor.encode_into(&gpu, &mut encoder, &store, &Se3::IDENTITY, 0, &small).expect_err("another size");
    assert!(matches!(err, Error::FrameSize { got_width: 160, want_width: 80, .. }), "{err}");
    let other_focal = webfusion_core::PinholeIntrinsics { fx_px: K.fx_px * 1.1, ..K };
    let wider = DepthPreprocessor::new(&gpu, RgbdCalibration { intrinsics: other_focal, depth_units_per_metre: UNITS_PER_METRE }, PreprocessConfig::default()).expect("preprocessor");
    let err = sensor.encode_into(&gpu, &mut encoder, &store, &Se3::IDENTITY, 0, &wider).expect_err("another focal length");
    assert!(matches!(&err, Error::InvalidConfig(m) if m.contains("back-projects")), "{err}");
    let millimetres = DepthPreprocessor::new(&gpu, RgbdCalibration { intrinsics: K, depth_units_per_metre: 1000.0 }, PreprocessConfig::default()).expect("preprocessor");
    let err = sensor.encode_into(&gpu, &mut encoder, &store, &Se3::IDENTITY, 0, &millimetres).expect_err("another scale");
    assert!(matches!(&err, Error::InvalidConfig(m) if m.contains("5000") && m.contains("1000")), "{err}");
    drop(encoder);
    finish(&gpu);
}
