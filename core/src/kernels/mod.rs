// SPDX-License-Identifier: MIT
//! Host side of every kernel, generated from the shaders' reflection (`shaders/build.rs`,
//! `core/build.rs`): one module per kernel, `kernels::<capability>::<kernel>` (also reachable
//! as `kernels::<kernel>`), holding
//!
//! - the `#[repr(C)]` mirrors of the WGSL structs it binds (defined once in [`gpu_data`]),
//! - `Bindings<'a>`: its resources by WGSL name, in binding order, and `bind_group`,
//! - `layout_entries()`, `WORKGROUP_SIZE`, `pipeline(gpu)` and `KERNEL` (the reflection),
//! - and, only for kernels with a host file `core/src/kernels/<capability>/<kernel>.rs`, that
//!   file's items (custom dispatch, constants).
//!
//! Pipelines are built once per device in [`Kernels`] (in parallel threads natively). Each
//! kernel pairs with `shaders/wgsl/<capability>/<kernel>.wgsl` and its CPU twin
//! `core/src/cpu/<capability>/<kernel>.rs`.

use crate::PinholeIntrinsics;

include!(concat!(env!("OUT_DIR"), "/kernels_tree.rs"));

/// Mirror of WGSL `Intrinsics` (shaders/wgsl/shared/camera.wgsl).
pub type GpuIntrinsics = gpu_data::Intrinsics;

impl From<PinholeIntrinsics> for GpuIntrinsics {
    fn from(k: PinholeIntrinsics) -> Self {
        Self { fx_px: k.fx_px, fy_px: k.fy_px, cx_px: k.cx_px, cy_px: k.cy_px, width_px: k.width_px, height_px: k.height_px, _pad0: 0, _pad1: 0 }
    }
}

/// A kernel's reflection and its layout entries, as `Kernels::new` compiles it.
type KernelSpec = (&'static webfusion_shaders::Kernel, fn() -> Vec<wgpu::BindGroupLayoutEntry>);

/// Compiles the kernels of `specs`, in order: natively all of them, spread over the available
/// cores (pipeline creation is thread-safe and dominates start-up on software adapters); in
/// the browser none (all `None`): there the GPU process compiles each pipeline in the order it
/// is asked for and runs a submission only after every pipeline asked for before it, so each
/// is created on first use and the first frame waits only for the kernels it runs (the app
/// compiles the rest once that frame is fused, [`Kernels::compile_deferred`]).
fn compile_eager(device: &wgpu::Device, specs: &[KernelSpec]) -> Vec<Option<KernelPipeline>> {
    #[cfg(not(target_arch = "wasm32"))]
    {
        let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get).min(specs.len()).max(1);
        let chunk = specs.len().div_ceil(threads).max(1);
        std::thread::scope(|scope| {
            let handles: Vec<_> = specs.chunks(chunk).map(|part| scope.spawn(move || part.iter().map(|(k, entries)| Some(KernelPipeline::new(device, k, &entries()))).collect::<Vec<_>>())).collect();
            handles.into_iter().flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).collect()
        })
    }
    #[cfg(target_arch = "wasm32")]
    {
        let _ = device;
        specs.iter().map(|_| None).collect()
    }
}

/// Override constants as a cache key: each name with its value's bits.
type OverrideKey = Vec<(String, u64)>;

/// A kernel pipeline that may be compiled later (in the browser, see [`compile_eager`]): it
/// derefs to its [`KernelPipeline`], compiling it on first use if that has not happened yet.
pub struct DeferredPipeline {
    cell: std::sync::OnceLock<KernelPipeline>,
    /// Pipelines compiled with override constants ([`Self::variant`]), by their constants.
    variants: std::sync::Mutex<Vec<(OverrideKey, KernelPipeline)>>,
    device: wgpu::Device,
    spec: KernelSpec,
    /// Bind group 0's layout, made at once (cheap): bind groups need no compiled pipeline.
    layout: wgpu::BindGroupLayout,
}

impl DeferredPipeline {
    /// `compiled` if it was, else compiled on first use.
    fn new(device: &wgpu::Device, spec: KernelSpec, compiled: Option<KernelPipeline>) -> Self {
        let layout = match &compiled {
            Some(pipeline) => pipeline.bind_group_layout.clone(),
            None => KernelPipeline::bind_group_layout(device, spec.0, &(spec.1)()),
        };
        let cell = std::sync::OnceLock::new();
        if let Some(pipeline) = compiled {
            let _ = cell.set(pipeline);
        }
        Self { cell, variants: std::sync::Mutex::default(), device: device.clone(), spec, layout }
    }

    /// Whether the pipeline exists yet.
    pub fn is_compiled(&self) -> bool {
        self.cell.get().is_some()
    }

    /// The kernel compiled with its `override` constants set to `constants`
    /// ([`KernelPipeline::specialised`]), bound by the same bind groups; the default pipeline
    /// is not compiled for it.
    pub fn specialised(&self, constants: &[(&str, f64)]) -> KernelPipeline {
        KernelPipeline::specialised(&self.device, self.spec.0, self.layout.clone(), constants)
    }

