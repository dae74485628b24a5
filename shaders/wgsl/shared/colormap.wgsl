// SPDX-License-Identifier: MIT
// The colour maps every view draws with, natively and in the browser (twins in
// core/src/cpu/shared.rs). Pixels are packed RGBA8 with red in the low byte: the memory
// layout of an rgba8unorm texture, so a view's buffer copies straight into a canvas texture.
#import invalid

// Packs a colour with channels in [0, 1] (clamped) as RGBA8, truncating each to 0..255.
fn pack_rgba8(c: vec4<f32>) -> u32 {
    let q = vec4<u32>(clamp(c, vec4<f32>(0.0), vec4<f32>(1.0)) * 255.0);
    return q.x | (q.y << 8u) | (q.z << 16u) | (q.w << 24u);
}

// Depth through a compact blue-teal-green-yellow map (near dark blue, `max_m` and beyond
// yellow); no depth (0, negative or NaN) is black.
fn depth_colour(depth_m: f32, max_m: f32) -> u32 {
    if !(is_valid_f32(depth_m) && depth_m > 0.0) {
        return pack_rgba8(vec4<f32>(0.0, 0.0, 0.0, 1.0));
    }
    let t = clamp(depth_m / max_m, 0.0, 1.0);
    let r = 0.27 + t * (-0.6 + t * 1.33);
    let g = t * 0.9;
    let b = 0.33 + t * (1.2 - t * 1.45);
    return pack_rgba8(vec4<f32>(r, g, b, 1.0));
}

// A unit normal as colour: each axis maps [-1, 1] to [1, 0], so a surface facing the camera
// (n = -z) is blue; an invalid normal is black.
fn normal_colour(n: vec4<f32>) -> u32 {
    if !is_valid_f32(n.x) {
        return pack_rgba8(vec4<f32>(0.0, 0.0, 0.0, 1.0));
    }
    return pack_rgba8(vec4<f32>(0.5 - 0.5 * n.xyz, 1.0));
}

// A distinct colour per plane label: hues a golden ratio of a turn apart, full saturation,
// lifted off black.
fn plane_colour(label: u32) -> vec3<f32> {
    let h = fract(f32(label) * 0.618034) * 6.0;
    let x = 1.0 - abs(h % 2.0 - 1.0);
    let sector = u32(h);
    var c = vec3<f32>(1.0, 0.0, x);
    if sector == 0u {
        c = vec3<f32>(1.0, x, 0.0);
    } else if sector == 1u {
        c = vec3<f32>(x, 1.0, 0.0);
    } else if sector == 2u {
        c = vec3<f32>(0.0, 1.0, x);
    } else if sector == 3u {
        c = vec3<f32>(0.0, x, 1.0);
    } else if sector == 4u {
        c = vec3<f32>(x, 0.0, 1.0);
    }
    return (40.0 + 215.0 * c) / 255.0;
}
