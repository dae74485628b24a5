// SPDX-License-Identifier: MIT
//! One invocation keeps a frame's plane list on the GPU (seed 003 §4.3.4's merging and the
//! reference's selection, `planes::reference::segment`), so segmentation needs no host round
//! trip. The list holds up to MAX_PLANES records (moments, then fit: PLANE_RECORD_VEC4S vec4);
//! `state` = [planes, curved rejected, overflow]. Per mode:
//! - 0, **merge**: the inner loop's fits (slots 0 .. `slot_count`) with at least
//!   max(`min_count`, 3) pixels join the list, those bent past `max_bend_deg` counted as curved
//!   instead; then the list and the newcomers, most pixels first (stable), are merged greedily:
//!   each joins the first plane already kept within acos(`cos_merge`) whose offset, measured at
//!   either centroid, is within `merge_sigmas` σ(z) at their mean depth (their moments combined
//!   and refitted), or is kept as a plane of its own.
//! - 1, **keep**: the fits of slot i are list plane i's refit; a plane stays (with its refit)
//!   when it has at least `min_count` pixels, bends at most `max_bend_deg` and faces the camera
//!   within the incidence limit (offset ≥ |centroid| · `cos_incidence`); a fitted plane that
//!   does not stay and bends too far is counted as curved. `renumber` maps old to new indices
//!   (NO_LABEL: dropped).
//! - 2, **sort**: most pixels first (stable); `renumber` maps old to new indices.
//! Every mode writes each plane's (normal, offset) to `planes` (plane_label's input and
//! normal_peaks' known normals) and the indirect dispatch sizes of the round's full-resolution
//! work that follows: plane_sums (`chunks`, planes, 1), plane_sums_reduce (planes, 1, 1),
//! plane_fit (⌈planes / 64⌉, 1, 1), plane_label (`label_groups`, 1, 1), plane_keys
//! (`keys_groups_x`, `keys_groups_y`, 1) and plane_relabel (`relabel_groups`, 1, 1). A round
//! whose merge took no newcomer is over (state[3] = 0, as the reference stops there): merge and
//! keep then leave the list as it is (the labels index it), and those sizes are all zero; so
//! are they after a keep that dropped no plane and whose refits all settled (each plane moved
//! by its refit, over its points, by at most σ(z) at its centroid: the old plane's distance at
//! the refit's centroid plus the tilt times the points' RMS radius; labelling again would then
//! give the same labels).
//! Mirrors core/src/cpu/planes/plane_list.rs.
#import kinect
#import planes
#import plane_moments
#import plane_fitting

const PLANE_RECORD_VEC4S: u32 = 15u;
const MODE_MERGE: u32 = 0u;
const MODE_KEEP: u32 = 1u;
// The scratch area (the list and the newcomers, 2 · MAX_PLANES records) starts here.
const SCRATCH: u32 = 64u;

struct PlaneListParams {
    // 0: merge, 1: keep, 2: sort.
    mode: u32,
    // Mode 0: slots of `fits` and `moments`.
    slot_count: u32,
    // Modes 0 and 1: the smallest plane, pixels.
    min_count: f32,
    // Modes 0 and 1: the largest bend, degrees.
    max_bend_deg: f32,
    // Mode 0: cos of the merge angle, and the merge distance in σ(z).
    cos_merge: f32,
    merge_sigmas: f32,
    // Mode 1: cos of the largest incidence angle (-1: no test).
    cos_incidence: f32,
    // Chunks of the full-resolution maps (plane_sums' first dispatch dimension).
    chunks: u32,
    // Workgroups of plane_label and plane_relabel over the full-resolution pixels, and of
    // plane_keys over the full-resolution image.
    label_groups: u32,
    relabel_groups: u32,
    keys_groups_x: u32,
    keys_groups_y: u32,
}

