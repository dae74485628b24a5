// SPDX-License-Identifier: MIT
//! `raycast_hint_tiles`: on a real Kinect frame and on a sphere with a hole in its depth, the GPU
//! marks exactly the tiles the twin does; a tile is marked if and only if every pixel in it has
//! a measured depth at itself or 2 or 4 pixels away along x or y (checked against the raw depth
//! directly); and marking changes nothing a prediction renders: the raycast twin gives
//! bit-identical images with the marked tiles and with all tiles widened.

use glam::DVec3;
use webfusion_core::cpu::{self, fusion::raycast_range::TILE_UNUSED, shared::pack_u16_pairs};
use webfusion_core::fusion::predictor::{RANGE_TILE_PX, camera_pose};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::raycast::{DEFAULT_MAX_STEPS, DEFAULT_STEP_FACTOR, RaycastParams};
use webfusion_core::kernels::raycast_hint_tiles::RaycastHintTilesParams;
use webfusion_core::{PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots, sample_frame};

use super::raycast_range::{K, scene, sphere_depth};

fn params(k: PinholeIntrinsics) -> RaycastHintTilesParams {
    RaycastHintTilesParams { intrinsics: GpuIntrinsics::from(k), tile_px: RANGE_TILE_PX, tiles_x: k.width_px.div_ceil(RANGE_TILE_PX), tiles_y: k.height_px.div_ceil(RANGE_TILE_PX), hint_metres_per_unit: 1e-3 }
}

/// (GPU, CPU) tiles marked from cleared ones.
fn run(p: &RaycastHintTilesParams, raw: &[u16]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let packed = pack_u16_pairs(raw);
    let zeros = vec![0u32; (2 * p.tiles_x * p.tiles_y) as usize];
    let out = run_kernel_slots(&gpu, &gpu.kernels.raycast_hint_tiles, p, &[Slot::In(bytemuck::cast_slice(&packed)), Slot::InOut(bytemuck::cast_slice(&zeros))], [p.tiles_x, p.tiles_y, 1]);
    finish(&gpu);
    let mut c = zeros;
    cpu::raycast_hint_tiles(p, &packed, &mut c);
    (cast(&out[0]), c)
}

/// Whether every pixel of tile (tx, ty) has a return at itself or 2 or 4 pixels along x or y.
fn all_hinted(k: PinholeIntrinsics, raw: &[u16], tx: u32, ty: u32) -> bool {
    let at = |x: i64, y: i64| x >= 0 && y >= 0 && x < i64::from(k.width_px) && y < i64::from(k.height_px) && raw[(y * i64::from(k.width_px) + x) as usize] != 0;
    let (x0, y0) = (tx * RANGE_TILE_PX, ty * RANGE_TILE_PX);
    (y0..(y0 + RANGE_TILE_PX).min(k.height_px)).all(|y| {
        (x0..(x0 + RANGE_TILE_PX).min(k.width_px)).all(|x| {
            let (x, y) = (i64::from(x), i64::from(y));
            at(x, y) || [2, 4].iter().any(|&r| at(x + r, y) || at(x - r, y) || at(x, y + r) || at(x, y - r))
        })
    })
}

/// Checks the marks against the raw depth; returns (marked, tiles).
fn check_marks(p: &RaycastHintTilesParams, k: PinholeIntrinsics, raw: &[u16], tiles: &[u32]) -> Result<(usize, usize), String> {
    let mut marked = 0;
    for ty in 0..p.tiles_y {
        for tx in 0..p.tiles_x {
            let t = (ty * p.tiles_x + tx) as usize;
            let want = all_hinted(k, raw, tx, ty);
            let got = tiles[2 * t + 1] == TILE_UNUSED;
            if want != got || tiles[2 * t] != 0 || (!got && tiles[2 * t + 1] != 0) {
                return Err(format!("tile ({tx}, {ty}): marked {got}, all pixels hinted {want}, words {:#x} {:#x}", tiles[2 * t], tiles[2 * t + 1]));
            }
            marked += usize::from(got);
        }
    }
    Ok((marked, (p.tiles_x * p.tiles_y) as usize))
}

