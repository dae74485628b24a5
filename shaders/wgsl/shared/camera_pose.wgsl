// SPDX-License-Identifier: MIT
// A camera pose that a kernel renders or fuses at, bound as a uniform (which leaves the
// kernels' storage bindings within WebGPU's default 8 per stage) from a buffer that is either
// the GPU tracker's state (the `pose` at offset 0 of `TrackState`, a storage buffer with uniform
// usage too) or written by the host (given poses, a free view, a virtual sensor). Mirrors
// `CameraPose` in core/src/kernels (generated).

struct CameraPose {
    // Camera to world, column-major.
    world_from_camera: mat4x4<f32>,
    // World to camera (the rigid inverse of `world_from_camera`).
    camera_from_world: mat4x4<f32>,
    // 0: skip the work (the frame was not tracked: nothing is fused or re-predicted); else use
    // this pose.
    enabled: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}
