// SPDX-License-Identifier: MIT
//! The GPU context and the harness itself: adapter choice, missing adapters, and the
//! uncaptured-error canary that fails tests whose outputs look right.

use webfusion_core::{Error, Gpu, GpuOptions};
use webfusion_tests::{finish, gpu};

#[test]
fn adapter_is_vulkan_with_the_limits_requested() {
    let gpu = gpu();
    eprintln!("adapter: {}", gpu.adapter_summary());
    assert_eq!(gpu.adapter_info.backend, wgpu::Backend::Vulkan, "native tests run on Vulkan");
    assert!(gpu.limits.max_storage_buffer_binding_size >= webfusion_core::gpu::REQUIRED_STORAGE_BINDING_BYTES, "128 MiB storage bindings");
    assert!(gpu.limits.max_compute_workgroup_storage_size >= 16 * 1024, "workgroup memory");
    finish(&gpu);
}

#[test]
fn a_missing_adapter_is_a_clear_error() {
    let options = GpuOptions { adapter_name_contains: Some("no-such-adapter-xyz".into()), ..Default::default() };
    let err = pollster::block_on(Gpu::new(&options)).unwrap_err();
    assert!(matches!(err, Error::NoAdapter { .. }), "{err}");
    assert!(err.to_string().contains("no-such-adapter-xyz"), "names the filter: {err}");
}

#[test]
fn validation_errors_are_caught_by_the_canary() {
    let gpu = gpu();
    // A 4-byte uniform where the kernel's params need 32 bytes: wgpu must report it.
    let tiny = gpu.device.create_buffer(&wgpu::BufferDescriptor { label: Some("test.tiny"), size: 4, usage: wgpu::BufferUsages::UNIFORM, mapped_at_creation: false });
    let storage = gpu.storage_buffer::<f32>("test.storage", 16);
    let _ = webfusion_core::kernels::vertex_map::Bindings { params: &tiny, depth_m: &storage, vertex_in_camera: &storage }.bind_group(&gpu);
    let errors = gpu.take_errors();
    assert!(!errors.is_empty(), "the canary must see the bad binding");
    assert!(std::panic::catch_unwind(|| {
        let g = webfusion_tests::gpu();
        let (a, b, c) = (g.storage_buffer::<u8>("a", 4), g.storage_buffer::<u8>("b", 4), g.storage_buffer::<u8>("c", 4));
        let _ = webfusion_core::kernels::vertex_map::Bindings { params: &a, depth_m: &b, vertex_in_camera: &c }.bind_group(&g);
        finish(&g);
    })
    .is_err(), "finish() must fail a test that produced validation errors");
}
