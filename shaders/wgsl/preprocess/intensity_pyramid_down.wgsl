// SPDX-License-Identifier: MIT
//! Each invocation computes one pixel of the next-coarser intensity level: the mean of the
//! 2x2 block of finer pixels it covers (pixel centres follow cx' = (cx - 0.5) / 2).

struct IntensityPyramidDownParams {
    // Finer level width, pixels.
    src_width_px: u32,
    // Finer level height, pixels.
    src_height_px: u32,
    // Coarser level width, pixels.
    dst_width_px: u32,
    // Coarser level height, pixels.
    dst_height_px: u32,
}

// Uniform `IntensityPyramidDownParams`.
@group(0) @binding(0) var<uniform> params: IntensityPyramidDownParams;
// Finer intensities.
@group(0) @binding(1) var<storage, read> src: array<f32>;
// Coarser intensities.
@group(0) @binding(2) var<storage, read_write> dst: array<f32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.dst_width_px || gid.y >= params.dst_height_px {
        return;
    }
    let x = min(2u * gid.x, params.src_width_px - 2u);
    let y = min(2u * gid.y, params.src_height_px - 2u);
    let w = params.src_width_px;
    let sum = (src[y * w + x] + src[y * w + x + 1u]) + (src[(y + 1u) * w + x] + src[(y + 1u) * w + x + 1u]);
    dst[gid.y * params.dst_width_px + gid.x] = 0.25 * sum;
}
