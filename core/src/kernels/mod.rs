// SPDX-License-Identifier: MIT
//! Host side of every kernel: the `#[repr(C)]` mirror of its uniform parameters, a typed
//! bindings struct in WGSL binding order, and an `encode` that records one dispatch.
//!
//! Each file here pairs with `shaders/wgsl/<name>.wgsl` and `core/src/cpu/<name>.rs`.
//! Pipelines and bind group layouts are built once per device from the reflected shader set.

pub mod bilateral_filter;
pub mod color_to_float;
pub mod depth_pyramid_down;
pub mod depth_to_metres;
pub mod gradient_smooth;
pub mod mc_count;
pub mod mc_generate;
pub mod mc_scan;
pub mod icp_reduce;
pub mod intensity_pyramid_down;
pub mod normal_map;
pub mod raycast;
pub mod rgb_reduce;
pub mod tsdf_integrate;
pub mod vertex_gradients;
pub mod vertex_map;

use webfusion_shaders::{BindingKind, Kernel};

use crate::PinholeIntrinsics;

/// Mirror of WGSL `Intrinsics` (shaders/wgsl/shared/camera.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuIntrinsics {
    /// Focal length x, pixels.
    pub fx_px: f32,
    /// Focal length y, pixels.
    pub fy_px: f32,
    /// Principal point x, pixels.
    pub cx_px: f32,
    /// Principal point y, pixels.
    pub cy_px: f32,
    /// Width, pixels.
    pub width_px: u32,
    /// Height, pixels.
    pub height_px: u32,
    /// Padding.
    pub _pad0: u32,
    /// Padding.
    pub _pad1: u32,
}

impl From<PinholeIntrinsics> for GpuIntrinsics {
    fn from(k: PinholeIntrinsics) -> Self {
        Self { fx_px: k.fx_px, fy_px: k.fy_px, cx_px: k.cx_px, cy_px: k.cy_px, width_px: k.width_px, height_px: k.height_px, _pad0: 0, _pad1: 0 }
    }
}

/// One compiled kernel: its reflected description, bind group layout and pipeline.
#[derive(Debug)]
pub struct KernelPipeline {
    /// Reflected kernel (source, workgroup size, bindings).
    pub kernel: &'static Kernel,
    /// Layout of bind group 0, built from the reflected bindings.
    pub bind_group_layout: wgpu::BindGroupLayout,
    /// The compute pipeline.
    pub pipeline: wgpu::ComputePipeline,
}

impl KernelPipeline {
    /// Compiles `kernel` for `device`.
    pub fn new(device: &wgpu::Device, kernel: &'static Kernel) -> Self {
        let label = format!("core.{}", kernel.name);
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(&label),
            source: wgpu::ShaderSource::Wgsl(kernel.source.into()),
        });
        let entries: Vec<wgpu::BindGroupLayoutEntry> = kernel
            .bindings
            .iter()
            .map(|b| wgpu::BindGroupLayoutEntry {
                binding: b.binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: match b.kind {
                        BindingKind::Uniform => wgpu::BufferBindingType::Uniform,
                        BindingKind::StorageRead => wgpu::BufferBindingType::Storage { read_only: true },
                        BindingKind::StorageReadWrite => wgpu::BufferBindingType::Storage { read_only: false },
                    },
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(b.min_size_bytes.into()),
                },
                count: None,
            })
            .collect();
        let bind_group_layout =
            device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(&format!("{label}.bind_group_layout")), entries: &entries });
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
            compilation_options: Default::default(),
            cache: None,
        });
        Self { kernel, bind_group_layout, pipeline }
    }

    /// Binds `buffers` in WGSL binding order.
    ///
    /// # Panics
    /// If the count differs from the reflected binding count: that is a bug in the typed
    /// bindings struct, which the layout tests catch.
    pub fn bind_group(&self, device: &wgpu::Device, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        assert_eq!(buffers.len(), self.kernel.bindings.len(), "kernel {} has {} bindings", self.kernel.name, self.kernel.bindings.len());
        let entries: Vec<wgpu::BindGroupEntry> = self
            .kernel
            .bindings
            .iter()
            .zip(buffers)
            .map(|(b, buf)| wgpu::BindGroupEntry { binding: b.binding, resource: buf.as_entire_binding() })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(&format!("core.{}.bind_group", self.kernel.name)),
            layout: &self.bind_group_layout,
            entries: &entries,
        })
    }

    /// Records one dispatch covering `invocations` threads (rounded up to whole workgroups).
    pub fn dispatch(&self, encoder: &mut wgpu::CommandEncoder, bind_group: &wgpu::BindGroup, invocations: [u32; 3]) {
        let label = format!("core.{}", self.kernel.name);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(&label), timestamp_writes: None });
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