@group(0) @binding(0) var<uniform> params: PlaneListParams;
// Per slot PLANE_FIT_VEC4S vec4 (plane_fit's output): mode 0 the inner loop's, mode 1 the
// list's refits.
@group(0) @binding(1) var<storage, read> fits: array<vec4<f32>>;
// Per slot PLANE_MOMENT_VEC4S vec4 (plane_sums_reduce's output), as `fits`.
@group(0) @binding(2) var<storage, read> moments: array<vec4<f32>>;
// The list, MAX_PLANES records, then scratch for 2 · MAX_PLANES records.
@group(0) @binding(3) var<storage, read_write> list: array<vec4<f32>>;
// Out: per plane (normal, offset).
@group(0) @binding(4) var<storage, read_write> planes: array<vec4<f32>>;
// [0] planes, [1] curved rejected, [2] planes that did not fit in the list, [3] 1 while the
// round's merge took a newcomer.
@group(0) @binding(5) var<storage, read_write> state: array<u32>;
// Out (modes 1, 2): per old plane its new index, or NO_LABEL.
@group(0) @binding(6) var<storage, read_write> renumber: array<u32>;
// Out: indirect dispatch sizes (x, y, z) of plane_sums, plane_sums_reduce, plane_fit,
// plane_label, plane_keys and plane_relabel.
@group(0) @binding(7) var<storage, read_write> dispatch: array<u32>;

fn count_of(record: u32) -> f32 {
    return list[record * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S + 1u].w;
}

fn copy_record(to: u32, source: u32) {
    for (var j = 0u; j < PLANE_RECORD_VEC4S; j++) {
        list[to * PLANE_RECORD_VEC4S + j] = list[source * PLANE_RECORD_VEC4S + j];
    }
}

// Record `to` = slot `slot` of `moments` and `fits`.
fn store_slot(to: u32, slot: u32) {
    for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
        list[to * PLANE_RECORD_VEC4S + j] = moments[slot * PLANE_MOMENT_VEC4S + j];
    }
    for (var j = 0u; j < PLANE_FIT_VEC4S; j++) {
        list[to * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S + j] = fits[slot * PLANE_FIT_VEC4S + j];
    }
}

fn moments_of(record: u32) -> array<vec4<f32>, 10> {
    var m = plane_moments_zero();
    for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
        m[j] = list[record * PLANE_RECORD_VEC4S + j];
    }
    return m;
}

// Sorts `count` records starting at `first` by pixels, most first, stable (insertion sort of
// their indices), and returns the order.
fn sorted_order(first: u32, count: u32) -> array<u32, 128> {
    var order: array<u32, 128>;
    for (var i = 0u; i < count; i++) {
        let c = count_of(first + i);
        var j = i;
        while j > 0u && count_of(first + order[j - 1u]) < c {
            order[j] = order[j - 1u];
            j -= 1u;
        }
        order[j] = i;
    }
    return order;
}

fn merge_mode(n: u32) -> u32 {
    // The list and the newcomers into scratch.
    var m = 0u;
    for (var i = 0u; i < n; i++) {
        copy_record(SCRATCH + m, i);
        m += 1u;
    }
    var newcomers = 0u;
    for (var s = 0u; s < params.slot_count; s++) {
        let f = fits[s * PLANE_FIT_VEC4S + 4u];
        let count = fits[s * PLANE_FIT_VEC4S + 1u].w;
        if f.w == 0.0 || count < max(params.min_count, 3.0) {
            continue;
        }
        if f.y > params.max_bend_deg {
            state[1] += 1u;
            continue;
        }
        newcomers += 1u;
        if m < 2u * MAX_PLANES {
            store_slot(SCRATCH + m, s);
            m += 1u;
        } else {
            state[2] += 1u;
        }
    }
    state[3] = select(0u, 1u, newcomers > 0u);
    if newcomers == 0u {
        // The round is over, the list (and the labels that index it) as they were.
        return n;
    }
    let order = sorted_order(SCRATCH, m);
    var out = 0u;
    for (var r = 0u; r < m; r++) {
        let p = SCRATCH + order[r];
        let pf = PLANE_MOMENT_VEC4S;
        let pn = list[p * PLANE_RECORD_VEC4S + pf];
        let pc = list[p * PLANE_RECORD_VEC4S + pf + 1u];
        var merged = false;
        for (var q = 0u; q < out; q++) {
            let qn = list[q * PLANE_RECORD_VEC4S + pf];
            let qc = list[q * PLANE_RECORD_VEC4S + pf + 1u];
            let apart = min(abs(dot(pn.xyz, qc.xyz) + pn.w), abs(dot(qn.xyz, pc.xyz) + qn.w));
            let z = 0.5 * (pc.z + qc.z);
            if dot(pn.xyz, qn.xyz) >= params.cos_merge && apart < params.merge_sigmas * kinect_sigma_m(z) {
                let sum = plane_moments_combine(moments_of(q), moments_of(p));
                let fit = plane_fit_moments(sum);
                if fit[4].w != 0.0 {
                    for (var j = 0u; j < PLANE_MOMENT_VEC4S; j++) {
                        list[q * PLANE_RECORD_VEC4S + j] = sum[j];
                    }
                    for (var j = 0u; j < PLANE_FIT_VEC4S; j++) {
                        list[q * PLANE_RECORD_VEC4S + pf + j] = fit[j];
                    }
                    merged = true;
                }
                break;
            }
        }
        if merged {
            continue;
        }
        if out < MAX_PLANES {
            copy_record(out, p);
            out += 1u;
        } else {
            state[2] += 1u;
        }
    }
    return out;
}

