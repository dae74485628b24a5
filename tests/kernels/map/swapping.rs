// SPDX-License-Identifier: MIT
//! Swapping end to end: the analytic room fused by the pose-driven mapper from its centre while
//! the camera turns a full circle and a quarter more, into a pool that holds about half the
//! room. Blocks behind the camera go to the host and come back when it faces them again, and
//! the map (every block, on the GPU or the host) is word for word the map a pool large enough
//! for the room builds without swapping. Without swapping the same small pool runs out and the
//! map differs (the negative control).

use glam::{DQuat, DVec3};
use webfusion_core::fusion::pose_driven::PoseDrivenMapper;
use webfusion_core::map::{MapBlock, MapStats};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::tsdf::TsdfConfig;
use webfusion_core::{ColorImage, DepthImage, PinholeIntrinsics, RgbdCalibration, RgbdFrame, Se3};
use webfusion_tests::{finish, gpu};

use crate::synthetic::{Room, UNITS_PER_M};

/// 160x120 camera with TUM-like focal lengths.
pub(crate) const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 129.3, fy_px: 129.1, cx_px: 79.6, cy_px: 63.8, width_px: 160, height_px: 120 };
/// Voxel edge: 2 cm (blocks of 16 cm).
pub(crate) const VOXEL_M: f32 = 0.02;
/// Frames: 10° of yaw each, 450° in all.
const FRAMES: usize = 46;

/// Frame `i`'s pose: at the room's centre, turned 10° per frame about the vertical (y) axis.
pub(crate) fn pose(i: usize) -> Se3 {
    Se3::new(DQuat::from_rotation_y((10.0 * i as f64).to_radians()), DVec3::new(0.0, -0.1, 1.1))
}

fn frame(i: usize) -> RgbdFrame {
    let units = Room::render_depth_units(&K, &pose(i));
    let color: Vec<u8> = (0..K.pixel_count()).flat_map(|p| [(p % 251) as u8, (i * 5) as u8, 90]).collect();
    RgbdFrame {
        index: i as u64,
        depth_timestamp_ns: i as i64 * 33_333_333,
        color_timestamp_ns: i as i64 * 33_333_333,
        depth: DepthImage::new(K.width_px, K.height_px, units).expect("depth size"),
        color: ColorImage::new(K.width_px, K.height_px, color).expect("colour size"),
    }
}

/// Fuses every frame into a sparse map of `pool_blocks`: (all blocks, the stats after each frame).
fn fuse(pool_blocks: u32, swap: bool) -> (Vec<MapBlock>, Vec<MapStats>) {
    let (blocks, stats, _) = fuse_room(pool_blocks, swap);
    (blocks, stats)
}

/// [`fuse`], with the map's origin (the world position of its box's voxel (0, 0, 0) corner).
pub(crate) fn fuse_room(pool_blocks: u32, swap: bool) -> (Vec<MapBlock>, Vec<MapStats>, [f32; 3]) {
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let tsdf = TsdfConfig { swap, ..TsdfConfig::sparse(VOXEL_M, pool_blocks) };
    let mut mapper = PoseDrivenMapper::new(&gpu, calibration, PreprocessConfig::default(), tsdf, &pose(0), false).expect("mapper");
    let mut stats = Vec::new();
    for i in 0..FRAMES {
        pollster::block_on(mapper.submit_frame(&gpu, &frame(i), &pose(i))).expect("fuse");
        // Collect this frame's counters before the next one, so every frame is in the record.
        pollster::block_on(mapper.flush(&gpu)).expect("flush");
        stats.push(mapper.map_stats().expect("a sparse map reports"));
    }
    let blocks = pollster::block_on(mapper.download_blocks(&gpu)).expect("download");
    let origin = mapper.mapper().origin_in_world();
    finish(&gpu);
    (blocks, stats, origin)
}

