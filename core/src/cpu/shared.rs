// SPDX-License-Identifier: MIT
//! Twins of the functions in `shaders/wgsl/shared/`, same names and argument order.

/// The invalid marker (quiet NaN), as `invalid_f32()` in `shared/invalid.wgsl`.
pub const INVALID: f32 = f32::from_bits(0x7fc0_0000);
/// The invalid vec4.
pub const INVALID_VEC4: [f32; 4] = [INVALID; 4];

/// Twin of `invalid_f32()`.
pub fn invalid_f32() -> f32 {
    INVALID
}

/// Twin of `is_valid_f32()`: finite values are valid.
pub fn is_valid_f32(x: f32) -> bool {
    (x.to_bits() & 0x7f80_0000) != 0x7f80_0000
}

/// Twin of `depth_to_metres()` in `shared/depth.wgsl`.
pub fn depth_to_metres(raw_units: u32, metres_per_unit: f32, min_depth_m: f32, max_depth_m: f32) -> f32 {
    if raw_units == 0 {
        return invalid_f32();
    }
    let depth_m = raw_units as f32 * metres_per_unit;
    if depth_m < min_depth_m || depth_m > max_depth_m {
        return invalid_f32();
    }
    depth_m
}

/// Twin of `back_project()` in `shared/camera.wgsl`.
pub fn back_project(k: &crate::kernels::GpuIntrinsics, u_px: f32, v_px: f32, z_m: f32) -> [f32; 3] {
    [(u_px - k.cx_px) * z_m / k.fx_px, (v_px - k.cy_px) * z_m / k.fy_px, z_m]
}

/// Packs u16 values two per u32 word, low half first (the layout `depth_raw` uses).
pub fn pack_u16_pairs(values: &[u16]) -> Vec<u32> {
    values.chunks(2).map(|c| u32::from(c[0]) | (u32::from(*c.get(1).unwrap_or(&0)) << 16)).collect()
}

/// Packs bytes four per u32 word, little-endian (the layout `rgb8` uses).
pub fn pack_bytes(bytes: &[u8]) -> Vec<u32> {
    bytes.chunks(4).map(|c| c.iter().enumerate().fold(0u32, |w, (i, b)| w | (u32::from(*b) << (8 * i)))).collect()
}
