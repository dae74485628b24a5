// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_extent.wgsl`, and the decoding of its output.

use crate::cpu::planes::moments::PLANE_MOMENT_VEC4S;
use crate::cpu::planes::plane_list::PLANE_RECORD_VEC4S;
use crate::cpu::shared::is_valid_f32;
use crate::kernels::plane_extent::PlaneExtentParams;
use crate::planes::NO_LABEL;

/// `ordered_key()`: an encoding of f32 as u32 that grows with the value.
pub fn ordered_key(f: f32) -> u32 {
    let bits = f.to_bits();
    if bits & 0x8000_0000 != 0 { !bits } else { bits | 0x8000_0000 }
}

/// The value of an [`ordered_key`].
pub fn from_ordered_key(key: u32) -> f32 {
    f32::from_bits(if key & 0x8000_0000 != 0 { key & 0x7fff_ffff } else { !key })
}

/// A plane's extent from its four encoded words: [[min, max] along the first axis, [min, max]
/// along the second], metres.
pub fn decode_extent(words: &[u32]) -> [[f32; 2]; 2] {
    [[from_ordered_key(!words[0]), from_ordered_key(words[1])], [from_ordered_key(!words[2]), from_ordered_key(words[3])]]
}

/// Widens the extents as the kernel's invocations do.
pub fn plane_extent(params: &PlaneExtentParams, vertex_in_camera: &[[f32; 4]], labels: &[u32], list: &[[f32; 4]], extents: &mut [u32]) {
    for ix in 0..params.pixel_count as usize {
        let (l, p) = (labels[ix], vertex_in_camera[ix]);
        if l == NO_LABEL || !is_valid_f32(p[2]) {
            continue;
        }
        let l = l as usize;
        // The fit follows the moments in a record.
        let base = l * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S;
        let c = list[base + 1];
        let rel = [p[0] - c[0], p[1] - c[1], p[2] - c[2]];
        for a in 0..2 {
            let t = list[base + 2 + a];
            let key = ordered_key(rel[0] * t[0] + rel[1] * t[1] + rel[2] * t[2]);
            extents[4 * l + 2 * a] = extents[4 * l + 2 * a].max(!key);
            extents[4 * l + 2 * a + 1] = extents[4 * l + 2 * a + 1].max(key);
        }
    }
}
