// SPDX-License-Identifier: MIT
//! `raycast`: an analytic TSDF (a plane and a sphere) renders to its exact depth (and, through
//! `surface_normals`' twin, its exact normals), the GPU matches the CPU reference for every
//! output, and rays that meet nothing give NaN / 0.
//!
//! Starting each ray at a measured depth (the prediction's depth hint) finds the same surface,
//! and a disabled pose renders nothing. The same scene as a sparse map (band blocks only, so
//! rays cross unallocated blocks and a third of the samples straddle blocks) renders as its
//! twin does and as the dense box does, and a block taken out of it is seen. The pipelines
//! compiled for one map kind (and without the hint's window) render as the twin does, and the
//! wrong kind's cannot.
//!
//! Tolerances: where both sides hit, vertex and depth within 1e-4 m, colour bytes within 1
//! level. The march accumulates t in f32 and the
//! zero-crossing test is a comparison, so under FMA contraction a ray grazing a silhouette can
//! hit on one side and miss on the other: at most 0.5 % of the pixels may disagree that way.

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, shared::{pack_rgb8, pack_u16_pairs}};
use webfusion_core::cpu::shared::{MAP_DENSE, MAP_SPARSE};
use webfusion_core::kernels::{GpuIntrinsics, KernelPipeline};
use webfusion_core::fusion::predictor::RANGE_TILE_PX;
use webfusion_core::kernels::raycast::{CameraPose, DEFAULT_MAX_STEPS, DEFAULT_STEP_FACTOR, RaycastParams};
use webfusion_core::kernels::raycast_range::RaycastRangeParams;
use webfusion_core::mesh::tsdf_from_sdf;
use webfusion_core::tsdf::{TsdfConfig, VolumeDesc};
use webfusion_core::{Gpu, PinholeIntrinsics, Se3};
use webfusion_tests::{SENTINEL_F32, cast, finish, gpu};

use crate::synthetic::K_SMALL;

const PLANE_Z_M: f32 = 1.5;
const SPHERE_CENTRE: [f32; 3] = [0.3, 0.1, 1.0];
const SPHERE_RADIUS_M: f32 = 0.2;
const MAX_DISAGREEING_FRACTION: f64 = 5e-3;
/// Raw units per metre of the depth hint (TUM's scale).
const HINT_UNITS_PER_M: f32 = 5000.0;

fn scene_sdf(p: [f32; 3]) -> f32 {
    let d = [p[0] - SPHERE_CENTRE[0], p[1] - SPHERE_CENTRE[1], p[2] - SPHERE_CENTRE[2]];
    let sphere = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - SPHERE_RADIUS_M;
    (PLANE_Z_M - p[2]).min(sphere)
}

fn scene() -> (VolumeDesc, Vec<u32>, Vec<u32>) {
    let config = TsdfConfig::cube(64, 0.04);
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let voxels = tsdf_from_sdf(&desc, 1, scene_sdf);
    // Colour: red on the sphere's side of x = 0.1, blue elsewhere.
    let colors = (0..desc.voxel_count())
        .map(|i| {
            let x = (i % desc.dim_x as usize) as f32 * desc.voxel_size_m + desc.origin_x_m;
            pack_rgb8(if x > 0.1 { [1.0, 0.0, 0.0] } else { [0.0, 0.0, 1.0] })
        })
        .collect();
    (desc, voxels, colors)
}

#[derive(Clone)]
struct Images {
    vertex: Vec<[f32; 4]>,
    depth: Vec<f32>,
    color: Vec<u32>,
}

/// Raycast parameters and pose; `hint`: each ray starts near a measured depth; `range_tiles`:
/// the depth-range tiles (`raycast_range`'s output) rays without a hint search within.
struct Setup {
    params: RaycastParams,
    pose: CameraPose,
    hint: Option<Vec<f32>>,
    range_tiles: Option<Vec<u32>>,
}

