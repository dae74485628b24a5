// SPDX-License-Identifier: MIT
//! Each invocation computes the unit normal of one pixel of a vertex map (000-digest Eq. 4.3,
//! 003-digest §4.2): n = normalize(grad_x x grad_y), flipped to face the camera (n . v < 0, the
//! eye at the origin), stored as (nx, ny, nz, 0); NaN where the vertex or the gradients are
//! invalid or the cross product vanishes.
//!
//! Without smoothing (radius 0) the gradients are the central differences
//! V(x+1, y) - V(x-1, y) and V(x, y+1) - V(x, y-1), taken here from the vertex map (invalid on
//! the image border or where the centre or one of its four neighbours is invalid): one pass
//! from vertices to normals. With smoothing, `vertex_gradients` has taken the differences and
//! the along-x pass of the separable Gaussian, and this takes the along-y pass: the weighted
//! mean, weights exp(-j^2 / (2 sigma^2)), of the valid gradients at the 2r+1 pixels (x, y+j)
//! within the image; an invalid centre stays invalid.
#import invalid
#import vertex_differences

struct VertexNormalsParams {
    // Image width, pixels.
    width_px: u32,
    // Image height, pixels.
    height_px: u32,
    // Gradient smoothing taps on each side; 0: no smoothing (the gradient buffers are unread).
    radius_px: u32,
    // Gradient smoothing Gaussian sigma, pixels (unused at radius 0).
    sigma_px: f32,
    // Cross products with a squared norm at or below this (m^4) give no normal.
    min_cross_norm_sq: f32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Uniform `VertexNormalsParams`.
@group(0) @binding(0) var<uniform> params: VertexNormalsParams;
// Vertices, camera frame.
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// x gradients smoothed along x (`vertex_gradients`), when radius_px > 0.
@group(0) @binding(2) var<storage, read> grad_x: array<vec4<f32>>;
// y gradients smoothed along x (`vertex_gradients`), when radius_px > 0.
@group(0) @binding(3) var<storage, read> grad_y: array<vec4<f32>>;
// Out: unit normals (nx, ny, nz, 0), camera frame.
@group(0) @binding(4) var<storage, read_write> normal_in_camera: array<vec4<f32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let ix = gid.y * w + gid.x;
    let v = vertex_in_camera[ix];
    var a = vec3<f32>(0.0);
    var b = vec3<f32>(0.0);
    if params.radius_px == 0u {
        let g = central_differences(w, h, i32(gid.x), i32(gid.y));
        if !g.valid {
            normal_in_camera[ix] = invalid_vec4();
            return;
        }
        a = g.x;
        b = g.y;
    } else {
        if !is_valid_f32(v.z) || !is_valid_f32(grad_x[ix].x) {
            normal_in_camera[ix] = invalid_vec4();
            return;
        }
        let r = i32(params.radius_px);
        let k = -0.5 / (params.sigma_px * params.sigma_px);
        var sum_w = 0.0;
        for (var j = -r; j <= r; j++) {
            let y = i32(gid.y) + j;
            if y < 0 || y >= i32(h) {
                continue;
            }
            let tap = u32(y) * w + gid.x;
            let gx = grad_x[tap];
            if !is_valid_f32(gx.x) {
                continue;
            }
            let wt = select(exp(f32(j * j) * k), 1.0, j == 0);
            sum_w += wt;
            a += wt * gx.xyz;
            b += wt * grad_y[tap].xyz;
        }
        a /= sum_w;
        b /= sum_w;
    }
    let c = cross(a, b);
    let norm_sq = dot(c, c);
    if !(norm_sq > params.min_cross_norm_sq) {
        normal_in_camera[ix] = invalid_vec4();
        return;
    }
    var n = c / sqrt(norm_sq);
    if dot(n, v.xyz) > 0.0 {
        n = -n;
    }
    normal_in_camera[ix] = vec4<f32>(n, 0.0);
}
