// SPDX-License-Identifier: MIT
//! Every WGSL kernel of webfusion, one compute entry point per file, grouped by capability:
//! `wgsl/<capability>/<kernel>.wgsl` (preprocess, fusion, mesh, views, …), with `#import`able
//! helpers in `wgsl/shared/`.
//!
//! `build.rs` resolves `#import name` lines against `wgsl/shared/name.wgsl`, parses and
//! validates each kernel with naga (a WGSL error fails `cargo build` with naga's annotated
//! message), and reflects its workgroup size, bindings and struct layouts into the constants
//! below. The same text is compiled by wgpu natively (Vulkan) and in the browser (WebGPU), so
//! there is exactly one source per kernel.
//!
//! The same reflection generates, for `webfusion-core`, the `#[repr(C)]` mirrors of the WGSL
//! structs, each kernel's typed bindings and bind group layout and the pipeline registry, and
//! for `webfusion-tests` the layout checks: adding a kernel means adding its WGSL file, its CPU
//! twin and its test, with no list to edit.
//!
//! Set `WGSL_DUMP_DIR=/some/dir` while building to write out the stitched sources.

/// Access of a storage texture binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StorageTextureAccess {
    /// `write`.
    WriteOnly,
    /// `read`.
    ReadOnly,
    /// `read_write`.
    ReadWrite,
}

/// Dimension of a texture binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureDimension {
    /// `texture_1d`.
    D1,
    /// `texture_2d`.
    D2,
    /// `texture_2d_array`.
    D2Array,
    /// `texture_3d`.
    D3,
    /// `texture_cube`.
    Cube,
    /// `texture_cube_array`.
    CubeArray,
}

/// Texel type of a sampled texture binding.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TextureSampleType {
    /// `texture_*<f32>` used with a sampler.
    Float,
    /// `texture_*<f32>` read with `textureLoad` only: binds any float format, `r32float` too.
    UnfilterableFloat,
    /// `texture_*<i32>`.
    Sint,
    /// `texture_*<u32>`.
    Uint,
}

/// How a kernel binding is declared in WGSL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
    /// `texture_storage_*<format, access>`.
    StorageTexture {
        /// Texel format, spelled as the `wgpu::TextureFormat` variant (e.g. `Rgba8Unorm`).
        format: &'static str,
        /// Declared access.
        access: StorageTextureAccess,
        /// Dimension.
        dimension: TextureDimension,
    },
    /// A sampled texture, `texture_*<T>`.
    Texture {
        /// Texel type.
        sample_type: TextureSampleType,
        /// Dimension.
        dimension: TextureDimension,
        /// `texture_multisampled_*`.
        multisampled: bool,
    },
    /// `sampler` or `sampler_comparison`.
    Sampler {
        /// `sampler_comparison`.
        comparison: bool,
    },
}

impl BindingKind {
    /// Whether the binding is a buffer (uniform or storage).
    pub fn is_buffer(&self) -> bool {
        matches!(self, Self::Uniform | Self::StorageRead | Self::StorageReadWrite)
    }
}

/// One `@group(g) @binding(b)` resource of a kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// Bind group index.
    pub group: u32,
    /// Binding index inside the group.
    pub binding: u32,
    /// WGSL variable name (also the field name of the kernel's typed bindings).
    pub name: &'static str,
    /// Declared address space and access.
    pub kind: BindingKind,
    /// Size in bytes of the fixed-size part of a buffer binding (the element stride for
    /// runtime arrays, the struct size otherwise); 0 for textures and samplers.
    pub min_size_bytes: u32,
    /// The declared WGSL type, e.g. `array<vec4<f32>>`.
    pub wgsl_type: &'static str,
}

/// One member of a reflected WGSL struct.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StructMember {
    /// Member name.
    pub name: &'static str,
    /// Byte offset inside the struct.
    pub offset_bytes: u32,
    /// Size in bytes.
    pub size_bytes: u32,
    /// The WGSL type, e.g. `mat4x4<f32>`.
    pub wgsl_type: &'static str,
}

/// Layout of a WGSL struct, used to check the `#[repr(C)]` Rust mirror.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StructLayout {
    /// WGSL struct name.
    pub name: &'static str,
    /// Size in bytes (WGSL `SizeOf`).
    pub size_bytes: u32,
    /// Members in declaration order.
    pub members: &'static [StructMember],
}

/// A validated compute kernel.
#[derive(Clone, Copy, Debug)]
pub struct Kernel {
    /// File stem, e.g. `depth_to_metres`; unique over all capabilities.
    pub name: &'static str,
    /// Capability folder, e.g. `preprocess`.
    pub capability: &'static str,
    /// First sentence of the kernel's `//!` doc.
    pub summary: &'static str,
    /// Stitched WGSL source (imports resolved).
    pub source: &'static str,
    /// Name of the single `@compute` entry point.
    pub entry_point: &'static str,
    /// `@workgroup_size(x, y, z)`.
    pub workgroup_size: [u32; 3],
    /// Why the kernel has no CPU twin, if its doc says `cpu-twin: none: <reason>`.
    pub cpu_twin_exemption: Option<&'static str>,
    /// Bindings in (group, binding) order.
    pub bindings: &'static [Binding],
    /// Every struct used by a binding, for layout checks.
    pub structs: &'static [StructLayout],
}

include!(concat!(env!("OUT_DIR"), "/kernels.rs"));

impl Kernel {
    /// Looks up a reflected struct by WGSL name.
    pub fn struct_layout(&self, name: &str) -> Option<&'static StructLayout> {
        self.structs.iter().find(|s| s.name == name)
    }

    /// Invocations per workgroup.
    pub fn invocations_per_workgroup(&self) -> u32 {
        self.workgroup_size.iter().product()
    }
}

/// Finds a kernel by file stem.
pub fn kernel(name: &str) -> Option<&'static Kernel> {
    ALL.iter().copied().find(|k| k.name == name)
}
