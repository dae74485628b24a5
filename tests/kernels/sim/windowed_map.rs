// SPDX-License-Identifier: MIT
//! A saved map larger than the GPU pool, rendered through a window (`map::window`): the
//! analytic room the swapping test fuses from its centre, rendered by the virtual sensor at
//! poses all around it and off its centre, once with every block on the GPU and once through a
//! pool of 40 % of the blocks. The depth is word for word the same at every pose, turning
//! uploads new windows (each writing only the blocks entering it) and nearby views reuse them. A view that alone reaches more blocks
//! than the pool is a typed error; a view that only looks at the map may take the nearest of
//! its blocks instead, and is then word for word the same for every surface nearer than the
//! distance it reports (and loses surfaces beyond it). Negative control: a window planned for
//! too short a range (so blocks the view reads stay on the host) renders other depth, and the
//! comparison sees it.

use glam::{DQuat, DVec3};
use webfusion_core::map::file::{MapFileHeader, MapFrame};
use webfusion_core::map::window::{MapWindow, NearestWindow, ViewCone, ViewedMap};
use webfusion_core::map::{MapBlock, SparseMap};
use webfusion_core::sim::sensor::{SensorOptions, VirtualSensor};
use webfusion_core::tsdf::{TsdfConfig, TsdfStore};
use webfusion_core::{Error, Gpu, Se3};
use webfusion_tests::{finish, gpu};

use crate::map::swapping::{K, VOXEL_M, fuse_room};
use crate::synthetic::UNITS_PER_M;

/// The header a saved copy of the fused room would carry.
fn header(origin_in_world: [f32; 3]) -> MapFileHeader {
    MapFileHeader::for_map(&TsdfConfig::sparse(VOXEL_M, 16384), origin_in_world, MapFrame::GivenPoses, None, "{}".to_owned())
}

/// The views: a full turn at the room's centre in 15° steps, then a walk towards a wall.
fn views() -> Vec<Se3> {
    let turn = (0..24).map(|i| Se3::new(DQuat::from_rotation_y((15.0 * f64::from(i)).to_radians()), DVec3::new(0.0, -0.1, 1.1)));
    let walk = (0..6).map(|i| Se3::new(DQuat::from_rotation_y(0.3), DVec3::new(0.1 * f64::from(i), -0.1, 1.1 - 0.1 * f64::from(i))));
    turn.chain(walk).collect()
}

fn options() -> SensorOptions {
    SensorOptions { units_per_metre: UNITS_PER_M, ..SensorOptions::default() }
}

/// The depth the sensor renders at every view of `views()` from `map`, preparing it first.
fn render_all(gpu: &Gpu, map: &mut ViewedMap) -> Vec<Vec<u16>> {
    let mut sensor = VirtualSensor::new(gpu, map.map(), K, options()).expect("sensor");
    let cone = ViewCone::for_camera(&K, options().depth_range_m);
    views()
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            map.prepare(gpu, pose, &cone).expect("the view fits the pool");
            pollster::block_on(sensor.render(gpu, map.map(), pose, i as u32)).expect("render").depth_units
        })
        .collect()
}

/// Views whose depth differs between `a` and `b`, with their differing pixel counts.
fn differing(a: &[Vec<u16>], b: &[Vec<u16>]) -> Vec<(usize, usize)> {
    a.iter().zip(b).enumerate().map(|(i, (x, y))| (i, x.iter().zip(y).filter(|(p, q)| p != q).count())).filter(|&(_, n)| n > 0).collect()
}

#[test]
fn a_windowed_map_renders_every_view_as_the_whole_map_does() {
    let (blocks, _, origin) = fuse_room(16384, false);
    let header = header(origin);
    let gpu = gpu();
    let mut whole = ViewedMap::load(&gpu, &header, blocks.clone(), None).expect("load");
    assert!(whole.window().is_none(), "the room fits the device's pool whole");
    let reference = render_all(&gpu, &mut whole);
    let hits = reference.iter().map(|d| d.iter().filter(|&&u| u > 0).count()).min().unwrap_or(0);
    assert!(hits > K.pixel_count() / 2, "every view sees the room ({hits} of {} pixels at least)", K.pixel_count());

    let pool = (blocks.len() * 2 / 5) as u32;
    let mut windowed = ViewedMap::load(&gpu, &header, blocks.clone(), Some(pool)).expect("load");
    let window = windowed.window().expect("more blocks than the pool: windowed");
    assert_eq!((window.blocks(), window.capacity()), (blocks.len(), pool as usize));
    let rendered = render_all(&gpu, &mut windowed);
    let (uploads, written) = windowed.window().map(|w| (w.uploads(), w.blocks_written())).expect("windowed");
    eprintln!("room: {} blocks, pool {pool}: {uploads} windows for {} views, {written} blocks written", blocks.len(), views().len());
    // After the first window each writes only the blocks entering it.
    assert!(written < u64::from(pool) * uploads / 2, "windows after the first write only what enters ({written} blocks for {uploads} windows of {pool})");
    assert_eq!(differing(&rendered, &reference), [], "views through the window differ from the whole map's");
    assert!(uploads > 1 && uploads < views().len() as u64 / 2, "turning uploads new windows, nearby views reuse them ({uploads})");

    // A view that alone reaches more blocks than the pool: a typed error, nothing rendered.
    let mut tiny = ViewedMap::load(&gpu, &header, blocks.clone(), Some(8)).expect("load");
    let err = tiny.prepare(&gpu, &views()[0], &ViewCone::for_camera(&K, options().depth_range_m)).expect_err("the view needs more than 8 blocks");
    let Error::ViewExceedsPool { pool_blocks: 8, view_blocks } = err else { panic!("{err}") };
    assert!(view_blocks > 8, "{view_blocks} blocks in view");
    nearest_blocks_render_the_near_surfaces_exactly(&gpu, &header, blocks.clone(), view_blocks, &reference[0]);
    finish(&gpu);

    // Negative control: windows planned for views that stop at 0.5 m leave blocks the sensor
    // (to 8 m) reads on the host, and the views render other depth.
    let gpu = webfusion_tests::gpu();
    let short = short_range_window_depths(&gpu, &header, blocks, pool);
    let missed = differing(&short, &reference);
    assert!(missed.iter().map(|&(_, n)| n).sum::<usize>() > K.pixel_count() / 10, "a window missing blocks must change the depth: {missed:?}");
    finish(&gpu);
}

