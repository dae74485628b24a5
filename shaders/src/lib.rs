// SPDX-License-Identifier: MIT
//! Every WGSL kernel of webfusion, one compute entry point per file.
//!
//! `build.rs` resolves `#import name` lines against `wgsl/shared/name.wgsl`, parses and
//! validates each kernel with naga (a WGSL error fails `cargo build` with naga's annotated
//! message), and reflects its workgroup size, bindings and uniform struct layouts into the
//! constants below. The same text is compiled by wgpu natively (Vulkan) and in the browser
//! (WebGPU), so there is exactly one source per kernel.
//!
//! Set `WGSL_DUMP_DIR=/some/dir` while building to write out the stitched sources.

/// How a kernel binding is declared in WGSL.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BindingKind {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>`.
    StorageRead,
    /// `var<storage, read_write>`.
    StorageReadWrite,
}

/// One `@group(g) @binding(b)` resource of a kernel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Binding {
    /// Bind group index.
    pub group: u32,
    /// Binding index inside the group.
    pub binding: u32,
    /// WGSL variable name.
    pub name: &'static str,
    /// Declared address space and access.
    pub kind: BindingKind,
    /// Size in bytes of the fixed-size part of the binding (the element stride for runtime
    /// arrays, the struct size for uniforms).
    pub min_size_bytes: u32,
}

/// One member of a reflected WGSL struct.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StructMember {
    /// Member name.
    pub name: &'static str,
    /// Byte offset inside the struct.
    pub offset_bytes: u32,
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
    /// File stem, e.g. `depth_to_metres`; also the entry point's label prefix.
    pub name: &'static str,
    /// Stitched WGSL source (imports resolved).
    pub source: &'static str,
    /// Name of the single `@compute` entry point.
    pub entry_point: &'static str,
    /// `@workgroup_size(x, y, z)`.
    pub workgroup_size: [u32; 3],
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
}

/// Finds a kernel by file stem.
pub fn kernel(name: &str) -> Option<&'static Kernel> {
    ALL.iter().copied().find(|k| k.name == name)
}
