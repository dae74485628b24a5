// SPDX-License-Identifier: MIT
//! A room larger than the map's GPU pool: the synthetic furnished room (6 x 3 x 6 m, 4 cm
//! voxels) fused at its path's exact poses into a pool of a third of the blocks it needs. The
//! map swaps blocks to the host and back without running out or missing a block the camera saw,
//! reports the host memory it uses, and its mesh (gathered from the GPU and the host) covers
//! every wall wherever no furniture hides it.

use glam::DVec3;
use webfusion_core::fusion::pose_driven::PoseDrivenMapper;
use webfusion_core::map::MapStats;
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::sim::room::{FLOOR_Y_M, SyntheticRoom};
use webfusion_core::tsdf::TsdfConfig;
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};
use webfusion_tests::{finish, gpu};

const K: PinholeIntrinsics = PinholeIntrinsics { fx_px: 131.25, fy_px: 131.25, cx_px: 79.5, cy_px: 59.5, width_px: 160, height_px: 120 };
const VOXEL_M: f32 = 0.04;
const FRAMES: usize = 150;
/// Edge of the wall cells the coverage is counted on, metres.
const CELL_M: f64 = 0.3;

/// Of the cells of the plane `axis` = `at` (within the room, heights/extents where the camera's
/// view reaches), those no furniture box comes within 0.7 m of, and the share of them holding a
/// mesh vertex within 3 cm of the plane.
fn coverage(room: &SyntheticRoom, positions: &[[f32; 3]], axis: usize, at: f64, span: [(usize, f64, f64); 2]) -> (usize, f64) {
    let [(a, a0, a1), (b, b0, b1)] = span;
    let (na, nb) = (((a1 - a0) / CELL_M) as usize, ((b1 - b0) / CELL_M) as usize);
    let mut hit = vec![false; na * nb];
    for p in positions {
        let p = DVec3::from_array(p.map(f64::from));
        if (p[axis] - at).abs() > 0.03 {
            continue;
        }
        let (i, j) = (((p[a] - a0) / CELL_M).floor(), ((p[b] - b0) / CELL_M).floor());
        if i >= 0.0 && j >= 0.0 && (i as usize) < na && (j as usize) < nb {
            hit[i as usize * nb + j as usize] = true;
        }
    }
    let (mut free, mut covered) = (0usize, 0usize);
    for i in 0..na {
        for j in 0..nb {
            let (lo_a, lo_b) = (a0 + i as f64 * CELL_M, b0 + j as f64 * CELL_M);
            let hidden = room.boxes.iter().any(|bx| {
                bx.max[a] > lo_a && bx.min[a] < lo_a + CELL_M && bx.max[b] > lo_b && bx.min[b] < lo_b + CELL_M && (bx.min[axis] - at).abs().min((bx.max[axis] - at).abs()) < 0.7
            });
            if !hidden {
                free += 1;
                covered += usize::from(hit[i * nb + j]);
            }
        }
    }
    (free, covered as f64 / free.max(1) as f64)
}

#[test]
fn a_room_larger_than_the_pool_is_mapped_by_swapping_and_its_mesh_covers_the_walls() {
    let gpu = gpu();
    let room = SyntheticRoom::new(6.0, 3.0, 6.0);
    let path = room.path(FRAMES);
    let calibration = RgbdCalibration { intrinsics: K, depth_units_per_metre: 5000.0 };
    let pool = 600;
    let mut mapper = PoseDrivenMapper::new(&gpu, calibration, PreprocessConfig::default(), TsdfConfig::sparse(VOXEL_M, pool), &path[0], false).expect("mapper");
    let mut peak = MapStats::default();
    for i in 0..FRAMES {
        pollster::block_on(mapper.submit_frame(&gpu, &room.frame(&K, &path, i), &path[i])).expect("fuse");
        if let Some(s) = mapper.map_stats() {
            peak.blocks_on_host = peak.blocks_on_host.max(s.blocks_on_host);
            peak.blocks_used = peak.blocks_used.max(s.blocks_used);
        }
    }
    pollster::block_on(mapper.flush(&gpu)).expect("flush");
    let end = mapper.map_stats().expect("a sparse map reports");
    let mesh = pollster::block_on(mapper.extract_mesh(&gpu)).expect("mesh");
    let blocks = end.blocks_used + end.blocks_on_host;
    eprintln!("room: {blocks} blocks, pool {pool} (peak {} resident), {} on the host at the end ({:.1} MiB, peak {}); {} swapped out, {} in; mesh {} triangles", peak.blocks_used, end.blocks_on_host, end.host_bytes as f64 / 1048576.0, peak.blocks_on_host, end.swapped_out_total, end.swapped_in_total, mesh.triangles.len());
    assert!(blocks > 2 * pool, "the room needs more than twice the pool ({blocks} blocks)");
    assert!(end.swapped_in_total > 0, "blocks came back as the loop closed");
    assert_eq!((end.pool_full, end.hash_full, end.swapped_hits, end.swap_in_refused), (0, 0, 0, 0), "no exhaustion, nothing the camera saw was on the host");
    assert_eq!(end.host_bytes, u64::from(end.blocks_on_host) * (4 + 2 * 4 * 512), "host memory is reported per block (surface word, voxels, colours)");
    let (lo, hi) = room.bounds();
    // Walls between 0.3 and 1.8 m above the floor (the camera's view reaches them; the floor it
    // sees only near the walls, looking outward 12° down).
    let band = (1, FLOOR_Y_M - 1.8, FLOOR_Y_M - 0.3);
    let faces = [
        ("wall x-", 0, lo.x, [(2, lo.z, hi.z), band]),
        ("wall x+", 0, hi.x, [(2, lo.z, hi.z), band]),
        ("wall z-", 2, lo.z, [(0, lo.x, hi.x), band]),
        ("wall z+", 2, hi.z, [(0, lo.x, hi.x), band]),
    ];
    for (name, axis, at, span) in faces {
        let (free, share) = coverage(&room, &mesh.positions_m, axis, at, span);
        eprintln!("{name}: {:.1} % of {free} unhidden cells of {CELL_M} m covered", 100.0 * share);
        assert!(free > 10 && share > 0.9, "{name}: the mesh covers {:.1} % of {free} cells", 100.0 * share);
    }
    // Negative control: a plane the room does not have is not covered.
    let (_, share) = coverage(&room, &mesh.positions_m, 0, 0.5 * (lo.x + hi.x) + 0.77, [(2, lo.z, hi.z), band]);
    assert!(share < 0.2, "a plane through the room's middle is not covered ({:.1} %)", 100.0 * share);
    finish(&gpu);
}