fn params(desc: VolumeDesc, k: PinholeIntrinsics, world_from_camera: &Se3) -> Setup {
    let params = RaycastParams {
        volume: desc,
        intrinsics: GpuIntrinsics::from(k),
        min_depth_m: 0.3,
        max_depth_m: 5.0,
        step_factor: DEFAULT_STEP_FACTOR,
        max_steps: DEFAULT_MAX_STEPS,
        ..Default::default()
    };
    Setup { params, pose: webfusion_core::fusion::predictor::camera_pose(Some(world_from_camera)), hint: None, range_tiles: None }
}

fn render(s: &Setup, voxels: &[u32], colors: &[u32]) -> (Images, Images) {
    render_map(s, voxels, colors, &[0u32])
}

/// [`render`] of a map of either kind: `table` is a sparse map's hash table (one placeholder
/// word for a dense box).
fn render_map(s: &Setup, voxels: &[u32], colors: &[u32], table: &[u32]) -> (Images, Images) {
    let gpu = gpu();
    render_with(&gpu, &gpu.kernels.raycast, s, voxels, colors, table)
}

/// [`render_map`] with `kernel`, one of `gpu`'s: the raycast as compiled (a variant with
/// override constants).
fn render_with(gpu: &Gpu, kernel: &KernelPipeline, s: &Setup, voxels: &[u32], colors: &[u32], table: &[u32]) -> (Images, Images) {
    let p = &s.params;
    let n = (p.intrinsics.width_px * p.intrinsics.height_px) as usize;
    // The hint as the sensor gives it: raw units (0: no return), two per word.
    let hint: Vec<u32> = match &s.hint {
        Some(h) => pack_u16_pairs(&h.iter().map(|&d| if d.is_nan() { 0 } else { (d * HINT_UNITS_PER_M).round() as u16 }).collect::<Vec<_>>()),
        None => vec![0],
    };
    let hint = &hint;
    let p = &RaycastParams { use_depth_hint: u32::from(s.hint.is_some()), hint_margin_m: p.volume.truncation_m, hint_metres_per_unit: 1.0 / HINT_UNITS_PER_M, ..*p };
    let no_tiles = vec![0u32];
    let tiles = s.range_tiles.as_ref().unwrap_or(&no_tiles);
    let p = &RaycastParams { range_tile_px: if s.range_tiles.is_some() { RANGE_TILE_PX } else { 0 }, range_tiles_x: p.intrinsics.width_px.div_ceil(RANGE_TILE_PX), ..*p };
    // Bindings: params, pose, volume, colours, then the outputs, the depth hint, the tiles.
    let inputs: [&[u8]; 3] = [bytemuck::bytes_of(&s.pose), bytemuck::cast_slice(voxels), bytemuck::cast_slice(colors)];
    use webfusion_tests::Slot::{In, Out};
    let slots = [In(inputs[0]), In(inputs[1]), In(inputs[2]), Out(16 * n), Out(4 * n), Out(4 * n), In(bytemuck::cast_slice(hint)), In(bytemuck::cast_slice(tiles)), In(bytemuck::cast_slice(table))];
    let out = webfusion_tests::run_kernel_slots(gpu, kernel, p, &slots, [p.intrinsics.width_px, p.intrinsics.height_px, 1]);
    finish(gpu);
    let g = Images { vertex: cast(&out[0]), depth: cast(&out[1]), color: cast(&out[2]) };
    let mut c = Images { vertex: vec![[0.0; 4]; n], depth: vec![0.0; n], color: vec![0; n] };
    cpu::raycast(p, &s.pose, voxels, colors, &mut c.vertex, &mut c.depth, &mut c.color, hint, tiles, table);
    (g, c)
}

/// Pixels where GPU and CPU disagree beyond the tolerances (hit vs miss counts as one).
fn disagreements(g: &Images, c: &Images) -> usize {
    let bytes_close = |a: u32, b: u32| (0..4).all(|i| ((a >> (8 * i)) & 0xff).abs_diff((b >> (8 * i)) & 0xff) <= 1);
    (0..c.depth.len())
        .filter(|&i| {
            let (gh, ch) = (!g.depth[i].is_nan(), !c.depth[i].is_nan());
            if gh != ch {
                return true;
            }
            if !ch {
                return !(g.vertex[i].iter().all(|v| v.is_nan()) && g.color[i] == 0);
            }
            let close = |a: &[f32; 4], b: &[f32; 4], tol: f32| a.iter().zip(b).all(|(x, y)| (x - y).abs() <= tol);
            !(close(&g.vertex[i], &c.vertex[i], 1e-4)
                && (g.depth[i] - c.depth[i]).abs() <= 1e-4
                && bytes_close(g.color[i], c.color[i]))
        })
        .count()
}

