// SPDX-License-Identifier: MIT
//! GPU-vs-CPU tests of every kernel on lavapipe (or any Vulkan adapter): synthetic inputs
//! with exact answers, a real TUM Kinect frame, and a negative control per comparison.

#![expect(clippy::type_complexity, reason = "test runners return (GPU, CPU) output tuples")]

mod bilateral_filter;
mod color_to_float;
mod depth_pyramid_down;
mod depth_to_metres;
mod gpu_context;
mod fusion;
mod gradient_smooth;
mod icp_reduce;
mod intensity_pyramid_down;
mod layout;
mod mc_count;
mod mc_generate;
mod mc_scan;
mod mesh;
mod normal_map;
mod preprocess;
mod raycast;
mod rgb_reduce;
mod synthetic;
mod tsdf_integrate;
mod vertex_gradients;
mod vertex_map;
