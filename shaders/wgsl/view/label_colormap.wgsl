// SPDX-License-Identifier: MIT
//! Each invocation colours one pixel of a plane label image over the frame's colour (seed
//! 003's segmentation view): a pixel of plane l < `label_count` gets its plane's colour
//! (shared plane_colour) mixed 60/40 with its own colour, any other pixel its own colour at
//! 40 % grey, into a view buffer whose rows are `row_stride_px` apart. Padding pixels are not
//! written.
#import invalid
#import colormap
#import planes

struct LabelColormapParams {
    // Image width and height, pixels.
    width_px: u32,
    height_px: u32,
    // Pixels from one row of the output to the next (≥ width_px).
    row_stride_px: u32,
    // Labels below this are planes.
    label_count: u32,
}

@group(0) @binding(0) var<uniform> params: LabelColormapParams;
// Per pixel its plane, or NO_LABEL.
@group(0) @binding(1) var<storage, read> labels: array<u32>;
// The frame's colour (r, g, b, 1) in [0, 1].
@group(0) @binding(2) var<storage, read> color: array<vec4<f32>>;
// Out: RGBA8 pixels (red in the low byte), rows row_stride_px apart.
@group(0) @binding(3) var<storage, read_write> rgba8: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let c = color[ix].rgb;
    let l = labels[ix];
    var out = vec3<f32>(0.4 * dot(c, vec3<f32>(0.299, 0.587, 0.114)));
    if l < params.label_count {
        out = 0.6 * plane_colour(l) + 0.4 * c;
    }
    rgba8[gid.y * params.row_stride_px + gid.x] = pack_rgba8(vec4<f32>(out, 1.0));
}
