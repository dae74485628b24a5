// SPDX-License-Identifier: MIT
//! CPU reference of `shaders/wgsl/planes/plane_list.wgsl`.

use crate::cpu::planes::moments::{PLANE_MOMENT_VEC4S, PlaneMoments, plane_moments_combine};
use crate::cpu::planes::plane_fit::{PLANE_FIT_VEC4S, plane_fit_moments};
use crate::cpu::shared::kinect_sigma_m;
use crate::kernels::plane_list::PlaneListParams;
use crate::planes::{MAX_PLANES, NO_LABEL};

/// vec4s per list record: moments, then fit.
pub const PLANE_RECORD_VEC4S: usize = PLANE_MOMENT_VEC4S + PLANE_FIT_VEC4S;
/// vec4s of the list buffer: MAX_PLANES records, then scratch for 2 · MAX_PLANES.
pub const PLANE_LIST_VEC4S: usize = 3 * MAX_PLANES * PLANE_RECORD_VEC4S;
/// Mode 0: add the inner loop's fits and merge.
pub const MODE_MERGE: u32 = 0;
/// Mode 1: keep the refitted planes that pass.
pub const MODE_KEEP: u32 = 1;
/// Mode 2: most pixels first.
pub const MODE_SORT: u32 = 2;
/// `state` entries: planes, curved rejected, overflow, and whether the round's merge took a
/// newcomer (0: the round is over).
pub const PLANE_LIST_STATE: usize = 4;
/// `dispatch` entries: six indirect (x, y, z) sizes, of plane_sums, plane_sums_reduce,
/// plane_fit, plane_label, plane_keys and plane_relabel.
pub const PLANE_LIST_DISPATCH: usize = 18;
/// Byte offsets in `dispatch` of each kernel's indirect size.
pub const DISPATCH_SUMS: u64 = 0;
/// See [`DISPATCH_SUMS`].
pub const DISPATCH_REDUCE: u64 = 12;
/// See [`DISPATCH_SUMS`].
pub const DISPATCH_FIT: u64 = 24;
/// See [`DISPATCH_SUMS`].
pub const DISPATCH_LABEL: u64 = 36;
/// See [`DISPATCH_SUMS`].
pub const DISPATCH_KEYS: u64 = 48;
/// See [`DISPATCH_SUMS`].
pub const DISPATCH_RELABEL: u64 = 60;
const SCRATCH: usize = MAX_PLANES;
const R: usize = PLANE_RECORD_VEC4S;
const F: usize = PLANE_MOMENT_VEC4S;

fn count_of(list: &[[f32; 4]], record: usize) -> f32 {
    list[record * R + F + 1][3]
}

fn copy_record(list: &mut [[f32; 4]], to: usize, from: usize) {
    list.copy_within(from * R..(from + 1) * R, to * R);
}

fn store_slot(list: &mut [[f32; 4]], fits: &[[f32; 4]], moments: &[[f32; 4]], to: usize, slot: usize) {
    list[to * R..to * R + F].copy_from_slice(&moments[slot * F..(slot + 1) * F]);
    list[to * R + F..(to + 1) * R].copy_from_slice(&fits[slot * PLANE_FIT_VEC4S..(slot + 1) * PLANE_FIT_VEC4S]);
}

fn moments_of(list: &[[f32; 4]], record: usize) -> PlaneMoments {
    list[record * R..record * R + F].try_into().expect("10 vec4")
}

fn sorted_order(list: &[[f32; 4]], first: usize, count: usize) -> Vec<usize> {
    let mut order = vec![0usize; count];
    for i in 0..count {
        let c = count_of(list, first + i);
        let mut j = i;
        while j > 0 && count_of(list, first + order[j - 1]) < c {
            order[j] = order[j - 1];
            j -= 1;
        }
        order[j] = i;
    }
    order
}