// Whether every plane the keep kept settled (see the header); keep_mode sets it.
var<private> settled: bool = true;

// Whether the refit `fit` (PLANE_FIT_VEC4S from `at`) moved the plane (normal, offset) `old`
// by at most σ(z) over its points.
fn refit_settled(old: vec4<f32>, at: u32) -> bool {
    let normal = fits[at].xyz;
    let centroid = fits[at + 1u].xyz;
    let radius = sqrt(fits[at + 2u].w + fits[at + 3u].w);
    let moved = abs(dot(old.xyz, centroid) + old.w) + length(cross(old.xyz, normal)) * radius;
    return moved <= kinect_sigma_m(centroid.z);
}

fn keep_mode(n: u32) -> u32 {
    if state[3] == 0u {
        // A round with no newcomer fitted nothing: the list stays.
        for (var i = 0u; i < n; i++) {
            renumber[i] = i;
        }
        return n;
    }
    var out = 0u;
    for (var i = 0u; i < n; i++) {
        let f = fits[i * PLANE_FIT_VEC4S + 4u];
        let normal = fits[i * PLANE_FIT_VEC4S];
        let centroid = fits[i * PLANE_FIT_VEC4S + 1u];
        renumber[i] = NO_LABEL;
        if f.w == 0.0 {
            continue;
        }
        if centroid.w >= params.min_count && f.y <= params.max_bend_deg && normal.w >= length(centroid.xyz) * params.cos_incidence {
            // Record i is read before any store reaches it (out <= i).
            settled = settled && refit_settled(list[i * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S], i * PLANE_FIT_VEC4S);
            store_slot(out, i);
            renumber[i] = out;
            out += 1u;
        } else if f.y > params.max_bend_deg {
            state[1] += 1u;
        }
    }
    return out;
}

fn sort_mode(n: u32) -> u32 {
    for (var i = 0u; i < n; i++) {
        copy_record(SCRATCH + i, i);
    }
    let order = sorted_order(SCRATCH, n);
    for (var r = 0u; r < n; r++) {
        copy_record(r, SCRATCH + order[r]);
        renumber[order[r]] = r;
    }
    return n;
}

@compute @workgroup_size(1, 1, 1)
fn main() {
    let n = state[0];
    var out = 0u;
    if params.mode == MODE_MERGE {
        out = merge_mode(n);
    } else if params.mode == MODE_KEEP {
        out = keep_mode(n);
    } else {
        out = sort_mode(n);
    }
    state[0] = out;
    for (var i = 0u; i < out; i++) {
        planes[i] = list[i * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S];
    }
    // The round's full-resolution work: none once the round is over, nor after a keep that
    // dropped no plane and whose refits settled (labelling again with the refits would only
    // iterate on the same planes; the next keep then finds the same fits and the same list).
    var on = state[3];
    if params.mode == MODE_KEEP && out == n && settled {
        on = 0u;
    }
    let sizes = array<vec3<u32>, 6>(
        vec3<u32>(params.chunks, out, 1u),
        vec3<u32>(out, 1u, 1u),
        vec3<u32>((out + 63u) / 64u, 1u, 1u),
        vec3<u32>(params.label_groups, 1u, 1u),
        vec3<u32>(params.keys_groups_x, params.keys_groups_y, 1u),
        vec3<u32>(params.relabel_groups, 1u, 1u),
    );
    for (var i = 0u; i < 6u; i++) {
        dispatch[3u * i] = sizes[i].x * on;
        dispatch[3u * i + 1u] = sizes[i].y;
        dispatch[3u * i + 2u] = sizes[i].z;
    }
}
