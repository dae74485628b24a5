// SPDX-License-Identifier: MIT
//! The webfusion browser app: connects to a `webfusion serve` bridge over WebSocket and runs
//! the full KinectFusion pipeline (the same core crate and WGSL as the native build) on
//! WebGPU, with colour, depth, normal, model and free 3D views, playback controls, settings
//! and exports. Status and the trajectory are published on `window.webfusion` for tests.
#![cfg(target_arch = "wasm32")]

mod app;
mod canvas;
mod fusion_mode;
mod link;
mod planes_world;
mod sim;
mod status;
mod ui;
mod view;

pub use app::start;

#[cfg(test)]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_browser);
