// SPDX-License-Identifier: MIT
//! Each invocation computes the vertex-map gradients of one pixel for `vertex_normals` when
//! the gradients are smoothed (003-digest §4.2): the central differences
//! grad_x = V(x+1, y) - V(x-1, y) and grad_y = V(x, y+1) - V(x, y-1), then the first, along-x
//! pass of Boots' separable Gaussian: the weighted mean, weights exp(-i^2 / (2 sigma^2)), of the
//! differences at the 2r+1 pixels (x+i, y) that have them (each computed here from the vertex
//! map: the differences are never stored). Stored as (dx, dy, dz, 0) in metres; invalid (NaN)
//! where the pixel itself has no differences (the image border, or the centre or one of its
//! four neighbours invalid). `vertex_normals` takes the along-y pass.
//!
//! No workgroup memory: CPU adapters (lavapipe, SwiftShader) run a workgroup with barriers as
//! one coroutine per invocation, which cost more than the recomputed differences save.
#import invalid
#import vertex_differences

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

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x >= params.width_px || gid.y >= params.height_px {
        return;
    }
    let ix = gid.y * params.width_px + gid.x;
    let x = i32(gid.x);
    let y = i32(gid.y);
    if !central_differences(params.width_px, params.height_px, x, y).valid {
        grad_x[ix] = invalid_vec4();
        grad_y[ix] = invalid_vec4();
        return;
    }
    let r = i32(params.radius_px);
    let k = -0.5 / (params.sigma_px * params.sigma_px);
    var sum_w = 0.0;
    var sum_x = vec3<f32>(0.0);
    var sum_y = vec3<f32>(0.0);
    for (var i = -r; i <= r; i++) {
        let g = central_differences(params.width_px, params.height_px, x + i, y);
        if !g.valid {
            continue;
        }
        // The centre's weight is exactly 1, as `vertex_normals`' radius-0 path assumes.
        let wt = select(exp(f32(i * i) * k), 1.0, i == 0);
        sum_w += wt;
        sum_x += wt * g.x;
        sum_y += wt * g.y;
    }
    grad_x[ix] = vec4<f32>(sum_x / sum_w, 0.0);
    grad_y[ix] = vec4<f32>(sum_y / sum_w, 0.0);
}
