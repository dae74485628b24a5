// SPDX-License-Identifier: MIT
//! `webfusion export-occupancy` on a synthetic room with exact geometry: the room fused at its
//! known poses and saved, then exported with and without carving. Free cells lie in the room's
//! open space, occupied cells on its surfaces, and what no camera saw (behind the walls, inside
//! the furniture) is unknown, never free. Bad grids and maps are clean errors.

use std::path::{Path, PathBuf};

use glam::DVec3;
use webfusion_core::sim::room::SyntheticRoom;

mod common;
use common::{fails, fused_room, ok, s, scratch, webfusion};

const FREE: u8 = 0;
const OCCUPIED: u8 = 255;
const UNKNOWN: u8 = 128;
const CELL_M: f64 = 0.05;
const VOXEL: &str = "0.04";

/// Signed distance from `p` to the room's solid geometry (walls, floor, ceiling, furniture):
/// positive in its open space, negative behind a wall or inside furniture.
fn room_distance_m(room: &SyntheticRoom, p: DVec3) -> f64 {
    let box_distance = |lo: DVec3, hi: DVec3| {
        let outside = (lo - p).max(DVec3::ZERO) + (p - hi).max(DVec3::ZERO);
        if outside.length() > 0.0 { outside.length() } else { -(p - lo).min(hi - p).min_element() }
    };
    let (lo, hi) = room.bounds();
    // Inside the room's box the open space ends at its faces; outside it, the distance is negative.
    let walls = -box_distance(lo, hi);
    room.boxes.iter().map(|b| box_distance(b.min, b.max)).fold(walls, f64::min)
}

struct Grid {
    dims: [u32; 3],
    corner: DVec3,
    cells: Vec<u8>,
    json: serde_json::Value,
}

impl Grid {
    fn read(path: &Path) -> Grid {
        let json: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path.with_extension("json")).expect("the JSON description")).expect("json");
        let dims: Vec<u32> = json["dims"].as_array().expect("dims").iter().map(|v| v.as_u64().expect("a dim") as u32).collect();
        let corner: Vec<f64> = json["origin_m"].as_array().expect("origin_m").iter().map(|v| v.as_f64().expect("a number")).collect();
        Grid { dims: [dims[0], dims[1], dims[2]], corner: DVec3::new(corner[0], corner[1], corner[2]), cells: std::fs::read(path).expect("the grid"), json }
    }

    /// Every cell's centre and state.
    fn cells(&self) -> impl Iterator<Item = (DVec3, u8)> + '_ {
        let [nx, ny, _] = self.dims.map(|d| d as usize);
        self.cells.iter().enumerate().map(move |(i, &c)| {
            let (x, y, z) = (i % nx, (i / nx) % ny, i / (nx * ny));
            (self.corner + CELL_M * (DVec3::new(x as f64, y as f64, z as f64) + 0.5), c)
        })
    }
}

