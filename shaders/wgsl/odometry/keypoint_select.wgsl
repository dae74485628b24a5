// SPDX-License-Identifier: MIT
//! Each invocation picks the keypoints of one cell of an image grid at one pyramid level, so
//! that keypoints spread over the frame (a strong texture cannot take them all): the
//! `per_cell` highest-scoring candidates of its cell (`corner_candidates`: FAST corners that
//! are strict local maxima of the score and pass seed 002's border filter). Slot
//! `slot_offset + cell · per_cell + i` holds the cell's i-th best (by score, then pixel index):
//! the keypoint (x, y in level pixels, level, score; score 0 for an empty slot) and its point
//! in the camera frame (back-projected at the level-0 position of the keypoint, with its depth
//! along that ray: a tent filter of radius 2 px about it over the valid depths within the
//! border filter's step, 4 σ(z) + 2 z / f, of the centre's, i.e. on the centre's surface. Read
//! from the raw depth, this needs no bilateral filter of the whole image, is unbiased on a
//! planar patch, and averages 7-9 samples' noise; invalid for an empty slot). Mirrors
//! core/src/cpu/odometry/keypoint_select.rs.
#import invalid
#import keypoint_depth

struct KeypointSelectParams {
    // The level's size.
    width_px: u32,
    height_px: u32,
    // Pyramid level (the level's pixel is 2^level full-resolution pixels).
    level: u32,
    // Cell side, level pixels; cells_x · cells_y cells cover the image.
    cell_px: u32,
    cells_x: u32,
    cells_y: u32,
    // Keypoints kept per cell, at most 8.
    per_cell: u32,
    // The first slot of this level's keypoints.
    slot_offset: u32,
    // Full-resolution (level 0) size and intrinsics, for the depth.
    depth_width_px: u32,
    depth_height_px: u32,
    fx_px: f32,
    fy_px: f32,
    cx_px: f32,
    cy_px: f32,
}

@group(0) @binding(0) var<uniform> params: KeypointSelectParams;
// The level's candidate scores (`corner_candidates`; 0: none).
@group(0) @binding(1) var<storage, read> score: array<f32>;
// Full-resolution depth, metres; invalid where none.
@group(0) @binding(2) var<storage, read> depth_m: array<f32>;
// Out: per slot, (x, y, level, score).
@group(0) @binding(3) var<storage, read_write> keypoints: array<vec4<f32>>;
// Out: per slot, the keypoint's point in the camera frame (x, y, z, 1), metres.
@group(0) @binding(4) var<storage, read_write> points: array<vec4<f32>>;

const MAX_PER_CELL: u32 = 8u;

// The point seen at level-0 position (x0, y0), a candidate's (its centre depth valid: the
// border filter passed there).
fn keypoint_point(x0: f32, y0: f32) -> vec4<f32> {
    let w = i32(params.depth_width_px);
    let h = i32(params.depth_height_px);
    let c = keypoint_depth_pixel(x0, y0, w, h);
    let z = depth_m[c.y * w + c.x];
    let step = same_surface_step_m(z, params.fx_px);
    // The depth along the keypoint's ray: a tent filter of radius 2 px centred on (x0, y0) over
    // the valid samples within `step` of the centre's (weights 1 2 1 about a whole pixel, 1 3 3 1
    // about a pixel corner, where coarser levels' keypoints fall), so a planar patch gives the
    // depth at the ray itself and 7-9 samples' noise averages down.
    let bx = i32(floor(x0)) - 1;
    let by = i32(floor(y0)) - 1;
    var sum = 0.0;
    var weight = 0.0;
    for (var j = 0; j < 4; j++) {
        for (var i = 0; i < 4; i++) {
            let px = clamp(bx + i, 0, w - 1);
            let py = clamp(by + j, 0, h - 1);
            let wt = max(0.0, 2.0 - abs(f32(bx + i) - x0)) * max(0.0, 2.0 - abs(f32(by + j) - y0));
            let n = depth_m[py * w + px];
            if wt > 0.0 && is_valid_f32(n) && n > 0.0 && abs(n - z) <= step {
                sum += wt * n;
                weight += wt;
            }
        }
    }
    let zm = sum / weight;
    return vec4<f32>((x0 - params.cx_px) / params.fx_px * zm, (y0 - params.cy_px) / params.fy_px * zm, zm, 1.0);
}

@compute @workgroup_size(64, 1, 1)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let cell = gid.x;
    if cell >= params.cells_x * params.cells_y {
        return;
    }
    let k = min(params.per_cell, MAX_PER_CELL);
    // The cell's best so far, by score descending then pixel index ascending.
    var best_score: array<f32, MAX_PER_CELL>;
    var best_pixel: array<u32, MAX_PER_CELL>;
    var kept = 0u;
    let x_begin = (cell % params.cells_x) * params.cell_px;
    let y_begin = (cell / params.cells_x) * params.cell_px;
    let x_end = min(x_begin + params.cell_px, params.width_px);
    let y_end = min(y_begin + params.cell_px, params.height_px);
    let scale = f32(1u << params.level);
    for (var y = y_begin; y < y_end; y++) {
        for (var x = x_begin; x < x_end; x++) {
            let s = score[y * params.width_px + x];
            // Pixels arrive in index order, so a tie never displaces an earlier keypoint.
            if !(s > 0.0) || (kept == k && !(s > best_score[k - 1u])) {
                continue;
            }
            // Insert after every entry with a score at least s.
            var at = min(kept, k - 1u);
            if kept < k {
                kept++;
            }
            while at > 0u && best_score[at - 1u] < s {
                best_score[at] = best_score[at - 1u];
                best_pixel[at] = best_pixel[at - 1u];
                at--;
            }
            best_score[at] = s;
            best_pixel[at] = y * params.width_px + x;
        }
    }
    for (var i = 0u; i < k; i++) {
        let slot = params.slot_offset + cell * k + i;
        if i < kept {
            let px = best_pixel[i];
            let x = px % params.width_px;
            let y = px / params.width_px;
            keypoints[slot] = vec4<f32>(f32(x), f32(y), f32(params.level), best_score[i]);
            points[slot] = keypoint_point((f32(x) + 0.5) * scale - 0.5, (f32(y) + 0.5) * scale - 0.5);
        } else {
            keypoints[slot] = vec4<f32>(0.0, 0.0, f32(params.level), 0.0);
            points[slot] = invalid_vec4();
        }
    }
}