fn dot(a: [f32; 4], b: [f32; 4]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn merge_mode(params: &PlaneListParams, fits: &[[f32; 4]], moments: &[[f32; 4]], list: &mut [[f32; 4]], state: &mut [u32], n: usize) -> usize {
    let mut m = 0;
    for i in 0..n {
        copy_record(list, SCRATCH + m, i);
        m += 1;
    }
    let mut newcomers = 0;
    for s in 0..params.slot_count as usize {
        let f = fits[s * PLANE_FIT_VEC4S + 4];
        let count = fits[s * PLANE_FIT_VEC4S + 1][3];
        if f[3] == 0.0 || count < params.min_count.max(3.0) {
            continue;
        }
        if f[1] > params.max_bend_deg {
            state[1] += 1;
            continue;
        }
        newcomers += 1;
        if m < 2 * MAX_PLANES {
            store_slot(list, fits, moments, SCRATCH + m, s);
            m += 1;
        } else {
            state[2] += 1;
        }
    }
    state[3] = u32::from(newcomers > 0);
    if newcomers == 0 {
        return n;
    }
    let order = sorted_order(list, SCRATCH, m);
    let mut out = 0;
    for &o in &order {
        let p = SCRATCH + o;
        let (pn, pc) = (list[p * R + F], list[p * R + F + 1]);
        let mut merged = false;
        for q in 0..out {
            let (qn, qc) = (list[q * R + F], list[q * R + F + 1]);
            let apart = (dot(pn, qc) + pn[3]).abs().min((dot(qn, pc) + qn[3]).abs());
            let z = 0.5 * (pc[2] + qc[2]);
            if dot(pn, qn) >= params.cos_merge && apart < params.merge_sigmas * kinect_sigma_m(z) {
                let sum = plane_moments_combine(&moments_of(list, q), &moments_of(list, p));
                let fit = plane_fit_moments(&sum);
                if fit[4][3] != 0.0 {
                    list[q * R..q * R + F].copy_from_slice(&sum);
                    list[q * R + F..(q + 1) * R].copy_from_slice(&fit);
                    merged = true;
                }
                break;
            }
        }
        if merged {
            continue;
        }
        if out < MAX_PLANES {
            copy_record(list, out, p);
            out += 1;
        } else {
            state[2] += 1;
        }
    }
    out
}

/// Whether the refit at `fits[at..]` moved the plane (normal, offset) `old` by at most σ(z) at
/// its centroid over its points: the old plane's distance at the refit's centroid plus the tilt
/// times the points' RMS radius from it.
fn refit_settled(old: [f32; 4], fits: &[[f32; 4]], at: usize) -> bool {
    let (normal, centroid) = (fits[at], fits[at + 1]);
    let radius = (fits[at + 2][3] + fits[at + 3][3]).sqrt();
    let shift = (old[0] * centroid[0] + old[1] * centroid[1] + old[2] * centroid[2] + old[3]).abs();
    let cross = [old[1] * normal[2] - old[2] * normal[1], old[2] * normal[0] - old[0] * normal[2], old[0] * normal[1] - old[1] * normal[0]];
    let tilt = (cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]).sqrt();
    shift + tilt * radius <= kinect_sigma_m(centroid[2])
}

/// Keeps the refits that pass; also whether every kept refit settled ([`refit_settled`]).
#[expect(clippy::too_many_arguments, reason = "the kernel's bindings it reads and writes")]
fn keep_mode(params: &PlaneListParams, fits: &[[f32; 4]], moments: &[[f32; 4]], list: &mut [[f32; 4]], state: &mut [u32], renumber: &mut [u32], n: usize, settled: &mut bool) -> usize {
    if state[3] == 0 {
        for (i, r) in renumber[..n].iter_mut().enumerate() {
            *r = i as u32;
        }
        return n;
    }
    let mut out = 0;
    for i in 0..n {
        let (f, normal, centroid) = (fits[i * PLANE_FIT_VEC4S + 4], fits[i * PLANE_FIT_VEC4S], fits[i * PLANE_FIT_VEC4S + 1]);
        renumber[i] = NO_LABEL;
        if f[3] == 0.0 {
            continue;
        }
        let length = (centroid[0] * centroid[0] + centroid[1] * centroid[1] + centroid[2] * centroid[2]).sqrt();
        if centroid[3] >= params.min_count && f[1] <= params.max_bend_deg && normal[3] >= length * params.cos_incidence {
            // Record i is read before any store reaches it (out <= i).
            *settled = *settled && refit_settled(list[i * R + F], fits, i * PLANE_FIT_VEC4S);
            store_slot(list, fits, moments, out, i);
            renumber[i] = out as u32;
            out += 1;
        } else if f[1] > params.max_bend_deg {
            state[1] += 1;
        }
    }
    out
}

fn sort_mode(list: &mut [[f32; 4]], renumber: &mut [u32], n: usize) -> usize {
    for i in 0..n {
        copy_record(list, SCRATCH + i, i);
    }
    let order = sorted_order(list, SCRATCH, n);
    for (r, &o) in order.iter().enumerate() {
        copy_record(list, r, SCRATCH + o);
        renumber[o] = r as u32;
    }
    n
}

/// Runs the kernel's one invocation.
#[expect(clippy::too_many_arguments, reason = "one argument per WGSL binding, in binding order")]
pub fn plane_list(params: &PlaneListParams, fits: &[[f32; 4]], moments: &[[f32; 4]], list: &mut [[f32; 4]], planes: &mut [[f32; 4]], state: &mut [u32], renumber: &mut [u32], dispatch: &mut [u32]) {
    let n = state[0] as usize;
    let mut settled = true;
    let out = match params.mode {
        MODE_MERGE => merge_mode(params, fits, moments, list, state, n),
        MODE_KEEP => keep_mode(params, fits, moments, list, state, renumber, n, &mut settled),
        _ => sort_mode(list, renumber, n),
    };
    state[0] = out as u32;
    for i in 0..out {
        planes[i] = list[i * R + F];
    }
    let on = u32::from(state[3] != 0 && !(params.mode == MODE_KEEP && out == n && settled));
    let out = out as u32;
    let sizes = [[params.chunks, out, 1], [out, 1, 1], [out.div_ceil(64), 1, 1], [params.label_groups, 1, 1], [params.keys_groups_x, params.keys_groups_y, 1], [params.relabel_groups, 1, 1]];
    for (i, [x, y, z]) in sizes.into_iter().enumerate() {
        dispatch[3 * i..3 * i + 3].copy_from_slice(&[x * on, y, z]);
    }
}
