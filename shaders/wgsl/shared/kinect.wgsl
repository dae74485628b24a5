// SPDX-License-Identifier: MIT
// The Kinect v1 depth noise model (Nguyen, Izadi and Lovell 2012, "Modeling Kinect Sensor
// Noise for Improved 3D Reconstruction and Tracking"), fitted by its authors to a Kinect
// looking at a plane at 0.5-3 m and 10-80°. Mirrors core/src/cpu/shared.rs.

// Axial (along z) standard deviation at depth z metres, for incidence angles up to 60°:
// σ_z(z) = 0.0012 + 0.0019 (z - 0.4)² metres.
fn kinect_sigma_m(z_m: f32) -> f32 {
    let d = z_m - 0.4;
    return 0.0012 + 0.0019 * d * d;
}

// Axial standard deviation at depth z metres and incidence angle θ radians (between the ray and
// the surface normal): beyond 60° the model adds 0.0001 / √z · θ² / (π/2 - θ)² metres.
fn kinect_sigma_at_angle_m(z_m: f32, theta_rad: f32) -> f32 {
    var sigma = kinect_sigma_m(z_m);
    if theta_rad > 1.0471976 {
        let g = theta_rad / (1.5707964 - theta_rad);
        sigma = sigma + 0.0001 / sqrt(z_m) * g * g;
    }
    return sigma;
}

// Lateral standard deviation in pixels at incidence angle θ radians:
// σ_L(θ) = 0.8 + 0.035 θ / (π/2 - θ) pixels.
fn kinect_lateral_sigma_px(theta_rad: f32) -> f32 {
    return 0.8 + 0.035 * theta_rad / (1.5707964 - theta_rad);
}
