// SPDX-License-Identifier: MIT
//! Each invocation converts one RGB8 pixel (bytes packed four per u32 word, little-endian) to
//! linear floats in [0, 1] as (r, g, b, 1), and to an intensity
//! 0.299 r + 0.587 g + 0.114 b (ITU-R BT.601 luma, as DVO and OpenCV use) for the
//! photometric and feature stages.

struct ColorToFloatParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    _pad0: u32,
    _pad1: u32,
}

// Uniform `ColorToFloatParams`.
@group(0) @binding(0) var<uniform> params: ColorToFloatParams;
// RGB8 bytes packed four per u32 word.
@group(0) @binding(1) var<storage, read> rgb8: array<u32>;
// Colour (r, g, b, 1) in [0, 1].
@group(0) @binding(2) var<storage, read_write> color: array<vec4<f32>>;
// Intensity in [0, 1].
@group(0) @binding(3) var<storage, read_write> intensity: array<f32>;

fn byte_at(byte_ix: u32) -> u32 {
    return (rgb8[byte_ix / 4u] >> ((byte_ix & 3u) * 8u)) & 0xffu;
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let r = f32(byte_at(3u * ix)) / 255.0;
    let g = f32(byte_at(3u * ix + 1u)) / 255.0;
    let b = f32(byte_at(3u * ix + 2u)) / 255.0;
    color[ix] = vec4<f32>(r, g, b, 1.0);
    intensity[ix] = 0.299 * r + 0.587 * g + 0.114 * b;
}
