// SPDX-License-Identifier: MIT
// The Kinect v1 axial depth noise model (Nguyen, Izadi and Lovell 2012):
// σ(z) = 0.0012 + 0.0019 (z - 0.4)² metres at depth z metres. Mirrors
// core/src/cpu/shared.rs::kinect_sigma_m.

fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    return 0.0012 + 0.0019 * d * d;
}
