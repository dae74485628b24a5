// SPDX-License-Identifier: MIT
// Pinhole camera (000-digest Eq. 3.2 / 3.7). Pixel centres at integer coordinates, x right,
// y down, camera looking down +z. Mirrors `GpuIntrinsics` in core/src/kernels/mod.rs.

struct Intrinsics {
    // Focal length x, pixels.
    fx_px: f32,
    // Focal length y, pixels.
    fy_px: f32,
    // Principal point x, pixels.
    cx_px: f32,
    // Principal point y, pixels.
    cy_px: f32,
    // Width, pixels.
    width_px: u32,
    // Height, pixels.
    height_px: u32,
    _pad0: u32,
    _pad1: u32,
}

// Point in the camera frame seen at pixel (u, v) with depth z (metres).
fn back_project(k: Intrinsics, u_px: f32, v_px: f32, z_m: f32) -> vec3<f32> {
    return vec3<f32>((u_px - k.cx_px) * z_m / k.fx_px, (v_px - k.cy_px) * z_m / k.fy_px, z_m);
}
