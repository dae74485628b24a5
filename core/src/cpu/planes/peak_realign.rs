// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/peak_realign.wgsl`.

use crate::kernels::peak_realign::PeakRealignParams;

/// Realigns every peak as the kernel's invocations do.
pub fn peak_realign(params: &PeakRealignParams, peaks: &[[f32; 4]], peak_count: &[u32], normal_sums: &[i32], realigned: &mut [[f32; 4]]) {
    for k in 0..params.peak_slots as usize {
        if k >= peak_count[0] as usize {
            realigned[k] = peaks[k];
            continue;
        }
        let s = [normal_sums[4 * k] as f32, normal_sums[4 * k + 1] as f32, normal_sums[4 * k + 2] as f32];
        let len = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt();
        realigned[k] = if len > 0.0 { [s[0] / len, s[1] / len, s[2] / len, 0.0] } else { [peaks[k][0], peaks[k][1], peaks[k][2], 0.0] };
    }
}