#[test]
fn a_swapping_pool_builds_the_map_a_large_pool_builds() {
    let (reference, ref_stats) = fuse(16384, false);
    let total = reference.len() as u32;
    let last = ref_stats.last().expect("frames");
    assert!(!last.exhausted() && last.blocks_used == total, "the large pool holds the room ({total} blocks)");
    let pool = total / 2;
    let (swapped, stats) = fuse(pool, true);
    let end = stats.last().expect("frames");
    let peak_host = stats.iter().map(|s| s.blocks_on_host).max().unwrap_or(0);
    eprintln!("room: {total} blocks; pool {pool}: {} swapped out, {} swapped in, peak {peak_host} on the host, {} resident at the end, peak resident {}", end.swapped_out_total, end.swapped_in_total, end.blocks_used, stats.iter().map(|s| s.blocks_used).max().unwrap_or(0));
    assert!(end.swapped_out_total > u64::from(total / 4), "blocks were swapped out ({})", end.swapped_out_total);
    assert!(end.swapped_in_total > 0, "blocks came back when the camera faced them again");
    assert_eq!((end.pool_full, end.hash_full, end.swap_in_refused, end.swapped_hits), (0, 0, 0, 0), "no exhaustion, and every block the camera saw was resident");
    assert!(stats.iter().all(|s| s.blocks_used <= pool), "resident blocks stay within the pool");
    assert_eq!(swapped.len(), reference.len(), "the same blocks");
    let differing = swapped.iter().zip(&reference).filter(|(a, b)| a != b).count();
    assert_eq!(differing, 0, "{differing} blocks differ from the large pool's");
    // A saved map larger than a pool loads with the nearest blocks on the GPU and the rest on
    // the host (their keys swapped out), and downloads exactly as saved.
    {
        let gpu = gpu();
        let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
        let mut loaded = PoseDrivenMapper::new(&gpu, calibration, PreprocessConfig::default(), TsdfConfig::sparse(VOXEL_M, pool), &pose(0), false).expect("mapper");
        loaded.mapper_mut().upload_blocks(&gpu, reference.clone(), Some(&pose(0))).expect("upload");
        let on_host = loaded.mapper().swapper().expect("swapping").blocks_on_host();
        assert!(on_host > 0 && on_host < reference.len(), "part of the map waits on the host ({on_host} of {})", reference.len());
        assert_eq!(pollster::block_on(loaded.download_blocks(&gpu)).expect("download"), reference, "the loaded map downloads as saved");
        // Fusing the first frames again brings blocks back in from the host, none missed.
        for i in 0..6 {
            pollster::block_on(loaded.submit_frame(&gpu, &frame(i), &pose(i))).expect("fuse");
            pollster::block_on(loaded.flush(&gpu)).expect("flush");
        }
        let s = loaded.map_stats().expect("stats");
        assert_eq!((s.pool_full, s.swapped_hits), (0, 0), "the loaded map fuses without exhaustion or misses");
        finish(&gpu);
    }
    // Negative control: the same pool without swapping runs out, and the comparison sees it.
    let (unswapped, unswapped_stats) = fuse(pool, false);
    assert!(unswapped_stats.last().expect("frames").pool_full > 0, "without swapping the pool runs out");
    assert_ne!(unswapped, reference, "and its map differs from the large pool's");
}

/// Frames of the slow turn: 2° each, 400° in all.
const SLOW_FRAMES: usize = 200;

/// Frame `i` of a slow turn (2° per frame) at the room's centre: slow enough for the swapper's
/// motion floor to let its margins shrink.
fn slow_pose(i: usize) -> Se3 {
    Se3::new(DQuat::from_rotation_y((2.0 * i as f64).to_radians()), DVec3::new(0.0, -0.1, 1.1))
}

