// SPDX-License-Identifier: MIT
//! The host side of the views (`core::view`): a depth and a normal view coloured on the GPU and
//! copied into an `Rgba8Unorm` texture (what a browser canvas is) hold exactly the twin's
//! pixels, padding rows dropped; a texture of another format or size is a typed error.

use webfusion_core::cpu;
use webfusion_core::kernels::depth_colormap::DepthColormapParams;
use webfusion_core::kernels::normal_colormap::NormalColormapParams;
use webfusion_core::view::{DEFAULT_DEPTH_VIEW_MAX_M, DepthView, NormalView, ViewImage};
use webfusion_core::{Error, Gpu};
use webfusion_tests::{SENTINEL_F32, compare_rgba8, finish, gpu, sample_frame};

use crate::preprocess::chain::real_cpu_chain;

fn texture(gpu: &Gpu, size_px: [u32; 2], format: wgpu::TextureFormat) -> wgpu::Texture {
    gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("test.view.texture"),
        size: wgpu::Extent3d { width: size_px[0], height: size_px[1], depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: wgpu::TextureUsages::COPY_DST | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

/// Encodes `dispatch`, copies `image` into a fresh texture and reads the texture back
/// (tightly packed rows).
fn through_texture(gpu: &Gpu, image: &ViewImage, dispatch: impl Fn(&mut wgpu::ComputePass<'_>)) -> Vec<u32> {
    let size = [image.width_px, image.height_px];
    let tex = texture(gpu, size, wgpu::TextureFormat::Rgba8Unorm);
    let readback = gpu.storage_buffer::<u32>("test.view.readback", (image.row_stride_px * image.height_px) as usize);
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.view") });
    {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("test.view"), timestamp_writes: None });
        dispatch(&mut pass);
    }
    image.copy_to_texture(&mut encoder, &tex).expect("a matching texture");
    encoder.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo { buffer: &readback, layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * image.row_stride_px), rows_per_image: Some(image.height_px) } },
        wgpu::Extent3d { width: size[0], height: size[1], depth_or_array_layers: 1 },
    );
    pollster::block_on(gpu.submit_and_wait(encoder)).expect("GPU work finishes");
    let padded: Vec<u32> = pollster::block_on(gpu.read_buffer(&readback, (image.row_stride_px * image.height_px) as usize)).expect("readback");
    padded.chunks(image.row_stride_px as usize).flat_map(|row| row[..image.width_px as usize].to_vec()).collect()
}

#[test]
fn depth_and_normal_views_reach_a_texture_as_the_twin_colours_them() {
    let gpu = gpu();
    let (calibration, frame) = sample_frame(0);
    let size = [frame.depth.width_px, frame.depth.height_px];
    let depth_raw = gpu.storage_buffer::<u16>("test.view.depth_raw", frame.depth.units.len());
    gpu.write_buffer(&depth_raw, &frame.depth.units);
    let metres_per_unit = 1.0 / calibration.depth_units_per_metre;
    let depth_view = DepthView::new(&gpu, &depth_raw, size, metres_per_unit, DEFAULT_DEPTH_VIEW_MAX_M);
    let g = through_texture(&gpu, &depth_view.image, |pass| depth_view.dispatch_in(&gpu, pass));
    let p = DepthColormapParams { width_px: size[0], height_px: size[1], row_stride_px: size[0], metres_per_unit, max_depth_m: DEFAULT_DEPTH_VIEW_MAX_M, ..Default::default() };
    let mut c = vec![SENTINEL_F32.to_bits(); frame.depth.units.len()];
    cpu::depth_colormap(&p, &frame.depth.units, &mut c);
    compare_rgba8("depth view in a texture", &g, &c, 1, 0.99).unwrap();

    // Level 1 (320 px wide): rows padded to 384 px in the buffer, 320 in the texture.
    let level = &real_cpu_chain().levels[1];
    let k = level.intrinsics;
    let normals = gpu.storage_buffer::<[f32; 4]>("test.view.normals", level.normal_in_camera.len());
    gpu.write_buffer(&normals, &level.normal_in_camera);
    let normal_view = NormalView::new(&gpu, "test.view.normal", &normals, [k.width_px, k.height_px]);
    assert_eq!(normal_view.image.row_stride_px, 320, "320 px rows are already aligned");
    let g = through_texture(&gpu, &normal_view.image, |pass| normal_view.dispatch_in(&gpu, pass));
    let p = NormalColormapParams { width_px: k.width_px, height_px: k.height_px, row_stride_px: k.width_px, ..Default::default() };
    let mut c = vec![SENTINEL_F32.to_bits(); k.pixel_count()];
    cpu::normal_colormap(&p, &level.normal_in_camera, &mut c);
    compare_rgba8("normal view in a texture", &g, &c, 1, 0.99).unwrap();
    finish(&gpu);
}

#[test]
fn padded_rows_are_dropped_and_a_mismatched_texture_is_an_error() {
    let gpu = gpu();
    // 100 px rows are 128 px apart in the buffer.
    let (w, h) = (100u32, 3u32);
    let units: Vec<u16> = (0..w * h).map(|i| (i * 40) as u16).collect();
    let depth_raw = gpu.storage_buffer::<u16>("test.view.depth_raw", units.len());
    gpu.write_buffer(&depth_raw, &units);
    let view = DepthView::new(&gpu, &depth_raw, [w, h], 0.001, 4.0);
    assert_eq!(view.image.row_stride_px, 128, "rows aligned to 64 px");
    let g = through_texture(&gpu, &view.image, |pass| view.dispatch_in(&gpu, pass));
    let p = DepthColormapParams { width_px: w, height_px: h, row_stride_px: w, metres_per_unit: 0.001, max_depth_m: 4.0, ..Default::default() };
    let mut c = vec![SENTINEL_F32.to_bits(); units.len()];
    cpu::depth_colormap(&p, &units, &mut c);
    compare_rgba8("padded depth view", &g, &c, 1, 0.99).unwrap();

    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.view.mismatch") });
    for (size, format) in [([w, h], wgpu::TextureFormat::Bgra8Unorm), ([w + 1, h], wgpu::TextureFormat::Rgba8Unorm), ([w, h - 1], wgpu::TextureFormat::Rgba8Unorm)] {
        let result = view.image.copy_to_texture(&mut encoder, &texture(&gpu, size, format));
        assert!(matches!(&result, Err(Error::InvalidConfig(m)) if m.contains("cannot be copied")), "{size:?} {format:?}: {result:?}");
    }
    drop(encoder);
    finish(&gpu);
}
