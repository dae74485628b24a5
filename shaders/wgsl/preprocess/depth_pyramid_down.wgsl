// SPDX-License-Identifier: MIT
//! Each invocation makes one pixel of the next-coarser depth level (000-digest §1.3: block
//! filter then half resolution) from the 2x2 block below it: the mean of the block's valid
//! depths that lie within max_depth_diff_m of the block's nearest valid depth, so blocks that
//! straddle an occlusion edge keep the foreground instead of inventing a depth in between.
#import invalid

struct DepthPyramidDownParams {
    // Fine level width, pixels.
    src_width_px: u32,
    // Fine level height, pixels.
    src_height_px: u32,
    // Coarse level width (fine / 2, rounded down).
    dst_width_px: u32,
    // Coarse level height (fine / 2, rounded down).
    dst_height_px: u32,
    // Block samples farther than this behind the block's nearest sample are left out, metres.
    max_depth_diff_m: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `DepthPyramidDownParams`.
@group(0) @binding(0) var<uniform> params: DepthPyramidDownParams;
// Fine depth, metres.
@group(0) @binding(1) var<storage, read> depth_fine_m: array<f32>;
// Coarse depth, metres.
@group(0) @binding(2) var<storage, read_write> depth_coarse_m: array<f32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.dst_width_px || gid.y >= params.dst_height_px {
        return;
    }
    var block: array<f32, 4>;
    var nearest_m = 3.0e38;
    var n_valid = 0u;
    for (var i = 0u; i < 4u; i++) {
        let x = 2u * gid.x + (i & 1u);
        let y = 2u * gid.y + (i >> 1u);
        let d_m = depth_fine_m[y * params.src_width_px + x];
        block[i] = d_m;
        if is_valid_f32(d_m) {
            nearest_m = min(nearest_m, d_m);
            n_valid++;
        }
    }
    let out_ix = gid.y * params.dst_width_px + gid.x;
    if n_valid == 0u {
        depth_coarse_m[out_ix] = invalid_f32();
        return;
    }
    var sum_m = 0.0;
    var n_used = 0u;
    for (var i = 0u; i < 4u; i++) {
        let d_m = block[i];
        if is_valid_f32(d_m) && d_m - nearest_m <= params.max_depth_diff_m {
            sum_m += d_m;
            n_used++;
        }
    }
    depth_coarse_m[out_ix] = sum_m / f32(n_used);
}
