// SPDX-License-Identifier: MIT
//! GPU-vs-CPU tests of every kernel on lavapipe (or any Vulkan adapter): synthetic inputs
//! with exact answers, a real TUM Kinect frame, and a negative control per comparison.
//! `tests/build.rs` declares every file of this folder as a module (`<capability>/<file>.rs`
//! under `<capability>`), so adding a test file edits no list.

#![expect(clippy::type_complexity, reason = "test runners return (GPU, CPU) output tuples")]

include!(concat!(env!("OUT_DIR"), "/test_tree.rs"));
