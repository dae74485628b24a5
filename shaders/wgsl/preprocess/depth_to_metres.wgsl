// SPDX-License-Identifier: MIT
//! Each invocation converts one depth pixel from raw sensor units (u16, two packed per u32
//! word, low half first) to metres, writing NaN where the sensor gave 0 or the depth lies
//! outside [min_depth_m, max_depth_m].
#import depth

struct DepthToMetresParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Metres per raw depth unit.
    metres_per_unit: f32,
    // Nearest valid depth, metres.
    min_depth_m: f32,
    // Farthest valid depth, metres.
    max_depth_m: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `DepthToMetresParams`.
@group(0) @binding(0) var<uniform> params: DepthToMetresParams;
// Raw depth, two u16 per u32 word (low half first).
@group(0) @binding(1) var<storage, read> depth_raw: array<u32>;
// Output depth, metres (f32 per pixel).
@group(0) @binding(2) var<storage, read_write> depth_m: array<f32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let pixel_ix = gid.y * params.width_px + gid.x;
    let word = depth_raw[pixel_ix / 2u];
    let raw_units = (word >> ((pixel_ix & 1u) * 16u)) & 0xffffu;
    depth_m[pixel_ix] = depth_to_metres(raw_units, params.metres_per_unit, params.min_depth_m, params.max_depth_m);
}