/// Fuses the slow turn into a swapping pool of `pool_blocks` (`None`: a pool large enough, not
/// swapping) whose margins may shrink down to `min_margin_scale` (1: pinned): (all blocks, the
/// last frame's stats).
fn fuse_under_pressure(pool_blocks: Option<u32>, min_margin_scale: f32) -> (Vec<MapBlock>, MapStats) {
    let gpu = gpu();
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: UNITS_PER_M };
    let tsdf = TsdfConfig { swap: pool_blocks.is_some(), ..TsdfConfig::sparse(VOXEL_M, pool_blocks.unwrap_or(16384)) };
    let mut mapper = PoseDrivenMapper::new(&gpu, calibration, PreprocessConfig::default(), tsdf, &slow_pose(0), false).expect("mapper");
    if let Some(s) = mapper.mapper_mut().swapper_mut() {
        s.set_min_margin_scale(min_margin_scale);
    }
    for i in 0..SLOW_FRAMES {
        let units = Room::render_depth_units(&K, &slow_pose(i));
        let f = RgbdFrame { depth: DepthImage::new(K.width_px, K.height_px, units).expect("depth size"), ..frame(0) };
        let f = RgbdFrame { index: i as u64, depth_timestamp_ns: i as i64 * 33_333_333, color_timestamp_ns: i as i64 * 33_333_333, ..f };
        pollster::block_on(mapper.submit_frame(&gpu, &f, &slow_pose(i))).expect("fuse");
        pollster::block_on(mapper.flush(&gpu)).expect("flush");
    }
    let stats = mapper.map_stats().expect("a sparse map reports");
    let blocks = pollster::block_on(mapper.download_blocks(&gpu)).expect("download");
    finish(&gpu);
    (blocks, stats)
}

/// The room turned slowly (2° a frame, 400°) into a pool of 45 % of it: the kept region at
/// full margins (the image's cone + 30°, 1.5 m around the camera) holds more than the pool's
/// eviction mark, so eviction runs dry, swap-ins find no room and the turning camera meets
/// blocks still on the host. Under the pressure rule the margins shrink (not below what the
/// camera's motion needs) and the map equals a large pool's word for word; pinned at full
/// margins (the negative control) the camera misses thousands of band samples and the maps
/// differ.
#[test]
fn a_pool_too_small_for_the_kept_region_shrinks_the_margins_and_misses_nothing() {
    let (reference, _) = fuse_under_pressure(None, 1.0);
    let total = reference.len() as u32;
    let pool = total * 45 / 100;
    let (pinned_blocks, pinned) = fuse_under_pressure(Some(pool), 1.0);
    let (adaptive_blocks, adaptive) = fuse_under_pressure(Some(pool), 0.125);
    let differing = |blocks: &[MapBlock]| {
        let by_key: std::collections::HashMap<[u32; 3], &MapBlock> = reference.iter().map(|b| (b.coords, b)).collect();
        blocks.iter().filter(|b| by_key.get(&b.coords).is_none_or(|r| *r != *b)).count() + reference.len().saturating_sub(blocks.len())
    };
    let (pinned_differ, adaptive_differ) = (differing(&pinned_blocks), differing(&adaptive_blocks));
    eprintln!("room: {total} blocks, pool {pool}: pinned margins: {} band samples met a block on the host, {} refused by the full pool, {pinned_differ} blocks differ; adaptive: {} met, {} refused, margins shrank {} times to {} %, {adaptive_differ} differ", pinned.swapped_hits, pinned.pool_full, adaptive.swapped_hits, adaptive.pool_full, adaptive.swap_margin_shrinks, adaptive.swap_margin_percent);
    assert!(pinned.swapped_hits > 1000 && pinned_differ > 0, "the negative control: at full margins the camera meets blocks on the host ({}) and the map differs ({pinned_differ} blocks)", pinned.swapped_hits);
    assert_eq!(pinned.swap_margin_shrinks, 0, "pinned margins never shrink");
    assert!(adaptive.swap_margin_shrinks >= 1 && adaptive.swap_margin_percent < 100, "the margins shrank");
    // 3 x 2° of motion over the fetch margin's 15°: the floor.
    assert!(adaptive.swap_margin_percent >= 40, "not below the camera's motion floor ({} %)", adaptive.swap_margin_percent);
    assert_eq!((adaptive.swapped_hits, adaptive.pool_full, adaptive.swap_in_refused), (0, 0, 0), "under the pressure rule every block the camera sees is on the GPU");
    assert_eq!(adaptive_blocks.len(), reference.len(), "the same blocks");
    assert_eq!(adaptive_differ, 0, "the map equals the large pool's");
}
