// SPDX-License-Identifier: MIT
//! Each invocation colours one pixel of a raw depth image (sensor units, two u16 per word, as
//! uploaded) with the shared depth map, into a view buffer whose rows are `row_stride_px`
//! apart (padded so the buffer copies into a texture). Padding pixels are not written.
#import invalid
#import colormap

struct DepthColormapParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Pixels from one row of the output to the next (≥ width_px).
    row_stride_px: u32,
    // Metres per raw depth unit.
    metres_per_unit: f32,
    // Depth drawn at the warm end of the map, metres.
    max_depth_m: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: DepthColormapParams;
// Raw depth, pixel i in bits 16 (i & 1) .. 16 (i & 1) + 15 of word i / 2; 0 = no return.
@group(0) @binding(1) var<storage, read> depth_raw: array<u32>;
// Out: RGBA8 pixels (red in the low byte), rows row_stride_px apart.
@group(0) @binding(2) var<storage, read_write> rgba8: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let raw = (depth_raw[ix >> 1u] >> (16u * (ix & 1u))) & 0xffffu;
    rgba8[gid.y * params.row_stride_px + gid.x] = depth_colour(f32(raw) * params.metres_per_unit, params.max_depth_m);
}
