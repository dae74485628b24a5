// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_relabel.wgsl`.

use crate::kernels::plane_relabel::PlaneRelabelParams;
use crate::planes::NO_LABEL;

/// Renumbers every pixel as the kernel's invocations do.
pub fn plane_relabel(params: &PlaneRelabelParams, renumber: &[u32], labels: &mut [u32]) {
    for l in &mut labels[..params.pixel_count as usize] {
        if *l != NO_LABEL {
            *l = renumber[*l as usize];
        }
    }
}
