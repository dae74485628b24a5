// SPDX-License-Identifier: MIT
//! `plane_list`: the GPU's plane list against the CPU twin in its three modes. Merge: the box
//! scene's inner-loop fits into an empty list (one plane per surface), then the same fits again
//! into that list (each newcomer joins its twin: pixels double, planes stay), plus crafted
//! newcomers (a bent one counted as curved, a small one ignored), then a merge with no newcomer
//! (the round ends: no full-resolution dispatch, and keep leaves the list). Keep: crafted refits
//! (kept, too small, bent, edge-on, unfittable) with the renumbering, and a keep that drops
//! nothing (no full-resolution work follows, unless a refit moved its plane by more than σ(z)).
//! Sort: most pixels first, stable.
//! Tolerances: counts, state, renumbering and dispatch sizes exact; records and planes 1e-4
//! relative + 1e-6 (merged fits run the same f32 code). Negative controls on each output.

use webfusion_core::cpu;
use webfusion_core::cpu::planes::moments::{PLANE_MOMENT_VEC4S, plane_moments_combine, plane_moments_point, plane_moments_zero};
use webfusion_core::cpu::planes::plane_fit::{PLANE_FIT_VEC4S, plane_fit_moments};
use webfusion_core::cpu::planes::plane_list::{MODE_KEEP, MODE_MERGE, MODE_SORT, PLANE_LIST_DISPATCH, PLANE_LIST_STATE, PLANE_LIST_VEC4S, PLANE_RECORD_VEC4S};
use webfusion_core::cpu::planes::plane_sums::plane_sums_chunks;
use webfusion_core::kernels::plane_fit::PlaneFitParams;
use webfusion_core::kernels::plane_list::PlaneListParams;
use webfusion_core::kernels::plane_sums_reduce::PlaneSumsReduceParams;
use webfusion_core::planes::{MAX_DISTANCE_PEAKS, MAX_NORMAL_PEAKS, MAX_PLANES, NO_LABEL, PlaneConfig};
use webfusion_core::sim::plane_scenes::PlaneScene;
use webfusion_tests::{Slot, Tolerance, cast, compare_vec4, finish, gpu, run_kernel_slots};

use super::plane_keys::{inner_fixture, inner_params};
use super::plane_sums::sums_params;

const SLOTS: usize = MAX_NORMAL_PEAKS * MAX_DISTANCE_PEAKS;
const TOL: Tolerance = Tolerance { absolute: 1e-6, relative: 1e-4 };

/// The inner loop's fits and moments of a synthetic scene (twins), SLOTS slots each.
fn inner_slots(scene: &PlaneScene) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let f = inner_fixture(scene, Some(3));
    let kp = inner_params(&f.level);
    let (keys, masks) = super::plane_keys::twin_keys(&kp, &f.assignment, &f.intervals, &f.interval_count, &[0.0], &[[0.0; 4]]);
    let chunks = plane_sums_chunks(keys.len());
    let mut peaks = f.peaks.clone();
    peaks.resize(MAX_NORMAL_PEAKS, [0.0, 0.0, 1.0, 0.0]);
    let mut partials = vec![[0.0f32; 4]; SLOTS * chunks * PLANE_MOMENT_VEC4S];
    cpu::plane_sums(&sums_params(&kp, false, MAX_DISTANCE_PEAKS.trailing_zeros()), &keys, &f.level.vertex_in_camera, &f.level.normal_in_camera, &[0.0], &peaks, &mut partials, &masks, SLOTS as u32);
    let mut moments = vec![[0.0f32; 4]; SLOTS * PLANE_MOMENT_VEC4S];
    cpu::plane_sums_reduce(&PlaneSumsReduceParams { chunks: chunks as u32, ..Default::default() }, &partials, &mut moments, SLOTS as u32);
    let mut fits = vec![[0.0f32; 4]; SLOTS * PLANE_FIT_VEC4S];
    cpu::plane_fit(&PlaneFitParams { plane_count: SLOTS as u32, ..Default::default() }, &moments, &mut fits);
    (fits, moments)
}

fn params(mode: u32, min_count: f32) -> PlaneListParams {
    let c = PlaneConfig::default();
    PlaneListParams {
        mode,
        slot_count: SLOTS as u32,
        min_count,
        max_bend_deg: c.max_bend_deg,
        cos_merge: c.merge_angle_deg.to_radians().cos(),
        merge_sigmas: c.merge_sigmas,
        cos_incidence: c.max_incidence_deg.to_radians().cos(),
        chunks: 75,
        label_groups: 1200,
        relabel_groups: 1199,
        keys_groups_x: 40,
        keys_groups_y: 30,
    }
}

