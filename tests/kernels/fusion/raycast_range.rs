// SPDX-License-Identifier: MIT
//! `raycast_range`: the depth-range tiles match the CPU twin (atomicMax of integers is
//! order-independent; the bounds within 4 ulps, the GPU may contract the corner transform into
//! FMAs) at poses looking at the scene, turned away from
//! it and standing inside it (bricks reaching in front of the near plane); every surface point
//! the full march finds lies within its tile's interval (the tiles are conservative); tiles
//! no surface brick covers stay empty; a disabled pose writes nothing.

use glam::{DQuat, DVec3};
use webfusion_core::cpu::{self, raycast_range::tile_depth_range};
use webfusion_core::fusion::predictor::{RANGE_TILE_PX, camera_pose};
use webfusion_core::kernels::GpuIntrinsics;
use webfusion_core::kernels::raycast_range::{CameraPose, RaycastRangeParams};
use webfusion_core::mesh::tsdf_from_sdf;
use webfusion_core::tsdf::{TsdfConfig, VolumeDesc};
use webfusion_core::{PinholeIntrinsics, Se3};
use webfusion_tests::{Slot, cast, finish, gpu, run_kernel_slots};

pub(crate) const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 129.4, fy_px: 129.2, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
const MIN_DEPTH_M: f32 = 0.3;
const MAX_DEPTH_M: f32 = 5.0;

/// A sphere of 0.2 m at (0.3, 0.1, 1.0) in a 64³ volume of 4 cm voxels in front of the origin.
pub(crate) fn scene() -> (VolumeDesc, Vec<u32>) {
    let config = TsdfConfig::cube(64, 0.04);
    let desc = config.desc(config.origin_for_first_camera(&Se3::IDENTITY));
    let voxels = tsdf_from_sdf(&desc, 1, |p| ((p[0] - 0.3).powi(2) + (p[1] - 0.1).powi(2) + (p[2] - 1.0).powi(2)).sqrt() - 0.2);
    (desc, voxels)
}

pub(crate) fn params(desc: VolumeDesc) -> RaycastRangeParams {
    let (tiles_x, tiles_y) = (K.width_px.div_ceil(RANGE_TILE_PX), K.height_px.div_ceil(RANGE_TILE_PX));
    RaycastRangeParams { volume: desc, intrinsics: GpuIntrinsics::from(K), tile_px: RANGE_TILE_PX, tiles_x, tiles_y, min_depth_m: MIN_DEPTH_M, max_depth_m: MAX_DEPTH_M, ..Default::default() }
}

/// (GPU, CPU) tiles.
fn run(p: &RaycastRangeParams, pose: &CameraPose, bricks: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let gpu = gpu();
    let n = (2 * p.tiles_x * p.tiles_y) as usize;
    let zeros = vec![0u32; n];
    let no_blocks = [0u32];
    let slots = [Slot::In(bytemuck::bytes_of(pose)), Slot::In(bytemuck::cast_slice(bricks)), Slot::InOut(bytemuck::cast_slice(&zeros)), Slot::In(bytemuck::cast_slice(&no_blocks))];
    let out = run_kernel_slots(&gpu, &gpu.kernels.raycast_range, p, &slots, [p.volume.brick_count() as u32, 1, 1]);
    finish(&gpu);
    let mut c = zeros;
    cpu::raycast_range(p, pose, bricks, &mut c, &no_blocks);
    (cast(&out[0]), c)
}

/// Largest difference of a tile bound between GPU and CPU, in ulps: the corner transform may
/// contract into FMAs on the GPU.
const MAX_ULPS: u32 = 4;

/// Tiles whose coverage differs, or whose bounds differ by more than [`MAX_ULPS`] (a pixel
/// bound that rounds across a tile edge changes a tile's coverage: allowed for 0.5 % of them).
fn tiles_differ(g: &[u32], c: &[u32]) -> usize {
    g.chunks(2).zip(c.chunks(2)).filter(|(a, b)| (a[1] == 0) != (b[1] == 0) || a[0].abs_diff(b[0]) > MAX_ULPS || a[1].abs_diff(b[1]) > MAX_ULPS).count()
}

/// Camera depth (z) of the sphere's first hit along pixel (x, y)'s ray from `world_from_camera`.
pub(crate) fn sphere_depth(world_from_camera: &Se3, x: u32, y: u32) -> Option<f64> {
    let ray_cam = DVec3::new((f64::from(x) - f64::from(K.cx_px)) / f64::from(K.fx_px), (f64::from(y) - f64::from(K.cy_px)) / f64::from(K.fy_px), 1.0);
    let dir = world_from_camera.rotation * ray_cam.normalize();
    let o = world_from_camera.translation_m;
    let oc = o - DVec3::new(0.3, 0.1, 1.0);
    let b = oc.dot(dir);
    let disc = b * b - (oc.length_squared() - 0.04);
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 0.0).then(|| t * ray_cam.normalize().z)
}