#[test]
fn the_occupancy_grid_of_a_room_knows_free_from_occupied_from_unseen() {
    let dir = scratch("occupancy");
    let common::FusedRoom { gt, poses, map, .. } = fused_room(&dir, 24, VOXEL);
    let room = SyntheticRoom::new(4.0, 2.5, 4.0);

    // The room (x ±2, y -1..1.5, z ±2, the map in the poses' frame) and 0.5 m around it.
    let grid_args = |out: &PathBuf| vec!["export-occupancy".to_owned(), "--map".into(), s(&map).into(), "--out".into(), s(out).into(), "--voxel-size".into(), CELL_M.to_string(), "--dims".into(), "100,70,100".into(), "--center".into(), "0,0.25,0".into()];
    let carved = dir.join("carved.bin");
    let mut args = grid_args(&carved);
    args.extend(["--poses".to_owned(), s(&poses).to_owned()]);
    let summary = ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    eprintln!("{summary}");
    let grid = Grid::read(&carved);
    assert_eq!(grid.cells.len(), 100 * 70 * 100, "one byte per cell");
    assert_eq!(grid.json["values"], serde_json::json!({ "occupied": 255, "free": 0, "unknown": 128 }));
    assert_eq!(grid.json["frame"], "given_poses", "the grid says which frame it is in");
    assert_eq!(grid.json["carving"]["views"], serde_json::json!(gt.len()));
    let mu_m = grid.json["map_truncation_m"].as_f64().expect("μ");
    let voxel_m: f64 = VOXEL.parse().expect("voxel");
    let counts = &grid.json["counts"];
    assert_eq!(counts["occupied"].as_u64().unwrap_or(0) + counts["free"].as_u64().unwrap_or(0) + counts["unknown"].as_u64().unwrap_or(0), 700_000, "counts add up");

    // Against the room's exact geometry. A cell may hold a surface when its centre is within
    // half its diagonal of one; the map's own surface is within a voxel of the true one.
    let slack_m = 0.5 * 3_f64.sqrt() * CELL_M + voxel_m;
    // Seen for certain: a cell whose footprint some camera's image holds, with the true surface
    // along its centre's ray well beyond it (the carving camera has the room camera's field of
    // view). Cells nobody saw (the ceiling, the space behind the cameras) must stay unknown
    // whatever they hold.
    let f_px = 525.0 * 320.0 / 640.0;
    let cameras: Vec<_> = gt.iter().map(|p| p.world_from_camera.inverse()).collect();
    let seen = |p: DVec3| {
        let radius_m = 0.5 * 3_f64.sqrt() * CELL_M;
        cameras.iter().zip(&gt).any(|(camera_from_world, pose)| {
            let c = camera_from_world.transform_point(p);
            if c.z - radius_m < 0.3 {
                return false;
            }
            let (u, v, r_px) = (f_px * c.x / c.z + 159.5, f_px * c.y / c.z + 119.5, 2.0 * f_px * radius_m / (c.z - radius_m));
            if u < r_px || v < r_px || u > 319.0 - r_px || v > 239.0 - r_px {
                return false;
            }
            let eye = pose.world_from_camera.translation_m;
            let dir = (p - eye).normalize();
            room.cast(eye, dir).is_some_and(|hit| hit.t_m > (p - eye).length() + mu_m + 2.0 * slack_m + 0.1)
        })
    };
    // Beyond this distance from every surface the TSDF alone knows nothing (μ in front of a
    // surface, and up to a block's edge more in a block its band allocated).
    let band_reach_m = mu_m + 8.0 * voxel_m + slack_m;
    let (mut free_behind, mut occupied_astray, mut open, mut open_free, mut outside_unknown, mut outside) = (0, 0, 0, 0, 0, 0);
    let (mut deep, mut deep_free) = (0, 0);
    let mut worst_free = f64::INFINITY;
    for (p, state) in grid.cells() {
        let d = room_distance_m(&room, p);
        match state {
            FREE => {
                worst_free = worst_free.min(d);
                // Never free: behind a wall or inside furniture by more than the map's band.
                if d < -(mu_m + slack_m) {
                    free_behind += 1;
                }
            }
            OCCUPIED => {
                if d.abs() > mu_m + slack_m {
                    occupied_astray += 1;
                }
            }
            other => assert_eq!(other, UNKNOWN, "only three values"),
        }
        if d > 0.3 && seen(p) {
            open += 1;
            open_free += usize::from(state == FREE);
            if d > band_reach_m {
                deep += 1;
                deep_free += usize::from(state == FREE);
            }
        }
        if d < -0.3 {
            outside += 1;
            outside_unknown += usize::from(state == UNKNOWN);
        }
    }
    eprintln!(
        "open space seen, 30 cm from any surface: {open_free} of {open} cells free ({:.1} %); {outside_unknown} of {outside} cells 30 cm behind surfaces unknown; nearest free cell {worst_free:.3} m from the geometry; {free_behind} free cells behind surfaces, {occupied_astray} occupied cells off them",
        100.0 * open_free as f64 / open as f64
    );
    eprintln!("seen cells farther than {band_reach_m:.2} m from any surface: {deep_free} of {deep} free");
    assert_eq!(free_behind, 0, "unseen space is never free");
    assert_eq!(occupied_astray, 0, "occupied cells lie on the room's surfaces");
    assert!(outside_unknown == outside, "everything 30 cm behind the surfaces is unknown");
    // The misses are cells whose footprint also covers a nearer surface beside their ray (the
    // carving is conservative); measured 92.7 %, and 90.3 % deep in the open.
    assert!(open_free as f64 > 0.85 * open as f64, "what the cameras saw of the open space is free: {open_free} of {open}");
    assert!(deep > 500 && deep_free as f64 > 0.85 * deep as f64, "carving frees what the TSDF cannot reach: {deep_free} of {deep} cells farther than {band_reach_m:.2} m from any surface");

    // Without the poses only the band around the surfaces is known.
    let band = dir.join("band.bin");
    let out = webfusion(&grid_args(&band).iter().map(String::as_str).collect::<Vec<_>>());
    assert!(out.status.success() && String::from_utf8_lossy(&out.stderr).contains("no --poses"), "{}", String::from_utf8_lossy(&out.stderr));
    let band_grid = Grid::read(&band);
    let far_free = band_grid.cells().filter(|&(p, c)| c == FREE && room_distance_m(&room, p) > band_reach_m).count();
    let band_free = band_grid.cells().filter(|&(_, c)| c == FREE).count();
    eprintln!("free cells from the TSDF alone: {band_free}");
    assert!(band_free > 0 && far_free == 0, "free only near surfaces without carving: {band_free} free, {far_free} farther than {band_reach_m} m from any surface");
    assert_eq!(band_grid.json["carving"]["views"], 0);

    // The virtual sensor marks the pixels whose ray crossed never-observed space (from its near
    // range, 0.4 m, to its return). From poses the map was fused at, with the carved grid, a part
    // (measured 63 %: the carving is conservative, a cell within a footprint's width of a nearer
    // surface stays unknown, so most unknown cells lie near grazing surfaces and at the image
    // borders, and one on the way marks the ray); with the band-only grid nearly all (the open
    // space is not known free); from outside the grid every one.
    let views = dir.join("views.txt");
    let outside: Vec<_> = gt.iter().take(4).map(|p| webfusion_core::io::trajectory::TimedPose { world_from_camera: webfusion_core::Se3::new(p.world_from_camera.rotation, DVec3::new(0.0, 0.0, 9.0)), ..*p }).collect();
    std::fs::write(&views, webfusion_core::io::trajectory::format_tum_trajectory(&gt[..4])).expect("views");
    let far = dir.join("far.txt");
    std::fs::write(&far, webfusion_core::io::trajectory::format_tum_trajectory(&outside)).expect("views");
    let marked = |poses: &Path, grid: &Path, out: &str| -> f64 {
        let text = ok(&["simulate", "--map", s(&map), "--poses", s(poses), "--out", s(&dir.join(out)), "--image-size", "320x240", "--occupancy", s(grid)]);
        let masks: Vec<String> = std::fs::read_to_string(dir.join(out).join("unknown.txt")).expect("unknown.txt").lines().filter(|l| !l.starts_with('#')).map(|l| l.split_whitespace().nth(1).expect("a name").to_owned()).collect();
        assert_eq!(masks.len(), 4, "a mask per frame");
        let set: usize = masks.iter().map(|m| webfusion_core::codec::png::decode_rgb8(&std::fs::read(dir.join(out).join(m)).expect("mask"), 320, 240).expect("an 8-bit mask").rgb8.iter().filter(|&&v| v == 255).count() / 3).sum();
        let percent = 100.0 * set as f64 / (4.0 * 320.0 * 240.0);
        assert!(text.contains(&format!("{percent:.2} % of the pixels looked through never-observed space")), "{text}");
        percent
    };
    let (carved_pct, band_pct, outside_pct) = (marked(&views, &carved, "sim_carved"), marked(&views, &band, "sim_band"), marked(&far, &carved, "sim_outside"));
    eprintln!("pixels through never-observed space: {carved_pct:.2} % with the carved grid, {band_pct:.2} % with the band-only grid, {outside_pct:.2} % from outside the grid");
    assert!(carved_pct < 80.0, "from its own poses the carved map is mostly known: {carved_pct:.2} %");
    assert!(band_pct > 95.0, "without carving the open space is unknown: {band_pct:.2} %");
    assert!(outside_pct == 100.0, "outside the grid nothing is known: {outside_pct:.2} %");
    fails(&["simulate", "--map", s(&map), "--poses", s(&views), "--out", s(&dir.join("sim_bad")), "--occupancy", s(&dir.join("missing.json"))], "missing.json");

    // Bad input: clean errors that name the problem.
    let o = s(&dir.join("x.bin")).to_owned();
    fails(&["export-occupancy", "--map", s(&map), "--out", &o, "--dims", "0,10,10"], "--dims");
    fails(&["export-occupancy", "--map", s(&map), "--out", &o, "--dims", "10,10"], "3 numbers");
    fails(&["export-occupancy", "--map", s(&map), "--out", &o, "--voxel-size", "NaN"], "finite and positive");
    fails(&["export-occupancy", "--map", s(&map), "--out", &o, "--dims", "100000,100000,1000"], "4 GiB");
    fails(&["export-occupancy", "--map", s(&map), "--out", s(&dir.join("x.json"))], ".json beside it");
    let bytes = std::fs::read(&map).expect("map");
    let truncated = dir.join("truncated.wfm");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).expect("write");
    fails(&["export-occupancy", "--map", s(&truncated), "--out", &o, "--dims", "10,10,10"], "truncated");
}