#[test]
fn a_real_frame_marks_the_tiles_whose_pixels_all_have_depth() {
    let (calibration, frame) = sample_frame(0);
    let k = calibration.intrinsics;
    let p = params(k);
    let raw = frame.depth.units.clone();
    let (g, c) = run(&p, &raw);
    assert_eq!(g, c, "GPU vs twin");
    let (marked, tiles) = check_marks(&p, k, &raw, &g).unwrap_or_else(|e| panic!("{e}"));
    eprintln!("{marked} of {tiles} tiles need no depth interval");
    assert!(marked > tiles / 2 && marked < tiles, "most tiles, not all, are hinted throughout ({marked} of {tiles})");
    // Negative control: a wrongly marked and a wrongly unmarked tile are both caught.
    let mut wrong = g.clone();
    let unmarked = (0..tiles).find(|&t| g[2 * t + 1] != TILE_UNUSED).expect("an unmarked tile");
    wrong[2 * unmarked + 1] = TILE_UNUSED;
    assert!(check_marks(&p, k, &raw, &wrong).is_err(), "a tile with an unhinted pixel marked is caught");
    let mut wrong = g.clone();
    let marked_tile = (0..tiles).find(|&t| g[2 * t + 1] == TILE_UNUSED).expect("a marked tile");
    wrong[2 * marked_tile + 1] = 0;
    assert!(check_marks(&p, k, &raw, &wrong).is_err(), "a hinted tile left unmarked is caught");
}

#[test]
fn marking_changes_nothing_a_prediction_renders() {
    let (desc, voxels) = scene();
    let pose = Se3::new(glam::DQuat::IDENTITY, DVec3::new(0.05, 0.0, 0.1));
    // The sphere's depth as the sensor would measure it (mm), with a 24-pixel hole in it.
    let raw: Vec<u16> = (0..K.height_px)
        .flat_map(|y| (0..K.width_px).map(move |x| (x, y)))
        .map(|(x, y)| if (60..84).contains(&x) && (50..74).contains(&y) { 0 } else { sphere_depth(&pose, x, y).map_or(0, |z| (z * 1000.0).round() as u16) })
        .collect();
    let p = params(K);
    let (g, c) = run(&p, &raw);
    assert_eq!(g, c, "GPU vs twin");
    let (marked, tiles) = check_marks(&p, K, &raw, &g).unwrap_or_else(|e| panic!("{e}"));
    assert!(marked > 0 && marked < tiles, "some tiles marked ({marked} of {tiles})");
    let cam = camera_pose(Some(&pose));
    let bricks = cpu::shared::surface_bricks(&desc, &voxels);
    let range_params = super::raycast_range::params(desc);
    let no_blocks = [0u32];
    let mut all_tiles = vec![0u32; g.len()];
    cpu::raycast_range(&range_params, &cam, &bricks, &mut all_tiles, &no_blocks);
    let mut marked_tiles = g;
    cpu::raycast_range(&range_params, &cam, &bricks, &mut marked_tiles, &no_blocks);
    let n = K.pixel_count();
    let rp = RaycastParams {
        volume: desc,
        intrinsics: GpuIntrinsics::from(K),
        min_depth_m: 0.3,
        max_depth_m: 5.0,
        step_factor: DEFAULT_STEP_FACTOR,
        max_steps: DEFAULT_MAX_STEPS,
        use_depth_hint: 1,
        hint_margin_m: desc.truncation_m,
        hint_metres_per_unit: 1e-3,
        range_tile_px: RANGE_TILE_PX,
        range_tiles_x: p.tiles_x,
        ..Default::default()
    };
    let packed = pack_u16_pairs(&raw);
    let render = |tiles: &[u32]| {
        let (mut v, mut d, mut col) = (vec![[0.0f32; 4]; n], vec![0.0f32; n], vec![0u32; n]);
        cpu::raycast(&rp, &cam, &voxels, &[0], &mut v, &mut d, &mut col, &packed, tiles, &no_blocks);
        (v.iter().flatten().map(|f| f.to_bits()).collect::<Vec<u32>>(), d.iter().map(|f| f.to_bits()).collect::<Vec<u32>>(), col)
    };
    let (with_all, with_marked) = (render(&all_tiles), render(&marked_tiles));
    let hits = with_all.1.iter().filter(|&&b| !f32::from_bits(b).is_nan()).count();
    assert!(hits > n / 10, "the sphere is seen ({hits} pixels)");
    assert!(with_all == with_marked, "the prediction is the same with marked tiles");
}
