// SPDX-License-Identifier: MIT
//! Each invocation filters four depth pixels (metres) side by side along x, (4x, y) to
//! (4x + 3, y), one per component of its vectors, with a (2r+1)^2 bilateral filter
//! (000-digest Eq. 4.1): weights exp(-|dq|^2 / (2 sigma_space^2) - (d_q - d_p)^2 / (2 sigma_range^2))
//! over the valid neighbours, normalised by their sum. Invalid centres stay invalid; invalid
//! neighbours are skipped, so holes never bleed into valid depth. A neighbour is read once for
//! all four pixels: 2r+4 reads per window row instead of 4(2r+1) (on CPU adapters a read is a
//! scalar load per lane and costs more than the arithmetic); each pixel still sums its own
//! window's taps in the same order as the CPU twin.
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
    let x0 = 4u * gid.x;
    if x0 >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let width = i32(params.width_px);
    let height = i32(params.height_px);
    let row = gid.y * params.width_px;
    let last = params.width_px - 1u;
    let xs = vec4<u32>(x0, x0 + 1u, x0 + 2u, x0 + 3u);
    let present = xs < vec4<u32>(params.width_px);
    let c = select(vec4<f32>(invalid_f32()), vec4<f32>(depth_in_m[row + x0], depth_in_m[row + min(xs.y, last)], depth_in_m[row + min(xs.z, last)], depth_in_m[row + min(xs.w, last)]), present);
    let radius = i32(params.radius_px);
    let k_space = -0.5 / (params.sigma_space_px * params.sigma_space_px);
    let k_range = -0.5 / (params.sigma_range_m * params.sigma_range_m);
    var sum_w = vec4<f32>(0.0);
    var sum_wd = vec4<f32>(0.0);
    let x_lo = max(i32(x0) - radius, 0);
    let x_hi = min(i32(x0) + 3 + radius, width - 1);
    let y_lo = max(i32(gid.y) - radius, 0);
    let y_hi = min(i32(gid.y) + radius, height - 1);
    for (var y = y_lo; y <= y_hi; y++) {
        let dy = y - i32(gid.y);
        for (var x = x_lo; x <= x_hi; x++) {
            let d_m = depth_in_m[y * width + x];
            let dx = vec4<i32>(x) - vec4<i32>(xs);
            let diff_m = vec4<f32>(d_m) - c;
            let w = exp(vec4<f32>(dx * dx + vec4<i32>(dy * dy)) * k_space + diff_m * diff_m * k_range);
            // Only within each pixel's own window, and only valid neighbours.
            let inside = vec4<bool>(is_valid_f32(d_m)) & (abs(dx) <= vec4<i32>(radius));
            sum_w += select(vec4<f32>(0.0), w, inside);
            sum_wd += select(vec4<f32>(0.0), w * d_m, inside);
        }
    }
    // Invalid centres stay invalid.
    let out = select(vec4<f32>(invalid_f32()), sum_wd / sum_w, is_valid_vec4(c));
    for (var j = 0u; j < 4u; j++) {
        if present[j] {
            depth_out_m[row + xs[j]] = out[j];
        }
    }
}
