// SPDX-License-Identifier: MIT
//! Each invocation computes the unit normals of two pixels of a vertex map, (x, 2y) and
//! (x, 2y + 1) (000-digest Eq. 4.3, 003-digest §4.2): n = normalize(grad_x x grad_y), flipped
//! to face the camera (n . v < 0, the eye at the origin), stored as (nx, ny, nz, 0); NaN where
//! the vertex or the gradients are invalid or the cross product vanishes.
//!
//! Without smoothing (radius 0) the gradients are the central differences
//! V(x+1, y) - V(x-1, y) and V(x, y+1) - V(x, y-1), taken here from the vertex map (invalid on
//! the image border or where the centre or one of its four neighbours is invalid): one pass
//! from vertices to normals. With smoothing, `vertex_gradients` has taken the differences and
//! the along-x pass of the separable Gaussian, and this takes the along-y pass: the weighted
//! mean, weights exp(-j^2 / (2 sigma^2)), of the valid gradients at the 2r+1 pixels (x, y+j)
//! within the image; an invalid centre stays invalid. The two pixels' windows share their
//! taps, each read once: 2r + 2 taps for two pixels instead of 2 (2r + 1).
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

// Writes the normal of pixel `ix` (vertex `v`) from its gradients `a` and `b` when `valid`:
// their cross product normalised and turned to face the camera; NaN where it vanishes or the
// gradients are not valid. (One call per pixel: a CPU adapter runs every branch's code.)
fn write_normal(ix: u32, v: vec4<f32>, a: vec3<f32>, b: vec3<f32>, valid: bool) {
    let c = cross(a, b);
    let norm_sq = dot(c, c);
    let n = c / sqrt(norm_sq);
    let facing = select(n, -n, dot(n, v.xyz) > 0.0);
    normal_in_camera[ix] = select(invalid_vec4(), vec4<f32>(facing, 0.0), valid && norm_sq > params.min_cross_norm_sq);
}

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    let y0 = 2u * gid.y;
    if gid.x >= w || y0 >= h {
        return;
    }
    let has_second = y0 + 1u < h;
    let ix0 = y0 * w + gid.x;
    let ix1 = select(ix0, ix0 + w, has_second);
    let v0 = vertex_in_camera[ix0];
    let v1 = vertex_in_camera[ix1];
    // Each pixel's gradients and whether it has them.
    var a0 = vec3<f32>(0.0);
    var b0 = vec3<f32>(0.0);
    var a1 = vec3<f32>(0.0);
    var b1 = vec3<f32>(0.0);
    var valid = vec2<bool>(false);
    if params.radius_px == 0u {
        // The central differences of each pixel.
        let g0 = central_differences(w, h, i32(gid.x), i32(y0));
        let g1 = central_differences(w, h, i32(gid.x), i32(y0 + 1u));
        a0 = g0.x;
        b0 = g0.y;
        a1 = g1.x;
        b1 = g1.y;
        valid = vec2<bool>(g0.valid, g1.valid);
    } else {
        // The along-y pass for both pixels at once: taps y0 - r to y0 + 1 + r, each read once
        // and weighed into the window of each pixel it lies in (ascending, as the CPU twin
        // sums them).
        let r = i32(params.radius_px);
        let k = -0.5 / (params.sigma_px * params.sigma_px);
        var sum_w = vec2<f32>(0.0);
        var own = vec2<bool>(false);
        for (var ty = i32(y0) - r; ty <= i32(y0) + 1 + r; ty++) {
            let tap = u32(clamp(ty, 0, i32(h) - 1)) * w + gid.x;
            let gx = grad_x[tap];
            let gy = grad_y[tap];
            let tap_valid = ty >= 0 && ty < i32(h) && is_valid_f32(gx.x);
            let j = vec2<i32>(ty - i32(y0), ty - i32(y0) - 1);
            let taken = vec2<bool>(tap_valid) & (abs(j) <= vec2<i32>(r));
            let wt = select(exp(vec2<f32>(j * j) * k), vec2<f32>(1.0), j == vec2<i32>(0));
            sum_w += select(vec2<f32>(0.0), wt, taken);
            a0 += select(vec3<f32>(0.0), wt.x * gx.xyz, taken.x);
            b0 += select(vec3<f32>(0.0), wt.x * gy.xyz, taken.x);
            a1 += select(vec3<f32>(0.0), wt.y * gx.xyz, taken.y);
            b1 += select(vec3<f32>(0.0), wt.y * gy.xyz, taken.y);
            own |= vec2<bool>(tap_valid) & (j == vec2<i32>(0));
        }
        a0 /= sum_w.x;
        b0 /= sum_w.x;
        a1 /= sum_w.y;
        b1 /= sum_w.y;
        // An invalid centre (vertex or gradient) stays invalid.
        valid = own & vec2<bool>(is_valid_f32(v0.z), is_valid_f32(v1.z));
    }
    write_normal(ix0, v0, a0, b0, valid.x);
    if has_second {
        write_normal(ix1, v1, a1, b1, valid.y);
    }
}