#[test]
fn tiles_match_the_twin_and_bound_every_surface_point() {
    let (desc, voxels) = scene();
    let bricks = cpu::shared::surface_bricks(&desc, &voxels);
    let marked = bricks.iter().filter(|&&b| b != 0).count();
    assert!(marked > 10 && marked < bricks.len() / 4, "the sphere marks a few bricks ({marked} of {})", bricks.len());
    let p = params(desc);
    let poses = [
        ("ahead", Se3::IDENTITY),
        ("turned", Se3::new(DQuat::from_axis_angle(DVec3::new(0.3, 1.0, -0.2).normalize(), 0.25), DVec3::new(0.2, -0.1, 0.1))),
        ("beside the sphere", Se3::new(DQuat::from_rotation_y(0.4), DVec3::new(0.1, 0.1, 0.65))),
        ("away", Se3::new(DQuat::from_rotation_y(std::f64::consts::PI), DVec3::ZERO)),
    ];
    for (what, pose) in poses {
        let (g, c) = run(&p, &camera_pose(Some(&pose)), &bricks);
        let differ = tiles_differ(&g, &c);
        eprintln!("{what}: {differ} tiles differ between GPU and CPU");
        assert!(differ * 200 <= c.len() / 2, "{what}: {differ} tiles differ between GPU and CPU");
        let covered = c.chunks(2).filter(|t| t[1] != 0).count();
        let mut inside = 0;
        for y in 0..K.height_px {
            for x in 0..K.width_px {
                let Some(z) = sphere_depth(&pose, x, y) else { continue };
                if !(f64::from(MIN_DEPTH_M)..=f64::from(MAX_DEPTH_M)).contains(&z) {
                    continue;
                }
                let t = ((y / RANGE_TILE_PX) * p.tiles_x + x / RANGE_TILE_PX) as usize;
                let (near, far) = tile_depth_range([c[2 * t], c[2 * t + 1]]).unwrap_or_else(|| panic!("{what}: pixel ({x}, {y}) sees the sphere at {z:.3} m but its tile is empty"));
                assert!(f64::from(near) <= z && z <= f64::from(far), "{what}: pixel ({x}, {y}) sees the sphere at {z:.3} m, outside its tile's [{near}, {far}]");
                inside += 1;
            }
        }
        eprintln!("{what}: {covered} of {} tiles covered, {inside} sphere pixels inside their tiles' intervals", c.len() / 2);
        match what {
            "away" => assert_eq!(covered, 0, "looking away, no tile is covered"),
            // Standing by the sphere, its bricks reach in front of the near plane and cover
            // the whole image.
            "beside the sphere" => assert!(inside > 50 && covered == c.len() / 2, "{what}: the sphere is seen ({inside} pixels), every tile covered ({covered})"),
            _ => assert!(inside > 1000 && covered < c.len() / 2, "{what}: the sphere is seen ({inside} pixels) and some tiles stay empty ({covered} covered)"),
        }
    }
}

#[test]
fn a_disabled_pose_or_no_surface_brick_covers_nothing_and_the_comparison_can_fail() {
    let (desc, voxels) = scene();
    let bricks = cpu::shared::surface_bricks(&desc, &voxels);
    let p = params(desc);
    let (g, c) = run(&p, &CameraPose { enabled: 0, ..camera_pose(Some(&Se3::IDENTITY)) }, &bricks);
    assert!(g.iter().chain(&c).all(|&w| w == 0), "a disabled pose leaves the tiles cleared");
    let (g, c) = run(&p, &camera_pose(Some(&Se3::IDENTITY)), &vec![0; bricks.len()]);
    assert!(g.iter().chain(&c).all(|&w| w == 0), "without surface bricks every tile stays empty");
    // Negative control: the same comparison catches one tile's bound widened by one ulp.
    let (g, c) = run(&p, &camera_pose(Some(&Se3::IDENTITY)), &bricks);
    let t = c.iter().position(|&w| w != 0).expect("a covered tile");
    let mut bad = g.clone();
    bad[t] += MAX_ULPS + 1;
    assert_eq!(tiles_differ(&bad, &c), tiles_differ(&g, &c) + 1, "a tile bound 5 ulps off is counted");
    bad[t] = g[t];
    bad[t | 1] = 0;
    assert_eq!(tiles_differ(&bad, &c), tiles_differ(&g, &c) + 1, "a tile emptied is counted");
}
