// SPDX-License-Identifier: MIT
//! CPU reference of every kernel, one file per kernel with the kernel's name, taking the same
//! parameters and buffers in the same order as the WGSL bindings.
//!
//! These are written to mirror the shaders statement by statement (same loop order, same f32
//! arithmetic) rather than idiomatically, so GPU-vs-CPU tests can use tight tolerances and any
//! stage can be swapped for its reference when bisecting.

#![expect(clippy::needless_range_loop, reason = "loops mirror the per-invocation WGSL code")]

pub mod bilateral_filter;
pub mod color_to_float;
pub mod depth_pyramid_down;
pub mod depth_to_metres;
pub mod gradient_smooth;
pub mod icp_reduce;
pub mod intensity_pyramid_down;
pub mod marching_cubes;
pub mod mc_count;
pub mod mc_generate;
pub mod mc_scan;
pub mod normal_map;
pub mod preprocess;
pub mod raycast;
pub mod rgb_reduce;
pub mod shared;
pub mod tsdf_integrate;
pub mod vertex_gradients;
pub mod vertex_map;

pub use bilateral_filter::bilateral_filter;
pub use color_to_float::color_to_float;
pub use depth_pyramid_down::depth_pyramid_down;
pub use depth_to_metres::depth_to_metres;
pub use gradient_smooth::gradient_smooth;
pub use icp_reduce::icp_reduce;
pub use intensity_pyramid_down::intensity_pyramid_down;
pub use mc_count::mc_count;
pub use mc_generate::mc_generate;
pub use mc_scan::mc_scan;
pub use normal_map::normal_map;
pub use raycast::raycast;
pub use rgb_reduce::rgb_reduce;
pub use tsdf_integrate::tsdf_integrate;
pub use vertex_gradients::vertex_gradients;
pub use vertex_map::vertex_map;

/// Which kernels have a CPU reference (all of them, today); a kernel added without one must
/// say why here, so coverage is explicit.
#[derive(Clone, Copy, Debug)]
pub enum CpuKernel {
    /// A reference exists.
    Present,
    /// No reference, and why.
    Missing {
        /// The reason.
        reason: &'static str,
    },
}

/// CPU-reference coverage by kernel name.
pub fn coverage(kernel_name: &str) -> CpuKernel {
    match kernel_name {
        "depth_to_metres" | "bilateral_filter" | "depth_pyramid_down" | "vertex_map" | "vertex_gradients" | "gradient_smooth"
        | "normal_map" | "color_to_float" | "tsdf_integrate" | "raycast" | "icp_reduce" | "intensity_pyramid_down" | "rgb_reduce" => CpuKernel::Present,
        "mc_count" | "mc_scan" | "mc_generate" => CpuKernel::Present,
        _ => CpuKernel::Missing { reason: "kernel not yet paired with a CPU reference" },
    }
}
