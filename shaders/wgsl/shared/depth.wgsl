// SPDX-License-Identifier: MIT
#import invalid

// Raw sensor units -> metres; invalid for 0 (no reading) and outside [min_m, max_m].
fn depth_to_metres(raw_units: u32, metres_per_unit: f32, min_depth_m: f32, max_depth_m: f32) -> f32 {
    if raw_units == 0u {
        return invalid_f32();
    }
    let depth_m = f32(raw_units) * metres_per_unit;
    if depth_m < min_depth_m || depth_m > max_depth_m {
        return invalid_f32();
    }
    return depth_m;
}