fn assert_agree(what: &str, g: &Images, c: &Images) {
    let n = disagreements(g, c);
    let allowed = (MAX_DISAGREEING_FRACTION * c.depth.len() as f64).floor() as usize;
    eprintln!("{what}: {n} of {} pixels disagree (allowed {allowed})", c.depth.len());
    assert!(n <= allowed, "{what}: {n} pixels disagree, allowed {allowed}");
}

/// Ray parameter of the analytic first hit (plane or sphere) for pixel (x, y) at identity, and
/// the closest approach of the ray to the sphere's centre.
fn analytic_hit(k: &PinholeIntrinsics, x: u32, y: u32) -> (f32, f32) {
    let ray = DVec3::new((f64::from(x) - f64::from(k.cx_px)) / f64::from(k.fx_px), (f64::from(y) - f64::from(k.cy_px)) / f64::from(k.fy_px), 1.0);
    let c = DVec3::new(f64::from(SPHERE_CENTRE[0]), f64::from(SPHERE_CENTRE[1]), f64::from(SPHERE_CENTRE[2]));
    let dir = ray.normalize();
    let tc = c.dot(dir);
    let closest = (c - dir * tc).length();
    let mut depth = f64::from(PLANE_Z_M);
    if closest < f64::from(SPHERE_RADIUS_M) {
        let t = tc - (f64::from(SPHERE_RADIUS_M).powi(2) - closest * closest).sqrt();
        depth = depth.min(t * dir.z);
    }
    (depth as f32, closest as f32)
}

#[test]
fn plane_and_sphere_render_to_their_true_depth_and_normals() {
    use webfusion_core::kernels::surface_normals::SurfaceNormalsParams;
    let (desc, voxels, colors) = scene();
    let k = K_SMALL;
    let setup = params(desc, k, &Se3::IDENTITY);
    let (g, c) = render(&setup, &voxels, &colors);
    assert_agree("identity", &g, &c);
    // Normals as the predictor derives them from the rendered vertices.
    let np = SurfaceNormalsParams { width_px: k.width_px, height_px: k.height_px, min_cross_norm_sq: 1e-20, ..Default::default() };
    let mut normal = vec![[0.0f32; 4]; k.pixel_count()];
    cpu::surface_normals(&np, &setup.pose, &g.vertex, &mut normal);
    let (mut plane, mut sphere) = (0, 0);
    let mut angles_deg = Vec::new();
    for y in 0..k.height_px {
        for x in 0..k.width_px {
            let i = (y * k.width_px + x) as usize;
            let (depth, closest) = analytic_hit(&k, x, y);
            let got = g.depth[i];
            assert!(!got.is_nan(), "pixel ({x}, {y}) sees the scene");
            if closest > SPHERE_RADIUS_M + 2.0 * desc.truncation_m {
                // Away from the sphere the TSDF is linear: trilinear sampling and the crossing
                // interpolation are exact up to the 16-bit quantisation.
                plane += 1;
                assert!((got - PLANE_Z_M).abs() < 1e-4, "plane pixel ({x}, {y}): depth {got}");
                let n = normal[i];
                let border = x == 0 || y == 0 || x + 1 == k.width_px || y + 1 == k.height_px;
                assert!(border || (n[0].abs() < 1e-3 && n[1].abs() < 1e-3 && (n[2] + 1.0).abs() < 1e-5), "plane normal {n:?} at ({x}, {y})");
            } else if closest < SPHERE_RADIUS_M - 0.02 {
                sphere += 1;
                assert!((got - depth).abs() < 5e-3, "sphere pixel ({x}, {y}): depth {got} vs {depth}");
                let p = g.vertex[i];
                let radial = [p[0] - SPHERE_CENTRE[0], p[1] - SPHERE_CENTRE[1], p[2] - SPHERE_CENTRE[2]];
                let len = (radial[0] * radial[0] + radial[1] * radial[1] + radial[2] * radial[2]).sqrt();
                let cos = (0..3).map(|a| radial[a] / len * normal[i][a]).sum::<f32>();
                angles_deg.push(cos.clamp(-1.0, 1.0).acos().to_degrees());
            }
        }
    }
    // Normals from vertex differences across 2 pixels (about 2 cm on the sphere here) carry
    // the few millimetres of error of the crossing interpolation on 4 cm voxels: the median
    // within 2° of the radial direction and every one within 5°.
    angles_deg.sort_by(f32::total_cmp);
    let (median, worst) = (angles_deg[angles_deg.len() / 2], angles_deg[angles_deg.len() - 1]);
    eprintln!("sphere normals vs radial: median {median:.2}°, worst {worst:.2}°");
    assert!(median < 2.0 && worst < 5.0, "sphere normals: median {median}°, worst {worst}°");
    assert!(plane > 500 && sphere > 100, "both surfaces covered ({plane} plane, {sphere} sphere pixels)");
}

