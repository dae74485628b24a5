// SPDX-License-Identifier: MIT
//! The webfusion browser app: the core crate's kernels on WebGPU.
//!
//! Today it replays the bundled sample recording through the GPU preprocessing (the same WGSL
//! the native build runs on Vulkan) and shows the level-0 normal map and per-stage timings.
//! Status is published as JSON on `window.webfusion.status` for automated tests.
#![cfg(target_arch = "wasm32")]

mod app;

pub use app::start;
