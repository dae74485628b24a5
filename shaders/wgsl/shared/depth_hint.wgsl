// SPDX-License-Identifier: MIT
// The depth hint of a prediction: the raw sensor depth measured at each pixel from the pose the
// prediction renders from. The importing kernel declares `depth_hint_raw: array<u32>` (u16
// units, two per word, low half first; 0: no return) and `params` with `intrinsics` and
// `hint_metres_per_unit`. Mirrors core/src/cpu/fusion/raycast.rs::{hint_at, depth_hint_range}.
#import invalid
#import camera

// The depth measured at pixel `ix`, metres, or NaN where the sensor gave no return.
fn hint_at(ix: u32) -> f32 {
    let raw_units = (depth_hint_raw[ix / 2u] >> ((ix & 1u) * 16u)) & 0xffffu;
    if raw_units == 0u {
        return invalid_f32();
    }
    return f32(raw_units) * params.hint_metres_per_unit;
}

// The range of depths (nearest, farthest) the surface at pixel `xy` may lie at: its own measured
// depth twice, or where it has none (a dropout, an edge) the range of the depths measured 2 and
// 4 pixels away along x and y, so that a pixel beside a silhouette searches both surfaces; NaN
// when all of those are missing too.
fn depth_hint_range(xy: vec2<u32>) -> vec2<f32> {
    let k = params.intrinsics;
    let own = hint_at(xy.y * k.width_px + xy.x);
    if is_valid_f32(own) {
        return vec2<f32>(own);
    }
    var range = vec2<f32>(invalid_f32());
    for (var r = 2u; r <= 4u; r += 2u) {
        let xs = array<u32, 4>(xy.x + r, xy.x - min(r, xy.x), xy.x, xy.x);
        let ys = array<u32, 4>(xy.y, xy.y, xy.y + r, xy.y - min(r, xy.y));
        for (var i = 0u; i < 4u; i++) {
            if xs[i] < k.width_px && ys[i] < k.height_px {
                let h = hint_at(ys[i] * k.width_px + xs[i]);
                if is_valid_f32(h) {
                    if is_valid_f32(range.x) {
                        range = vec2<f32>(min(range.x, h), max(range.y, h));
                    } else {
                        range = vec2<f32>(h);
                    }
                }
            }
        }
    }
    return range;
}