#[test]
fn gpu_matches_cpu_at_a_rotated_pose_and_the_comparison_can_fail() {
    let (desc, voxels, colors) = scene();
    let pose = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.25), DVec3::new(0.2, -0.1, 0.1));
    let k = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
    let (g, c) = render(&params(desc, k, &pose), &voxels, &colors);
    let hits = c.depth.iter().filter(|d| !d.is_nan()).count();
    assert!(hits > 5000 && hits < c.depth.len(), "a mix of hits and misses ({hits})");
    assert_agree("rotated", &g, &c);
    // Negative controls: each kind of error must be counted.
    let i = c.depth.iter().position(|d| !d.is_nan()).expect("a hit");
    let base = disagreements(&g, &c);
    let mut bad = g.clone();
    bad.depth[i] += 1e-3;
    assert_eq!(disagreements(&bad, &c), base + 1, "a depth 1 mm off is counted");
    bad.depth[i] = g.depth[i];
    bad.vertex[i][0] += 1e-3;
    assert_eq!(disagreements(&bad, &c), base + 1, "a moved vertex is counted");
    bad.vertex[i] = g.vertex[i];
    bad.color[i] ^= 0x04;
    assert_eq!(disagreements(&bad, &c), base + 1, "a colour 4 levels off is counted");
    bad.color[i] = g.color[i];
    bad.depth[i] = SENTINEL_F32;
    assert_eq!(disagreements(&bad, &c), base + 1, "an unwritten depth is counted");
    let all_wrong = Images { depth: vec![f32::NAN; c.depth.len()], ..bad };
    assert!(disagreements(&all_wrong, &c) > (MAX_DISAGREEING_FRACTION * c.depth.len() as f64) as usize, "everything missing fails");
}

#[test]
fn rays_that_meet_nothing_are_invalid() {
    let (desc, voxels, colors) = scene();
    // Looking backwards, out of the volume, and (separately) into never-observed space.
    let backwards = Se3::new(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::ZERO);
    let unobserved = vec![0u32; voxels.len()];
    for (what, pose, vox) in [("backwards", backwards, &voxels), ("unobserved", Se3::IDENTITY, &unobserved)] {
        let (g, c) = render(&params(desc, K_SMALL, &pose), vox, &colors);
        for i in 0..g.depth.len() {
            assert!(g.depth[i].is_nan() && c.depth[i].is_nan(), "{what}: pixel {i} should miss");
            assert_eq!(g.depth[i].to_bits(), 0x7fc0_0000, "{what}: the invalid marker bit pattern");
            assert!(g.vertex[i].iter().all(|v| v.to_bits() == 0x7fc0_0000), "{what}: vertex invalid");
            assert_eq!(g.color[i], 0, "{what}: no colour on a miss");
        }
    }
}