/// The dispatch sizes plane_list writes for `planes` planes in a round that goes on.
fn sizes(planes: u32) -> Vec<u32> {
    vec![75, planes, 1, planes, 1, 1, planes.div_ceil(64), 1, 1, 1200, 1, 1, 40, 30, 1, 1199, 1, 1]
}

/// One run's outputs: list, planes, state, renumber, dispatch.
#[derive(Clone, Debug, PartialEq)]
struct Out {
    list: Vec<[f32; 4]>,
    planes: Vec<[f32; 4]>,
    state: Vec<u32>,
    renumber: Vec<u32>,
    dispatch: Vec<u32>,
}

fn run(p: &PlaneListParams, fits: &[[f32; 4]], moments: &[[f32; 4]], list: &[[f32; 4]], state: &[u32]) -> (Out, Out) {
    let gpu = gpu();
    let out = run_kernel_slots(
        &gpu,
        &gpu.kernels.plane_list,
        p,
        &[
            Slot::In(bytemuck::cast_slice(fits)),
            Slot::In(bytemuck::cast_slice(moments)),
            Slot::InOut(bytemuck::cast_slice(list)),
            Slot::Out(16 * MAX_PLANES),
            Slot::InOut(bytemuck::cast_slice(state)),
            Slot::Out(4 * MAX_PLANES),
            Slot::Out(4 * PLANE_LIST_DISPATCH),
        ],
        [1, 1, 1],
    );
    finish(&gpu);
    let g = Out { list: cast(&out[0]), planes: cast(&out[1]), state: cast(&out[2]), renumber: cast(&out[3]), dispatch: cast(&out[4]) };
    let sentinel = webfusion_tests::SENTINEL_F32;
    let mut c = Out { list: list.to_vec(), planes: vec![[sentinel; 4]; MAX_PLANES], state: state.to_vec(), renumber: vec![sentinel.to_bits(); MAX_PLANES], dispatch: vec![0; PLANE_LIST_DISPATCH] };
    cpu::plane_list(p, fits, moments, &mut c.list, &mut c.planes, &mut c.state, &mut c.renumber, &mut c.dispatch);
    (g, c)
}

/// Compares the parts of two runs that mean something: the first `state[0]` records and planes,
/// the state, the renumbering of the `renumbered` old planes, the dispatch sizes.
fn compare(what: &str, g: &Out, c: &Out, renumbered: usize) -> Result<(), String> {
    if g.state != c.state || g.dispatch != c.dispatch || g.renumber[..renumbered] != c.renumber[..renumbered] {
        return Err(format!("{what}: state {:?} vs {:?}, dispatch {:?} vs {:?}, renumber {:?} vs {:?}", g.state, c.state, g.dispatch, c.dispatch, &g.renumber[..renumbered], &c.renumber[..renumbered]));
    }
    let n = c.state[0] as usize;
    compare_vec4(what, &g.list[..n * PLANE_RECORD_VEC4S], &c.list[..n * PLANE_RECORD_VEC4S], TOL)?;
    compare_vec4(what, &g.planes[..n], &c.planes[..n], TOL)?;
    Ok(())
}

fn assert_with_controls(what: &str, g: &Out, c: &Out, renumbered: usize) {
    compare(what, g, c, renumbered).unwrap();
    assert!(c.state[0] > 0, "{what}: a control needs planes");
    let mut bad: Vec<(&str, Out)> = Vec::new();
    let mut b = g.clone();
    b.state[0] += 1;
    bad.push(("another plane count", b));
    let mut b = g.clone();
    b.dispatch[1] += 1;
    bad.push(("another dispatch", b));
    let mut b = g.clone();
    b.list[PLANE_MOMENT_VEC4S][3] += 0.01;
    bad.push(("a moved offset", b));
    let mut b = g.clone();
    b.planes[0][0] = webfusion_tests::SENTINEL_F32;
    bad.push(("an unwritten plane", b));
    if renumbered > 0 {
        let mut b = g.clone();
        b.renumber[0] = b.renumber[0].wrapping_add(1);
        bad.push(("another renumbering", b));
    }
    for (case, b) in bad {
        assert!(compare(what, &b, c, renumbered).is_err(), "{what}: the comparison accepted {case}");
    }
}

