// SPDX-License-Identifier: MIT
//! webfusion's core: one pipeline of WGSL kernels that runs natively (Vulkan) and in the
//! browser (WebGPU), the Rust CPU reference of every kernel, and the frame/camera/pose types
//! and log readers shared by the bridge and the web app.
//!
//! The crate has no tokio and no web-sys in its API: the GPU context is created by an async
//! constructor that native code drives with `pollster` and the browser with
//! `wasm-bindgen-futures`.

pub mod camera;
pub mod codec;
pub mod cpu;
pub mod engine;
mod error;
pub mod eval;
pub mod frame;
pub mod fusion;
pub mod gpu;
pub mod io;
pub mod kernels;
pub mod map;
pub mod mesh;
pub mod odometry;
pub mod planes;
pub mod pose;
pub mod preprocess;
pub mod protocol;
pub mod recording;
pub mod sim;
pub mod source;
pub mod tsdf;
pub mod view;

pub use camera::{PinholeIntrinsics, RgbdCalibration};
pub use error::{Error, Result};
pub use frame::{ColorImage, DepthImage, RgbdFrame};
pub use gpu::{Gpu, GpuCounts, GpuOptions};
pub use pose::Se3;
