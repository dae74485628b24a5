// SPDX-License-Identifier: MIT
//! Each invocation gathers, for one pixel, the planes that label a pixel within `reach_px` of
//! it along one axis, as a bit mask over the plane table (x: planes 0-31, y: planes 32-63):
//! axis 0 from the labels along its row, axis 1 by OR-ing axis 0's masks along its column. The
//! two passes give each pixel the planes of the (2 reach + 1)² window around it (plane_complete's
//! candidates) with 2 (2 reach + 1) reads instead of (2 reach + 1)². NO_LABEL and labels past
//! the table (`plane_count`) are left out. Mirrors core/src/cpu/planes/plane_window.rs.
#import planes

struct PlaneWindowParams {
    width_px: u32,
    height_px: u32,
    // Window radius, pixels.
    reach_px: u32,
    // 0: along rows, from the labels; 1: along columns, from axis 0's masks.
    axis: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneWindowParams;
// Axis 0: the segmentation's labels.
@group(0) @binding(1) var<storage, read> labels: array<u32>;
// [0] = the number of planes.
@group(0) @binding(2) var<storage, read> plane_count: array<u32>;
// Axis 1: axis 0's masks.
@group(0) @binding(3) var<storage, read> masks_in: array<vec2<u32>>;
// Out: per pixel the planes within reach along the axis.
@group(0) @binding(4) var<storage, read_write> masks_out: array<vec2<u32>>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let r = i32(params.reach_px);
    var mask = vec2<u32>(0u);
    if params.axis == 0u {
        let count = min(plane_count[0], MAX_PLANES);
        for (var du = -r; du <= r; du++) {
            let u = i32(gid.x) + du;
            if u < 0 || u >= i32(w) {
                continue;
            }
            let m = labels[gid.y * w + u32(u)];
            if m < count {
                mask[m / 32u] |= 1u << (m % 32u);
            }
        }
    } else {
        for (var dv = -r; dv <= r; dv++) {
            let v = i32(gid.y) + dv;
            if v < 0 || v >= i32(h) {
                continue;
            }
            mask |= masks_in[u32(v) * w + gid.x];
        }
    }
    masks_out[gid.y * w + gid.x] = mask;
}
