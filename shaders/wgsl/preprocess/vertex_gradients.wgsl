// SPDX-License-Identifier: MIT
//! Each invocation computes the vertex-map gradients of two pixels side by side, (2x, y) and
//! (2x + 1, y), for `vertex_normals` when the gradients are smoothed (003-digest §4.2): the
//! central differences grad_x = V(x+1, y) - V(x-1, y) and grad_y = V(x, y+1) - V(x, y-1), then the first, along-x
//! pass of Boots' separable Gaussian: the weighted mean, weights exp(-i^2 / (2 sigma^2)), of the
//! differences at the 2r+1 pixels (x+i, y) that have them (each computed here from the vertex
//! map: the differences are never stored). Stored as (dx, dy, dz, 0) in metres; invalid (NaN)
//! where the pixel itself has no differences (the image border, or the centre or one of its
//! four neighbours invalid). `vertex_normals` takes the along-y pass.
//!
//! The invocation walks the 2r+2 pixels whose differences its two pixels' windows need from
//! left to right, keeping the row's vertices left of, at and right of the current pixel, so
//! each pixel's differences cost three reads (right, above, below) instead of five and serve
//! both windows: 3 (2r + 2) + 2 reads for two pixels instead of 10 (2r + 1) (on CPU adapters a
//! read is a scalar load per lane and costs more than the arithmetic). No workgroup memory: CPU adapters (lavapipe, SwiftShader) run a
//! workgroup with barriers as one coroutine per invocation, which costs more than it saves.
#import invalid

struct VertexGradientsParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Smoothing taps on each side.
    radius_px: u32,
    // Smoothing Gaussian sigma, pixels.
    sigma_px: f32,
}

// Uniform `VertexGradientsParams`.
@group(0) @binding(0) var<uniform> params: VertexGradientsParams;
// Vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// Out: V(x+1) - V(x-1), smoothed along x, metres.
@group(0) @binding(2) var<storage, read_write> grad_x: array<vec4<f32>>;
// Out: V(y+1) - V(y-1), smoothed along x, metres.
@group(0) @binding(3) var<storage, read_write> grad_y: array<vec4<f32>>;

// The vertex at column `x` of the row starting at `row` (x clamped into the image: a clamped
// read is never used, a pixel beside the border has no differences).
fn vertex_at(row: u32, x: i32) -> vec4<f32> {
    return vertex_in_camera[row + u32(clamp(x, 0, i32(params.width_px) - 1))];
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = i32(params.width_px);
    let h = i32(params.height_px);
    let x0 = 2 * i32(gid.x);
    let y = i32(gid.y);
    if x0 >= w || y >= h {
        return;
    }
    let r = i32(params.radius_px);
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    let row = u32(y * w);
    let row_above = u32(max(y - 1, 0) * w);
    let row_below = u32(min(y + 1, h - 1) * w);
    // Rows 0 and h - 1 have no differences.
    let inner_row = y >= 1 && y + 1 < h;
    var left = vertex_at(row, x0 - r - 1);
    var centre = vertex_at(row, x0 - r);
    // Per pixel (x0, x0 + 1): the weights, the weighted sums and whether it has differences.
    var sum_w = vec2<f32>(0.0);
    var sum_x0 = vec3<f32>(0.0);
    var sum_y0 = vec3<f32>(0.0);
    var sum_x1 = vec3<f32>(0.0);
    var sum_y1 = vec3<f32>(0.0);
    var own = vec2<bool>(false);
    for (var p = x0 - r; p <= x0 + 1 + r; p++) {
        let right = vertex_at(row, p + 1);
        let above = vertex_at(row_above, p);
        let below = vertex_at(row_below, p);
        // The central differences at (p, y), as central_differences() takes them.
        let valid = inner_row && p >= 1 && p + 1 < w && is_valid_f32(centre.z) && is_valid_f32(left.z) && is_valid_f32(right.z) && is_valid_f32(above.z) && is_valid_f32(below.z);
        let gx = right.xyz - left.xyz;
        let gy = below.xyz - above.xyz;
        // Tap i of each pixel's window (ascending, as the CPU twin sums them).
        let i = vec2<i32>(p - x0, p - x0 - 1);
        let taken = vec2<bool>(valid) & (abs(i) <= vec2<i32>(r));
        let wt = select(exp(vec2<f32>(i * i) * k), vec2<f32>(1.0), i == vec2<i32>(0));
        sum_w += select(vec2<f32>(0.0), wt, taken);
        sum_x0 += select(vec3<f32>(0.0), wt.x * gx, taken.x);
        sum_y0 += select(vec3<f32>(0.0), wt.x * gy, taken.x);
        sum_x1 += select(vec3<f32>(0.0), wt.y * gx, taken.y);
        sum_y1 += select(vec3<f32>(0.0), wt.y * gy, taken.y);
        own |= vec2<bool>(valid) & (i == vec2<i32>(0));
        left = centre;
        centre = right;
    }
    // A pixel without differences of its own has no gradients.
    let ix = row + u32(x0);
    grad_x[ix] = select(invalid_vec4(), vec4<f32>(sum_x0 / sum_w.x, 0.0), own.x);
    grad_y[ix] = select(invalid_vec4(), vec4<f32>(sum_y0 / sum_w.x, 0.0), own.x);
    if x0 + 1 < w {
        grad_x[ix + 1u] = select(invalid_vec4(), vec4<f32>(sum_x1 / sum_w.y, 0.0), own.y);
        grad_y[ix + 1u] = select(invalid_vec4(), vec4<f32>(sum_y1 / sum_w.y, 0.0), own.y);
    }
}