/// The depth of every view through a window of `pool` blocks planned for views to 0.5 m.
fn short_range_window_depths(gpu: &Gpu, header: &MapFileHeader, blocks: Vec<MapBlock>, pool: u32) -> Vec<Vec<u16>> {
    let config = TsdfConfig { swap: false, ..TsdfConfig::sparse(VOXEL_M, pool) };
    let sparse = SparseMap::new(gpu, config, header.origin_in_world).expect("pool");
    let cone = ViewCone::for_camera(&K, (options().depth_range_m.0, 0.5));
    let mut window = MapWindow::new(&sparse.desc(), blocks, pool as usize);
    let mut sensor = VirtualSensor::new(gpu, &sparse, K, options()).expect("sensor");
    views()
        .iter()
        .enumerate()
        .map(|(i, pose)| {
            window.prepare(gpu, &sparse, pose, &cone).expect("the short view fits");
            pollster::block_on(sensor.render(gpu, &sparse, pose, i as u32)).expect("render").depth_units
        })
        .collect()
}

/// The first view through a pool of a third of its blocks, nearest first: identical to
/// `reference` wherever the surface is nearer than the distance the window reports, and
/// missing surfaces beyond it.
fn nearest_blocks_render_the_near_surfaces_exactly(gpu: &Gpu, header: &MapFileHeader, blocks: Vec<MapBlock>, view_blocks: usize, reference: &[u16]) {
    let pose = views()[0];
    let cone = ViewCone::for_camera(&K, options().depth_range_m);
    let pool = view_blocks / 3;
    let mut near = ViewedMap::load(gpu, header, blocks, Some(pool as u32)).expect("load");
    let window = near.prepare_nearest(gpu, &pose, &cone).expect("the nearest blocks");
    assert!(window.uploaded && window.left_out == view_blocks - pool, "{window:?} for {view_blocks} blocks in view, pool {pool}");
    assert!(window.complete_within_m > 0.5 && window.complete_within_m < cone.reach_m, "{window:?}");
    // The same view again keeps its window.
    assert_eq!(near.prepare_nearest(gpu, &pose, &cone).expect("again"), NearestWindow { uploaded: false, ..window }, "the same view keeps its window");
    let mut sensor = VirtualSensor::new(gpu, near.map(), K, options()).expect("sensor");
    let depth = pollster::block_on(sensor.render(gpu, near.map(), &pose, 0)).expect("render").depth_units;
    // Per pixel of the whole map's render: whether its surface lies within the complete
    // distance (the ray's length to it, from its planar depth).
    let (mut near_px, mut near_same, mut far_px, mut far_same) = (0usize, 0usize, 0usize, 0usize);
    for (i, (&r, &d)) in reference.iter().zip(&depth).enumerate() {
        if r == 0 {
            continue;
        }
        let (u, v) = ((i % K.width_px as usize) as f64, (i / K.width_px as usize) as f64);
        let ray = DVec3::new((u - f64::from(K.cx_px)) / f64::from(K.fx_px), (v - f64::from(K.cy_px)) / f64::from(K.fy_px), 1.0);
        let t_m = f64::from(r) / f64::from(UNITS_PER_M) * ray.length();
        if t_m < window.complete_within_m {
            near_px += 1;
            near_same += usize::from(d == r);
        } else {
            far_px += 1;
            far_same += usize::from(d == r);
        }
    }
    eprintln!("nearest {pool} of {view_blocks} blocks, complete within {:.2} m: {near_same} of {near_px} near pixels the same, {far_same} of {far_px} beyond", window.complete_within_m);
    assert!(near_px > K.pixel_count() / 20, "the window holds a part of the view worth comparing ({near_px} pixels)");
    assert_eq!(near_same, near_px, "surfaces within the complete distance render as with the whole map");
    // Negative control: beyond it surfaces are lost, so the same comparison there fails.
    assert!(far_same < far_px * 9 / 10, "a third of the view's blocks must lose far surfaces ({far_same} of {far_px} the same)");
}
