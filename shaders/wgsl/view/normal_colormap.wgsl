// SPDX-License-Identifier: MIT
//! Each invocation colours one pixel of a normal map (x, y, z, _; NaN = none) with the shared
//! normal map, into a view buffer whose rows are `row_stride_px` apart (padded so the buffer
//! copies into a texture). Padding pixels are not written.
#import invalid
#import colormap

struct NormalColormapParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Pixels from one row of the output to the next (≥ width_px).
    row_stride_px: u32,
    _pad0: u32,
}

@group(0) @binding(0) var<uniform> params: NormalColormapParams;
// Unit normals (nx, ny, nz, _), any frame; NaN where there is none.
@group(0) @binding(1) var<storage, read> normals: array<vec4<f32>>;
// Out: RGBA8 pixels (red in the low byte), rows row_stride_px apart.
@group(0) @binding(2) var<storage, read_write> rgba8: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    rgba8[gid.y * params.row_stride_px + gid.x] = normal_colour(normals[gid.y * params.width_px + gid.x]);
}