#[test]
fn starting_at_the_measured_depth_finds_the_same_surface() {
    let (desc, voxels, colors) = scene();
    let k = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
    let plain = params(desc, k, &Se3::IDENTITY);
    let (full, _) = render(&plain, &voxels, &colors);
    // The measured depth: the rendered surface, with holes where nothing was measured (those
    // rays march from the near plane as before).
    let hint: Vec<f32> = full.depth.iter().enumerate().map(|(i, &d)| if i % 7 == 0 { f32::NAN } else { d }).collect();
    let hinted = Setup { hint: Some(hint), ..params(desc, k, &Se3::IDENTITY) };
    let (g, c) = render(&hinted, &voxels, &colors);
    assert_agree("hinted GPU vs CPU", &g, &c);
    assert_same_surfaces("hinted", k, desc, &full, &g);
    // A hint far behind every surface: the ray starts past them and sees nothing in front. The
    // same for a return beyond the depth range (5 m here): the sensor saw through everything.
    for far_m in [4.5, 5.5] {
        let behind = Setup { hint: Some(vec![far_m; k.pixel_count()]), ..params(desc, k, &Se3::IDENTITY) };
        let (g, c) = render(&behind, &voxels, &colors);
        assert!(g.depth.iter().chain(&c.depth).all(|d| d.is_nan()), "a ray hinted at {far_m} m meets only the surfaces' backs");
    }
}

/// `got` (a march that starts elsewhere than `full`'s) finds `full`'s surfaces: the march
/// visits other sample points, so a crossing moves by a fraction of a voxel; only rays grazing
/// a silhouette (a neighbour within 2 pixels whose full-march depth is 10 cm or more away, or
/// which is a miss where this one hits, or a hit where this one misses), where the TSDF dips
/// below zero for less than a step, may find another surface or none, and at most 2 % of the
/// pixels do.
fn assert_same_surfaces(what: &str, k: PinholeIntrinsics, desc: VolumeDesc, full: &Images, got: &Images) {
    let (w, h) = (k.width_px as usize, k.height_px as usize);
    let silhouette = |i: usize| {
        let (x, y) = (i % w, i / w);
        (y.saturating_sub(2)..(y + 3).min(h)).any(|yy| {
            (x.saturating_sub(2)..(x + 3).min(w)).any(|xx| {
                let (a, b) = (full.depth[yy * w + xx], full.depth[i]);
                a.is_nan() != b.is_nan() || (a - b).abs() >= 0.1
            })
        })
    };
    let quarter_voxel = desc.voxel_size_m / 4.0;
    let mut off_surface = 0;
    for i in 0..full.depth.len() {
        let (f, g) = (full.depth[i], got.depth[i]);
        let same = if f.is_nan() { g.is_nan() } else { (g - f).abs() <= quarter_voxel };
        if !same {
            off_surface += 1;
            assert!(silhouette(i), "{what}: pixel ({}, {}) away from any silhouette: {g} vs full march {f}", i % w, i / w);
        }
    }
    eprintln!("{what} vs full march: {off_surface} of {} pixels differ (by more than a quarter voxel, or hit vs miss), all at silhouettes", full.depth.len());
    assert!(off_surface * 50 < full.depth.len(), "{what}: at most 2 % of the pixels ({off_surface})");
}

/// The depth-range tiles of `voxels` seen from `s`, by the CPU twin of `raycast_range` (whose
/// own test compares it with the GPU).
fn range_tiles(desc: VolumeDesc, voxels: &[u32], s: &Setup) -> Vec<u32> {
    let k = s.params.intrinsics;
    let (tiles_x, tiles_y) = (k.width_px.div_ceil(RANGE_TILE_PX), k.height_px.div_ceil(RANGE_TILE_PX));
    let rp = RaycastRangeParams { volume: desc, intrinsics: k, tile_px: RANGE_TILE_PX, tiles_x, tiles_y, min_depth_m: s.params.min_depth_m, max_depth_m: s.params.max_depth_m, ..Default::default() };
    let mut tiles = vec![0u32; (2 * tiles_x * tiles_y) as usize];
    cpu::raycast_range(&rp, &s.pose, &cpu::shared::surface_bricks(&desc, voxels), &mut tiles, &[0]);
    tiles
}

