// SPDX-License-Identifier: MIT
//! CPU reference of every kernel: `cpu/<capability>/<kernel>.rs` defines `pub fn <kernel>`,
//! taking the same parameters and buffers in the same order as the WGSL bindings, and is
//! re-exported here as `cpu::<kernel>`. `core/build.rs` builds this module tree from the files
//! it finds, and the coverage list ([`TWINS`], [`coverage`]) with it.
//!
//! These are written to mirror the shaders statement by statement (same loop order, same f32
//! arithmetic) rather than idiomatically, so GPU-vs-CPU tests can use tight tolerances and any
//! stage can be swapped for its reference when bisecting. Files of a capability folder that are
//! named after no kernel are helpers shared by its twins (e.g. `mesh/marching_cubes.rs`) or CPU
//! compositions of several kernels (`preprocess/chain.rs`).

#![expect(clippy::needless_range_loop, reason = "loops mirror the per-invocation WGSL code")]

pub mod shared;

include!(concat!(env!("OUT_DIR"), "/cpu_tree.rs"));

/// Whether a kernel has a CPU reference; a kernel without one must say why in its WGSL doc
/// (`//! cpu-twin: none: <reason>`), so coverage is explicit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuKernel {
    /// `core/src/cpu/<capability>/<kernel>.rs` exists.
    Present,
    /// No reference, and why.
    Missing {
        /// The reason.
        reason: &'static str,
    },
}

/// CPU-reference coverage of the kernel called `kernel_name`.
pub fn coverage(kernel_name: &str) -> CpuKernel {
    if TWINS.contains(&kernel_name) {
        return CpuKernel::Present;
    }
    match webfusion_shaders::kernel(kernel_name).and_then(|k| k.cpu_twin_exemption) {
        Some(reason) => CpuKernel::Missing { reason },
        None => CpuKernel::Missing { reason: "no core/src/cpu/<capability>/<kernel>.rs and no `cpu-twin: none:` reason in its WGSL doc" },
    }
}
