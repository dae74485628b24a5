// SPDX-License-Identifier: MIT
//! One pass of the separable Gaussian that smooths the vertex gradients before the normal
//! cross product (003-digest §4.2, "gradient smoothing"). Each invocation averages one pixel
//! of grad_x and grad_y along `axis` (0 = x, 1 = y) over the 2r+1 taps with weights
//! exp(-i^2 / (2 sigma^2)), skipping invalid taps; an invalid centre stays invalid.
#import invalid

struct GradientSmoothParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Taps on each side.
    radius_px: u32,
    // 0 = along x, 1 = along y.
    axis: u32,
    // Gaussian sigma, pixels.
    sigma_px: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `GradientSmoothParams`.
@group(0) @binding(0) var<uniform> params: GradientSmoothParams;
// x gradients in.
@group(0) @binding(1) var<storage, read> grad_x_in: array<vec4<f32>>;
// y gradients in.
@group(0) @binding(2) var<storage, read> grad_y_in: array<vec4<f32>>;
// x gradients out.
@group(0) @binding(3) var<storage, read_write> grad_x_out: array<vec4<f32>>;
// y gradients out.
@group(0) @binding(4) var<storage, read_write> grad_y_out: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let ix = gid.y * w + gid.x;
    if !is_valid_f32(grad_x_in[ix].x) {
        grad_x_out[ix] = invalid_vec4();
        grad_y_out[ix] = invalid_vec4();
        return;
    }
    let radius = i32(params.radius_px);
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    let along = i32(select(gid.x, gid.y, params.axis == 1u));
    let extent = i32(select(w, h, params.axis == 1u));
    var sum_w = 0.0;
    var sum_x = vec3<f32>(0.0);
    var sum_y = vec3<f32>(0.0);
    for (var i = -radius; i <= radius; i++) {
        let p = along + i;
        if p < 0 || p >= extent {
            continue;
        }
        var tap_ix = u32(p) * w + gid.x;
        if params.axis == 0u {
            tap_ix = gid.y * w + u32(p);
        }
        let gx = grad_x_in[tap_ix];
        if !is_valid_f32(gx.x) {
            continue;
        }
        let gy = grad_y_in[tap_ix];
        let wt = exp(f32(i * i) * k);
        sum_w += wt;
        sum_x += wt * gx.xyz;
        sum_y += wt * gy.xyz;
    }
    grad_x_out[ix] = vec4<f32>(sum_x / sum_w, 0.0);
    grad_y_out[ix] = vec4<f32>(sum_y / sum_w, 0.0);
}