#[test]
fn range_tiles_find_the_full_marchs_surfaces_and_empty_tiles_miss() {
    let (desc, voxels, colors) = scene();
    let k = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
    let rotated = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.25), DVec3::new(0.2, -0.1, 0.1));
    for (what, pose) in [("identity", Se3::IDENTITY), ("rotated", rotated)] {
        let plain = params(desc, k, &pose);
        let (full, _) = render(&plain, &voxels, &colors);
        let tiles = range_tiles(desc, &voxels, &plain);
        let empty_tiles = tiles.chunks(2).filter(|t| t[1] == 0).count();
        let ranged = Setup { range_tiles: Some(tiles), ..params(desc, k, &pose) };
        let (g, c) = render(&ranged, &voxels, &colors);
        assert_agree(&format!("{what}, range tiles: GPU vs CPU"), &g, &c);
        assert_same_surfaces(&format!("{what}, range tiles"), k, desc, &full, &g);
        eprintln!("{what}: {empty_tiles} of {} tiles meet no surface brick", c.depth.len() / (RANGE_TILE_PX * RANGE_TILE_PX) as usize);
    }
    // Negative control: tiles that say "no surface brick anywhere" make every ray a miss, so
    // the kernel does read them.
    let none = Setup { range_tiles: Some(vec![0; 2 * 20 * 15]), ..params(desc, k, &Se3::IDENTITY) };
    let (g, c) = render(&none, &voxels, &colors);
    assert!(g.depth.iter().chain(&c.depth).all(|d| d.is_nan()), "empty tiles: only misses");
}

#[test]
fn a_disabled_pose_renders_nothing() {
    let (desc, voxels, colors) = scene();
    let mut s = params(desc, K_SMALL, &Se3::IDENTITY);
    s.pose.enabled = 0;
    let (g, c) = render(&s, &voxels, &colors);
    assert!(g.depth.iter().all(|d| d.to_bits() == SENTINEL_F32.to_bits()), "the GPU wrote nothing for a lost frame's pose");
    assert!(c.depth.iter().all(|&d| d == 0.0), "nor did the CPU twin");
}

/// Block coordinates of the sparse map's block holding the world point `p`.
fn block_containing(desc: &VolumeDesc, p: [f32; 3]) -> [u32; 3] {
    let corner = webfusion_core::cpu::shared::box_corner_in_world(desc);
    let block_m = desc.voxel_size_m * (1 << webfusion_core::cpu::shared::BRICK_SHIFT) as f32;
    std::array::from_fn(|i| ((p[i] - corner[i]) / block_m).floor() as u32)
}

/// The scene as a sparse map of the same voxel size: the blocks of the region the dense box
/// covers that hold part of the truncation band (the rest never allocated), in key order, with
/// the scene's colours.
fn sparse_scene() -> (VolumeDesc, Vec<webfusion_core::map::MapBlock>) {
    use webfusion_core::cpu::shared::{BLOCK_VOXELS, BRICK_SHIFT, pack_voxel, voxel_centre_in_world, voxel_tsdf};
    let config = TsdfConfig { color: true, ..TsdfConfig::sparse(0.04, 4096) };
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let (lo, hi) = (block_containing(&desc, [-1.3, -1.3, 0.1]), block_containing(&desc, [1.3, 1.3, 2.2]));
    let mut blocks = Vec::new();
    for bz in lo[2]..=hi[2] {
        for by in lo[1]..=hi[1] {
            for bx in lo[0]..=hi[0] {
                let centres: Vec<[f32; 3]> = (0..BLOCK_VOXELS)
                    .map(|l| voxel_centre_in_world(&desc, (bx << BRICK_SHIFT) + (l & 7), (by << BRICK_SHIFT) + ((l >> 3) & 7), (bz << BRICK_SHIFT) + (l >> 6)))
                    .collect();
                let voxels: Vec<u32> = centres.iter().map(|&p| pack_voxel((scene_sdf(p) / desc.truncation_m).clamp(-1.0, 1.0), 1)).collect();
                if voxels.iter().any(|&w| voxel_tsdf(w).abs() < 1.0) {
                    let colors = centres.iter().map(|p| pack_rgb8(if p[0] > 0.1 { [1.0, 0.0, 0.0] } else { [0.0, 0.0, 1.0] })).collect();
                    blocks.push(webfusion_core::map::MapBlock { coords: [bx, by, bz], voxels, colors });
                }
            }
        }
    }
    (desc, blocks)
}

