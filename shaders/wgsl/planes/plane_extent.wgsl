// SPDX-License-Identifier: MIT
//! Each invocation widens its pixel's plane's extent to the pixel's point (seed 003's plane
//! bounding box, in the plane's frame): u = (p - centroid) · t for both in-plane axes t of the
//! plane's fit (plane_list's records). Float min and max by integer atomics (WebGPU has no
//! float atomics) on an order-preserving encoding: key(f) = bits(f) with the sign bit set for
//! f ≥ 0 and all bits flipped for f < 0 grows with f, so a maximum is atomicMax(key) and a
//! minimum atomicMax(!key); the caller clears `extents` to 0. Mirrors
//! core/src/cpu/planes/plane_extent.rs.
#import invalid
#import planes

const PLANE_RECORD_VEC4S: u32 = 15u;
// The fit's place in a record, after the moments.
const FIT_AT: u32 = 10u;

struct PlaneExtentParams {
    // Pixels of the maps.
    pixel_count: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneExtentParams;
@group(0) @binding(1) var<storage, read> vertex_in_camera: array<vec4<f32>>;
// Per pixel its plane, or NO_LABEL.
@group(0) @binding(2) var<storage, read> labels: array<u32>;
// The plane list (plane_list's records).
@group(0) @binding(3) var<storage, read> list: array<vec4<f32>>;
// In/out: per plane, encoded: [!min u0, max u0, !min u1, max u1].
@group(0) @binding(4) var<storage, read_write> extents: array<atomic<u32>>;

fn ordered_key(f: f32) -> u32 {
    let bits = bitcast<u32>(f);
    return select(bits | 0x80000000u, ~bits, (bits & 0x80000000u) != 0u);
}

@compute @workgroup_size(256, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let ix = gid.x;
    if ix >= params.pixel_count {
        return;
    }
    let l = labels[ix];
    let p = vertex_in_camera[ix];
    if l == NO_LABEL || !is_valid_f32(p.z) {
        return;
    }
    let base = l * PLANE_RECORD_VEC4S + FIT_AT;
    let rel = p.xyz - list[base + 1u].xyz;
    for (var a = 0u; a < 2u; a++) {
        let key = ordered_key(dot(rel, list[base + 2u + a].xyz));
        // Only a point beyond the extent so far writes (a load first: once the extent has
        // grown, nearly every pixel of a plane lies inside it, and contended
        // read-modify-writes on four words per plane are what this kernel would cost).
        let lo = 4u * l + 2u * a;
        if ~key > atomicLoad(&extents[lo]) {
            atomicMax(&extents[lo], ~key);
        }
        if key > atomicLoad(&extents[lo + 1u]) {
            atomicMax(&extents[lo + 1u], key);
        }
    }
}
