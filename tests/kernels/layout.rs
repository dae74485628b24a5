// SPDX-License-Identifier: MIT
//! The kernel registry holds together: every `#[repr(C)]` mirror matches its WGSL struct as naga
//! laid it out (size, member names, order and offsets; the checks are generated from the
//! reflection), every kernel has its params at binding 0, a `//!` doc, a CPU twin and a test
//! file, and the typed bindings of each kernel list exactly its reflected bindings.

use webfusion_core::cpu::{CpuKernel, coverage};
use webfusion_shaders as shaders;

#[test]
fn every_kernel_has_params_at_binding_zero_a_doc_a_twin_and_a_test() {
    for k in shaders::ALL {
        let first = k.bindings.first().unwrap_or_else(|| panic!("{} has no bindings", k.name));
        assert_eq!((first.group, first.binding, first.kind), (0, 0, shaders::BindingKind::Uniform), "{}: params at @group(0) @binding(0)", k.name);
        assert!(k.source.contains("//! "), "{} documents what one invocation computes", k.name);
        assert!(!k.summary.is_empty(), "{}: the //! doc's first sentence is its summary", k.name);
        match coverage(k.name) {
            CpuKernel::Present => {}
            CpuKernel::Missing { reason } => assert!(k.cpu_twin_exemption.is_some(), "{} lacks a CPU reference: {reason}", k.name),
        }
    }
    assert!(crate::KERNELS_WITHOUT_TESTS.is_empty(), "kernels without a test file tests/kernels/<capability>/<kernel>.rs: {:?}", crate::KERNELS_WITHOUT_TESTS);
}

#[test]
fn every_kernel_fits_webgpus_default_storage_binding_limit() {
    // WebGPU guarantees 8 storage buffers per shader stage; an adapter may offer more, but a
    // kernel that needs more fails on the devices that do not (the camera pose is a uniform
    // for this reason). Negative control: the count is not trivially small everywhere.
    let default = wgpu::Limits::default().max_storage_buffers_per_shader_stage as usize;
    assert_eq!(default, 8, "WebGPU's default");
    let counts: Vec<(&str, usize)> = shaders::ALL.iter().map(|k| (k.name, k.bindings.iter().filter(|b| b.kind != shaders::BindingKind::Uniform).count())).collect();
    let over: Vec<_> = counts.iter().filter(|(_, n)| *n > default).collect();
    assert!(over.is_empty(), "kernels over {default} storage buffers: {over:?}");
    assert!(counts.iter().any(|(_, n)| *n == default), "some kernel uses all {default}: the check is not vacuous");
}

#[test]
fn the_registry_compiles_one_pipeline_per_kernel_with_its_reflected_bindings() {
    let gpu = webfusion_tests::gpu();
    let pipelines = gpu.kernels.all();
    assert_eq!(pipelines.len(), shaders::ALL.len(), "one pipeline per kernel");
    for (p, k) in pipelines.iter().zip(shaders::ALL) {
        assert_eq!(p.kernel.name, k.name, "Kernels::all follows ALL");
    }
    webfusion_tests::finish(&gpu);
}

/// Natively every pipeline is compiled when the device is made (in the browser each on first
/// use: web/tests/webgpu.rs), and compiling the rest is then a no-op.
#[test]
fn natively_every_pipeline_is_compiled_at_start_up() {
    use webfusion_core::kernels::Kernels;
    assert_eq!(Kernels::COUNT, shaders::ALL.len());
    let gpu = webfusion_tests::gpu();
    assert!(gpu.kernels.all_compiled(), "natively every pipeline is compiled at start-up");
    assert_eq!(gpu.kernels.compiled_count(), Kernels::COUNT);
    gpu.kernels.compile_deferred();
    webfusion_tests::finish(&gpu);
}

#[test]
fn coverage_names_a_missing_twin() {
    assert_eq!(coverage("depth_to_metres"), CpuKernel::Present);
    assert!(matches!(coverage("no_such_kernel"), CpuKernel::Missing { .. }), "an unknown kernel is not covered");
}