#[test]
fn a_sparse_map_renders_like_the_twin_and_the_dense_box_and_a_missing_block_is_seen() {
    // Samples that straddle blocks (a third of them at 4 cm voxels) read their corners from up
    // to eight blocks; unallocated blocks are crossed in one step.
    let (desc, blocks) = sparse_scene();
    let image = webfusion_core::map::PoolImage::from_blocks(desc, true, &blocks).expect("pool image");
    let pose = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.25), DVec3::new(0.2, -0.1, 0.1));
    let k = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
    let (g, c) = render_map(&params(desc, k, &pose), &image.voxels, &image.colors, &image.table);
    let hits = c.depth.iter().filter(|d| !d.is_nan()).count();
    eprintln!("{} blocks; {hits} of {} pixels hit", blocks.len(), c.depth.len());
    assert!(hits > 5000 && hits < c.depth.len(), "a mix of hits and misses ({hits})");
    assert_agree("sparse, rotated", &g, &c);
    // The dense box of the same scene on the same lattice sees the same surfaces.
    let (dense_desc, voxels, colors) = scene();
    let (dense, _) = render(&params(dense_desc, k, &pose), &voxels, &colors);
    // The sparse map also holds the plane beyond the box (the blocks reach 2 cm further
    // out): compare where the box sees anything. Rays that pass a silhouette may march
    // differently (a sparse map crosses unallocated blocks in one step, the box steps through
    // its observed free space), as for the range tiles.
    let dense_hits = dense.depth.iter().filter(|d| !d.is_nan()).count();
    assert!((0..c.depth.len()).all(|i| dense.depth[i].is_nan() || !g.depth[i].is_nan()), "the sparse map sees whatever the box sees");
    let within_box = Images { depth: g.depth.iter().zip(&dense.depth).map(|(&s, &d)| if d.is_nan() { f32::NAN } else { s }).collect(), ..g.clone() };
    eprintln!("sparse: {hits} pixels hit, the dense box {dense_hits}");
    assert_same_surfaces("sparse vs dense box", k, desc, &dense, &within_box);
    // Negative control: the map without one block of the plane in the middle of the view
    // renders differently from the twin's full map (the comparison sees block contents).
    let centre = (0..c.depth.len()).filter(|&i| !c.depth[i].is_nan()).min_by_key(|&i| (i as i64 - (60 * 160 + 80) as i64).abs()).expect("a hit");
    let p = c.vertex[centre];
    let hit_block = block_containing(&desc, [p[0], p[1], p[2]]);
    let holed: Vec<_> = blocks.iter().filter(|b| b.coords != hit_block).cloned().collect();
    assert_eq!(holed.len() + 1, blocks.len(), "the hit's block is one of the map's");
    let holed = webfusion_core::map::PoolImage::from_blocks(desc, true, &holed).expect("pool image");
    let (g_holed, _) = render_map(&params(desc, k, &pose), &holed.voxels, &holed.colors, &holed.table);
    let n = disagreements(&g_holed, &c);
    assert!(n > (MAX_DISAGREEING_FRACTION * c.depth.len() as f64) as usize, "a missing block is seen: {n} pixels");
}

/// The raycast compiled for maps of `kind`, with or without the depth hint's window (what
/// `RaycastTarget` dispatches).
fn variant(gpu: &Gpu, kind: u32, hints: bool) -> KernelPipeline {
    gpu.kernels.raycast.variant(&[("MAP_KIND", f64::from(kind)), ("DEPTH_HINTS", if hints { 1.0 } else { 0.0 })])
}