/// Moments of an n x n grid of points 1 cm apart on the plane z = `z_m` (normal towards the
/// camera), centred at (x_m, 0); `bend` tilts each point's normal by `bend` · x (radians per
/// metre) about the y axis.
fn patch(n: usize, x_m: f32, z_m: f32, bend: f32) -> Vec<[f32; 4]> {
    let mut m = plane_moments_zero();
    for i in 0..n {
        for j in 0..n {
            let (u, v) = ((i as f32 - n as f32 / 2.0) * 0.01, (j as f32 - n as f32 / 2.0) * 0.01);
            let a = bend * u;
            m = plane_moments_combine(&m, &plane_moments_point([x_m + u, v, z_m], [a.sin(), 0.0, -a.cos()], 1e-4, 0.0));
        }
    }
    m.to_vec()
}

/// Slots holding these moments (and their fits), the rest empty.
fn slots(sets: &[Vec<[f32; 4]>]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let mut moments = vec![[0.0f32; 4]; SLOTS * PLANE_MOMENT_VEC4S];
    let mut fits = vec![[0.0f32; 4]; SLOTS * PLANE_FIT_VEC4S];
    for (s, m) in sets.iter().enumerate() {
        moments[s * PLANE_MOMENT_VEC4S..(s + 1) * PLANE_MOMENT_VEC4S].copy_from_slice(m);
        fits[s * PLANE_FIT_VEC4S..(s + 1) * PLANE_FIT_VEC4S].copy_from_slice(&plane_fit_moments(m.as_slice().try_into().unwrap()));
    }
    (fits, moments)
}

#[test]
fn merging_the_inner_loops_fits() {
    let (fits, moments) = inner_slots(&PlaneScene::box_on_floor());
    let empty = vec![[0.0f32; 4]; PLANE_LIST_VEC4S];
    let p = params(MODE_MERGE, 192.0);
    let (g, c) = run(&p, &fits, &moments, &empty, &[0; PLANE_LIST_STATE]);
    assert_with_controls("box, into an empty list", &g, &c, 0);
    let planes = c.state[0];
    eprintln!("box: {planes} planes from the inner loop, state {:?}", c.state);
    assert!((3..=4).contains(&planes), "the box's visible faces and the floor");
    assert_eq!(c.dispatch, sizes(planes));
    assert_eq!(c.state[3], 1, "the round goes on");
    // The same fits again: each joins its twin.
    let (g2, c2) = run(&p, &fits, &moments, &g.list, &g.state);
    assert_with_controls("box, again", &g2, &c2, 0);
    assert_eq!(c2.state[0], planes, "every newcomer merged");
    for i in 0..planes as usize {
        let (before, after) = (c.list[i * PLANE_RECORD_VEC4S][0], c2.list[i * PLANE_RECORD_VEC4S][0]);
        assert_eq!(after, 2.0 * before, "plane {i}: pixels doubled");
    }
    // Crafted: a flat patch, the same patch 1 mm behind (merges), a bent one (curved), a small one.
    let (fits, moments) = slots(&[patch(20, 0.0, 1.0, 0.0), patch(20, 0.0, 1.001, 0.0), patch(20, 0.5, 1.0, 3.0), patch(5, -0.5, 1.0, 0.0)]);
    let (g, c) = run(&params(MODE_MERGE, 100.0), &fits, &moments, &empty, &[0; PLANE_LIST_STATE]);
    assert_with_controls("crafted", &g, &c, 0);
    assert_eq!(c.state, vec![1, 1, 0, 1], "one plane, one curved");
    assert_eq!(c.list[0][0], 800.0, "both flat patches");
    // No newcomer (only a small and a bent fit): the round ends, its full-resolution kernels get
    // no workgroup, and keep then leaves the list (stale fits in its slots) as it is.
    let (fits_none, moments_none) = slots(&[patch(5, -0.5, 1.0, 0.0), patch(20, 0.5, 1.0, 3.0)]);
    let (g2, c2) = run(&params(MODE_MERGE, 100.0), &fits_none, &moments_none, &g.list, &g.state);
    assert_with_controls("no newcomer", &g2, &c2, 0);
    assert_eq!(c2.state, vec![1, 2, 0, 0], "the plane stays, one more curved, the round over");
    let mut over = sizes(1);
    for i in 0..6 {
        over[3 * i] = 0;
    }
    assert_eq!(c2.dispatch, over);
    let (g3, c3) = run(&params(MODE_KEEP, 1e9), &fits_none, &moments_none, &g2.list, &g2.state);
    assert_with_controls("keep after no newcomer", &g3, &c3, 1);
    assert_eq!(c3.state, c2.state, "nothing dropped, though the slots' fits would fail");
    assert_eq!(c3.list[..PLANE_RECORD_VEC4S], c2.list[..PLANE_RECORD_VEC4S]);
    assert_eq!(c3.renumber[0], 0);
}