    /// [`Self::specialised`], compiled once per set of constants and shared: every stage that
    /// asks for the same variant (each raycast target for its map kind) gets the same pipeline,
    /// so a page that compiles its pipelines when they are first needed compiles each variant
    /// once.
    pub fn variant(&self, constants: &[(&str, f64)]) -> KernelPipeline {
        let key: OverrideKey = constants.iter().map(|(name, value)| ((*name).to_owned(), value.to_bits())).collect();
        let mut variants = self.variants.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if let Some((_, pipeline)) = variants.iter().find(|(k, _)| *k == key) {
            return pipeline.clone();
        }
        let pipeline = self.specialised(constants);
        variants.push((key, pipeline.clone()));
        pipeline
    }

    /// A bind group of `entries`, without compiling the pipeline (a stage binds its deferred
    /// kernels when it is built, and may never dispatch them: swapping, meshing).
    pub fn bind_group(&self, device: &wgpu::Device, entries: &[wgpu::BindGroupEntry]) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(&format!("core.{}.bind_group", self.spec.0.name)), layout: &self.layout, entries })
    }
}

impl std::ops::Deref for DeferredPipeline {
    type Target = KernelPipeline;
    fn deref(&self) -> &KernelPipeline {
        self.cell.get_or_init(|| KernelPipeline::with_layout(&self.device, self.spec.0, self.layout.clone()))
    }
}

impl std::fmt::Debug for DeferredPipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeferredPipeline").field("kernel", &self.spec.0.name).field("compiled", &self.is_compiled()).finish()
    }
}

/// One compiled kernel: its reflected description, bind group layout and pipeline (a clone
/// shares them).
#[derive(Clone, Debug)]
pub struct KernelPipeline {
    /// Reflected kernel (source, workgroup size, bindings).
    pub kernel: &'static webfusion_shaders::Kernel,
    /// Layout of bind group 0, built from the reflected bindings.
    pub bind_group_layout: wgpu::BindGroupLayout,
    /// The compute pipeline.
    pub pipeline: wgpu::ComputePipeline,
}

impl KernelPipeline {
    /// Compiles `kernel` for `device` with bind group 0 laid out as `entries`.
    pub fn new(device: &wgpu::Device, kernel: &'static webfusion_shaders::Kernel, entries: &[wgpu::BindGroupLayoutEntry]) -> Self {
        Self::with_layout(device, kernel, Self::bind_group_layout(device, kernel, entries))
    }

    /// Bind group 0's layout for `kernel` from `entries`.
    pub fn bind_group_layout(device: &wgpu::Device, kernel: &'static webfusion_shaders::Kernel, entries: &[wgpu::BindGroupLayoutEntry]) -> wgpu::BindGroupLayout {
        device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(&format!("core.{}.bind_group_layout", kernel.name)), entries })
    }

    /// Compiles `kernel` for `device` with bind group 0 laid out by `bind_group_layout`.
    pub fn with_layout(device: &wgpu::Device, kernel: &'static webfusion_shaders::Kernel, bind_group_layout: wgpu::BindGroupLayout) -> Self {
        Self::specialised(device, kernel, bind_group_layout, &[])
    }

    /// Compiles `kernel` with its WGSL `override` constants set to `constants` (name, value;
    /// booleans as 0 or 1; those not given keep their defaults) and bind group 0 laid out by
    /// `bind_group_layout`, so bind groups of the kernel's layout bind it too. A use of a
    /// kernel that never takes one of its branches compiles a pipeline of its own without it:
    /// lavapipe (Mesa 22.3's llvmpipe) runs an `if` as masked code, so every branch costs its
    /// full time, taken or not; only loops end early.
    pub fn specialised(device: &wgpu::Device, kernel: &'static webfusion_shaders::Kernel, bind_group_layout: wgpu::BindGroupLayout, constants: &[(&str, f64)]) -> Self {
        let label = format!("core.{}", kernel.name);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some(&label), source: wgpu::ShaderSource::Wgsl(kernel.source.into()) });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(&format!("{label}.pipeline_layout")),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(&format!("{label}.pipeline")),
            layout: Some(&layout),
            module: &module,
            entry_point: Some(kernel.entry_point),
            compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
            cache: None,
        });
        Self { kernel, bind_group_layout, pipeline }
    }

    /// A bind group of `entries` (the generated `Bindings::bind_group` passes them in WGSL
    /// binding order).
    pub fn bind_group(&self, device: &wgpu::Device, entries: &[wgpu::BindGroupEntry]) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(&format!("core.{}.bind_group", self.kernel.name)), layout: &self.bind_group_layout, entries })
    }

    /// Records one dispatch covering `invocations` threads (rounded up to whole workgroups) in
    /// a compute pass of its own.
    pub fn dispatch(&self, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, invocations: [u32; 3]) {
        let label = format!("core.{}", self.kernel.name);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(&label), timestamp_writes: None });
        self.dispatch_in(&mut pass, bind_group, invocations);
    }

    /// Records one dispatch covering `invocations` threads into an open compute pass (a stage
    /// records all its dispatches into one pass).
    pub fn dispatch_in(&self, pass: &mut wgpu::ComputePass<'_>, bind_group: &wgpu::BindGroup, invocations: [u32; 3]) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind_group, &[]);
        let [x, y, z] = self.workgroup_count(invocations);
        pass.dispatch_workgroups(x, y, z);
    }

    /// Workgroups needed to cover `invocations`, from the reflected workgroup size.
    pub fn workgroup_count(&self, invocations: [u32; 3]) -> [u32; 3] {
        let wg = self.kernel.workgroup_size;
        [invocations[0].div_ceil(wg[0]), invocations[1].div_ceil(wg[1]), invocations[2].div_ceil(wg[2])]
    }
}