#[test]
fn pipelines_compiled_for_one_map_kind_render_like_the_twin_and_the_wrong_kind_cannot() {
    let pose = Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.25), DVec3::new(0.2, -0.1, 0.1));
    let k = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
    let allowed = (MAX_DISAGREEING_FRACTION * k.pixel_count() as f64) as usize;
    let gpu = gpu();
    let variant = |kind, hints| variant(&gpu, kind, hints);
    let (sparse_desc, blocks) = sparse_scene();
    let image = webfusion_core::map::PoolImage::from_blocks(sparse_desc, true, &blocks).expect("pool image");
    let sparse = |kernel: &KernelPipeline, s: &Setup| render_with(&gpu, kernel, s, &image.voxels, &image.colors, &image.table);
    let (dense_desc, voxels, colors) = scene();
    let dense = |kernel: &KernelPipeline, s: &Setup| render_with(&gpu, kernel, s, &voxels, &colors, &[0]);
    let (sparse_setup, dense_setup) = (params(sparse_desc, k, &pose), params(dense_desc, k, &pose));
    let (g, c) = sparse(&variant(MAP_SPARSE, false), &sparse_setup);
    assert!(c.depth.iter().filter(|d| !d.is_nan()).count() > 5000, "the sparse scene is in view");
    assert_agree("sparse-only raycast", &g, &c);
    let (g, c) = dense(&variant(MAP_DENSE, false), &dense_setup);
    assert!(c.depth.iter().filter(|d| !d.is_nan()).count() > 5000, "the box is in view");
    assert_agree("dense-only raycast", &g, &c);
    // With the hint's window: the measured depth is the twin's render, a seventh of it missing.
    let hint: Vec<f32> = c.depth.iter().enumerate().map(|(i, &d)| if i % 7 == 0 { f32::NAN } else { d }).collect();
    let hinted = Setup { hint: Some(hint), ..params(dense_desc, k, &pose) };
    let (g, c) = dense(&variant(MAP_DENSE, true), &hinted);
    assert_agree("dense-only raycast with hints", &g, &c);
    let sparse_hinted = Setup { hint: Some(c.depth.clone()), ..params(sparse_desc, k, &pose) };
    let (g, c) = sparse(&variant(MAP_SPARSE, true), &sparse_hinted);
    assert_agree("sparse-only raycast with hints", &g, &c);
    // Negative controls: each kind's pipeline reads the other's map as its own and renders
    // something else than the twin; a pipeline without the hint's window ignores a hint behind
    // every surface (the twin then sees nothing) and renders the unhinted image.
    let (g, c) = sparse(&variant(MAP_DENSE, false), &sparse_setup);
    let n = disagreements(&g, &c);
    assert!(n > allowed, "a dense-only raycast cannot read a sparse map: {n} pixels disagree");
    let (g, c) = dense(&variant(MAP_SPARSE, false), &dense_setup);
    let n = disagreements(&g, &c);
    assert!(n > allowed, "a sparse-only raycast cannot read the dense box: {n} pixels disagree");
    let behind = Setup { hint: Some(vec![4.5; k.pixel_count()]), ..params(dense_desc, k, &pose) };
    let (g, c) = dense(&variant(MAP_DENSE, false), &behind);
    assert!(c.depth.iter().all(|d| d.is_nan()), "the twin hinted behind every surface sees nothing");
    assert!(disagreements(&g, &c) > allowed, "the pipeline without hints does not read them");
    let (unhinted, _) = dense(&variant(MAP_DENSE, false), &dense_setup);
    assert_agree("hint ignored", &g, &unhinted);
    // One pipeline per set of constants.
    assert!(variant(MAP_SPARSE, false).pipeline == variant(MAP_SPARSE, false).pipeline, "the same constants give the same pipeline");
    assert!(variant(MAP_SPARSE, false).pipeline != variant(MAP_SPARSE, true).pipeline, "other constants another");
}