#[test]
fn keeping_and_sorting() {
    let list_of = |sets: &[Vec<[f32; 4]>]| {
        let (fits, moments) = slots(sets);
        let mut list = vec![[0.0f32; 4]; PLANE_LIST_VEC4S];
        for s in 0..sets.len() {
            list[s * PLANE_RECORD_VEC4S..s * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S].copy_from_slice(&moments[s * PLANE_MOMENT_VEC4S..(s + 1) * PLANE_MOMENT_VEC4S]);
            list[s * PLANE_RECORD_VEC4S + PLANE_MOMENT_VEC4S..(s + 1) * PLANE_RECORD_VEC4S].copy_from_slice(&fits[s * PLANE_FIT_VEC4S..(s + 1) * PLANE_FIT_VEC4S]);
        }
        (fits, moments, list)
    };
    // Keep: [kept, too small, bent, unfittable, kept]; an edge-on plane fails the incidence test.
    let sets = [patch(20, 0.0, 1.0, 0.0), patch(5, 0.3, 1.0, 0.0), patch(20, 0.5, 1.0, 3.0), plane_moments_zero().to_vec(), patch(15, -0.5, 2.0, 0.0)];
    let (fits, moments, list) = list_of(&sets);
    let (g, c) = run(&params(MODE_KEEP, 100.0), &fits, &moments, &list, &[5, 0, 0, 1]);
    assert_with_controls("keep", &g, &c, 5);
    assert_eq!(c.state, vec![2, 1, 0, 1]);
    assert_eq!(&c.renumber[..5], &[0, NO_LABEL, NO_LABEL, NO_LABEL, 1]);
    assert_eq!(c.dispatch, sizes(2), "planes dropped: the round labels again");
    // A keep that drops nothing: no full-resolution work follows.
    let (fits2, moments2, list2) = list_of(&[patch(20, 0.0, 1.0, 0.0), patch(15, -0.5, 2.0, 0.0)]);
    let (g, c) = run(&params(MODE_KEEP, 100.0), &fits2, &moments2, &list2, &[2, 0, 0, 1]);
    assert_with_controls("keep, nothing dropped", &g, &c, 2);
    assert_eq!((c.state.clone(), &c.renumber[..2]), (vec![2, 0, 0, 1], &[0, 1][..]));
    assert!((0..6).all(|i| c.dispatch[3 * i] == 0), "no full-resolution work: {:?}", c.dispatch);
    // A keep that drops nothing but whose refit moved a plane by more than σ(z) (1 cm at 1 m,
    // σ = 1.9 mm) labels again; a move within it (1 mm) does not.
    let moved_list = |z_m: f32| {
        let (_, _, list) = list_of(&[patch(20, 0.0, z_m, 0.0), patch(15, -0.5, 2.0, 0.0)]);
        let (g, c) = run(&params(MODE_KEEP, 100.0), &fits2, &moments2, &list, &[2, 0, 0, 1]);
        compare("keep, a plane moved", &g, &c, 2).unwrap();
        assert_eq!(g.dispatch, c.dispatch, "the GPU decides as the twin does");
        c.dispatch
    };
    assert_eq!(moved_list(1.01), sizes(2), "a refit 1 cm off its plane: the round labels again");
    assert!(moved_list(1.001)[..].chunks(3).all(|d| d[0] == 0), "a refit 1 mm off settles");
    let mut edge_on = params(MODE_KEEP, 100.0);
    edge_on.cos_incidence = 0.9999;
    let (g, c) = run(&edge_on, &fits, &moments, &list, &[5, 0, 0, 1]);
    compare("keep, strict incidence", &g, &c, 5).unwrap();
    assert_eq!(&c.renumber[..5], &[0, NO_LABEL, NO_LABEL, NO_LABEL, NO_LABEL], "the patch 0.5 m aside is seen at 14°");
    // Sort: 400, 25, 225 pixels -> 400, 225, 25.
    let (fits, moments, list) = list_of(&[patch(20, 0.0, 1.0, 0.0), patch(5, 0.3, 1.0, 0.0), patch(15, -0.5, 2.0, 0.0)]);
    let (g, c) = run(&params(MODE_SORT, 0.0), &fits, &moments, &list, &[3, 0, 0, 1]);
    assert_with_controls("sort", &g, &c, 3);
    assert_eq!(&c.renumber[..3], &[0, 2, 1]);
    assert_eq!([0, 1, 2].map(|i| c.list[i * PLANE_RECORD_VEC4S][0]), [400.0, 225.0, 25.0]);
}
