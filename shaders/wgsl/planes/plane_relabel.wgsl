// SPDX-License-Identifier: MIT
//! Each invocation renumbers one pixel's label by plane_list's renumbering (after planes were
//! dropped or sorted): NO_LABEL stays, a dropped plane's pixels become NO_LABEL. Mirrors
//! core/src/cpu/planes/plane_relabel.rs.
#import planes

struct PlaneRelabelParams {
    // Pixels of the label image.
    pixel_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneRelabelParams;
// Per old plane its new index, or NO_LABEL.
@group(0) @binding(1) var<storage, read> renumber: array<u32>;
// In/out: per pixel its plane, or NO_LABEL.
@group(0) @binding(2) var<storage, read_write> labels: array<u32>;

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ix = gid.x;
    if ix >= params.pixel_count {
        return;
    }
    let l = labels[ix];
    if l != NO_LABEL {
        labels[ix] = renumber[l];
    }
}
