// SPDX-License-Identifier: MIT
// Central differences of a vertex map, the gradients a normal is crossed from (003-digest
// §4.2). The importing kernel declares `vertex_in_camera: array<vec4<f32>>` (camera frame,
// NaN z where invalid). Mirrors core/src/cpu/preprocess/vertex_gradients.rs::central_differences.
#import invalid

struct Differences {
    // V(x+1, y) - V(x-1, y), metres.
    x: vec3<f32>,
    // V(x, y+1) - V(x, y-1), metres.
    y: vec3<f32>,
    valid: bool,
}

// The central differences at pixel (px, py) of a width_px x height_px map; invalid outside the
// image, on its border, or where the centre or one of its four neighbours is invalid.
fn central_differences(width_px: u32, height_px: u32, px: i32, py: i32) -> Differences {
    let w = i32(width_px);
    var g = Differences(vec3<f32>(0.0), vec3<f32>(0.0), false);
    if px < 1 || py < 1 || px + 1 >= w || py + 1 >= i32(height_px) {
        return g;
    }
    let ix = u32(py * w + px);
    let centre = vertex_in_camera[ix];
    let left = vertex_in_camera[ix - 1u];
    let right = vertex_in_camera[ix + 1u];
    let up = vertex_in_camera[ix - u32(w)];
    let down = vertex_in_camera[ix + u32(w)];
    if !is_valid_f32(centre.z) || !is_valid_f32(left.z) || !is_valid_f32(right.z) || !is_valid_f32(up.z) || !is_valid_f32(down.z) {
        return g;
    }
    g.x = right.xyz - left.xyz;
    g.y = down.xyz - up.xyz;
    g.valid = true;
    return g;
}