/// Every kernel pipeline, compiled once per device.
#[derive(Debug)]
pub struct Kernels {
    /// `depth_to_metres`.
    pub depth_to_metres: KernelPipeline,
    /// `bilateral_filter`.
    pub bilateral_filter: KernelPipeline,
    /// `depth_pyramid_down`.
    pub depth_pyramid_down: KernelPipeline,
    /// `vertex_map`.
    pub vertex_map: KernelPipeline,
    /// `vertex_gradients`.
    pub vertex_gradients: KernelPipeline,
    /// `gradient_smooth`.
    pub gradient_smooth: KernelPipeline,
    /// `normal_map`.
    pub normal_map: KernelPipeline,
    /// `color_to_float`.
    pub color_to_float: KernelPipeline,
    /// `tsdf_integrate`.
    pub tsdf_integrate: KernelPipeline,
    /// `raycast`.
    pub raycast: KernelPipeline,
    /// `icp_reduce`.
    pub icp_reduce: KernelPipeline,
    /// `intensity_pyramid_down`.
    pub intensity_pyramid_down: KernelPipeline,
    /// `rgb_reduce`.
    pub rgb_reduce: KernelPipeline,
    /// `mc_count` (marching cubes, pass 1).
    pub mc_count: KernelPipeline,
    /// `mc_scan` (marching cubes, pass 2).
    pub mc_scan: KernelPipeline,
    /// `mc_generate` (marching cubes, pass 3).
    pub mc_generate: KernelPipeline,
}

impl Kernels {
    /// Compiles every kernel.
    pub fn new(device: &wgpu::Device) -> Self {
        use webfusion_shaders as s;
        Self {
            depth_to_metres: KernelPipeline::new(device, &s::DEPTH_TO_METRES),
            bilateral_filter: KernelPipeline::new(device, &s::BILATERAL_FILTER),
            depth_pyramid_down: KernelPipeline::new(device, &s::DEPTH_PYRAMID_DOWN),
            vertex_map: KernelPipeline::new(device, &s::VERTEX_MAP),
            vertex_gradients: KernelPipeline::new(device, &s::VERTEX_GRADIENTS),
            gradient_smooth: KernelPipeline::new(device, &s::GRADIENT_SMOOTH),
            normal_map: KernelPipeline::new(device, &s::NORMAL_MAP),
            color_to_float: KernelPipeline::new(device, &s::COLOR_TO_FLOAT),
            tsdf_integrate: KernelPipeline::new(device, &s::TSDF_INTEGRATE),
            raycast: KernelPipeline::new(device, &s::RAYCAST),
            icp_reduce: KernelPipeline::new(device, &s::ICP_REDUCE),
            intensity_pyramid_down: KernelPipeline::new(device, &s::INTENSITY_PYRAMID_DOWN),
            rgb_reduce: KernelPipeline::new(device, &s::RGB_REDUCE),
            mc_count: KernelPipeline::new(device, &s::MC_COUNT),
            mc_scan: KernelPipeline::new(device, &s::MC_SCAN),
            mc_generate: KernelPipeline::new(device, &s::MC_GENERATE),
        }
    }
}
