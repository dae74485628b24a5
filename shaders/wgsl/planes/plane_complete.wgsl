// SPDX-License-Identifier: MIT
//! Each invocation completes the label of one full-resolution pixel for meshing (the CPU
//! reference's `planes::mesh::complete_labels`): a labelled pixel keeps its label; an
//! unlabelled one with a raw depth z takes, among the planes labelling a pixel within the
//! window plane_window gathered around it (`window`: a bit per plane), the one its ray meets at
//! the depth nearest z (depth error |z (n·p + d) / (n·p)|, the sensor's noise being along the
//! ray), if that error is below max(`min_distance_m`, 3 σ(z)); the first in the table among
//! equals. Along a plane's border the filtered normals blend into the next surface's and fail
//! the labelling's angle test although the raw points are on the plane. Mirrors
//! core/src/cpu/planes/plane_complete.rs.
#import invalid
#import kinect
#import planes

struct PlaneCompleteParams {
    width_px: u32,
    height_px: u32,
    // The smallest depth tolerance, metres.
    min_distance_m: f32,
    _pad0: u32,
    // Pinhole intrinsics of the full-resolution image.
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
}

@group(0) @binding(0) var<uniform> params: PlaneCompleteParams;
// Raw depth (before the edge-preserving filter), metres; invalid where none.
@group(0) @binding(1) var<storage, read> depth_m: array<f32>;
// The segmentation's labels.
@group(0) @binding(2) var<storage, read> labels_in: array<u32>;
// Per pixel the planes labelling a pixel of the window around it (plane_window, axis 1).
@group(0) @binding(3) var<storage, read> window: array<vec2<u32>>;
// The planes: unit normal (xyz, facing the camera) and offset d (w) of n·p + d = 0.
@group(0) @binding(4) var<storage, read> planes: array<vec4<f32>>;
// Out: the completed labels.
@group(0) @binding(5) var<storage, read_write> labels_out: array<u32>;

@compute @workgroup_size(16, 16, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let w = params.width_px;
    let h = params.height_px;
    if gid.x >= w || gid.y >= h {
        return;
    }
    let ix = gid.y * w + gid.x;
    let own = labels_in[ix];
    labels_out[ix] = own;
    let z = depth_m[ix];
    let candidates = window[ix];
    if own != NO_LABEL || !is_valid_f32(z) || !(z > 0.0) || all(candidates == vec2<u32>(0u)) {
        return;
    }
    let p = vec3<f32>((f32(gid.x) - params.cx_px) / params.fx_px * z, (f32(gid.y) - params.cy_px) / params.fy_px * z, z);
    let tolerance = max(params.min_distance_m, 3.0 * kinect_sigma_m(z));
    var best = NO_LABEL;
    var best_e = 0.0;
    for (var word = 0u; word < 2u; word++) {
        var bits = candidates[word];
        while bits != 0u {
            let m = word * 32u + firstTrailingBit(bits);
            bits &= bits - 1u;
            let plane = planes[m];
            let np = dot(plane.xyz, p);
            if !(np < 0.0) {
                continue;
            }
            // The ray meets the plane at depth z* = −d z / (n·p): z − z* = z (n·p + d) / (n·p).
            let e = abs(z * (np + plane.w) / np);
            if e <= tolerance && (best == NO_LABEL || e < best_e) {
                best = m;
                best_e = e;
            }
        }
    }
    labels_out[ix] = best;
}
