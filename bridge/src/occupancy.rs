// SPDX-License-Identifier: MIT
//! `webfusion export-occupancy`: seed 000's occupancy grid of a saved map, with unknown space
//! kept apart from free space (`core::map::occupancy`). Free space beyond the TSDF's band is
//! carved from the map rendered at the poses it was fused from (`--poses`, e.g. the
//! `trajectory.txt` of the run that saved it).

use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::map::file::{MapFrame, read_map_file, read_map_file_recovering};
use webfusion_core::map::occupancy::{CarveView, FREE, GridSpec, OCCUPIED, OccupancyBuilder, UNKNOWN};
use webfusion_core::map::window::{ViewCone, ViewedMap};
use webfusion_core::sim::sensor::VirtualSensor;
use webfusion_core::{Gpu, GpuOptions};

/// Raw units per metre of the carving renders: 0.5 mm steps up to 32 m.
const CARVE_UNITS_PER_METRE: f32 = 2000.0;
/// Views rendered and held at once before they carve.
const CARVE_BATCH: usize = 32;

#[derive(clap::Args)]
pub(crate) struct ExportOccupancyArgs {
    /// The saved map (`reconstruct --save-map`).
    #[arg(long)]
    map: PathBuf,
    /// The grid file to write (one byte per cell); its description goes beside it as `.json`.
    #[arg(long)]
    out: PathBuf,
    /// Cell edge, metres.
    #[arg(long, default_value_t = 0.01)]
    voxel_size: f64,
    /// Cells along x, y, z.
    #[arg(long, default_value = "1024,1024,480", value_name = "NX,NY,NZ")]
    dims: String,
    /// The grid's centre in the map's frame, metres.
    #[arg(long, default_value = "0,0,0", value_name = "X,Y,Z")]
    center: String,
    /// The poses the map was fused from (`--poses`: its run's trajectory.txt), to carve the free
    /// space between each camera and what the map shows it; without, free space is known only
    /// within the map's truncation band of its surfaces.
    #[command(flatten)]
    given: crate::pose_args::PoseFileArgs,
    /// The carving camera `fx,fy,cx,cy[,W,H]` (default the Kinect's field of view at --image-size).
    #[arg(long, value_name = "FX,FY,CX,CY[,W,H]")]
    intrinsics: Option<String>,
    /// The carving camera's image size `WxH` (default 320x240).
    #[arg(long, value_name = "WxH")]
    image_size: Option<String>,
    /// Farthest surface a carving view looks for, metres.
    #[arg(long, default_value_t = 20.0)]
    max_depth: f32,
    /// Load the intact blocks of a damaged map file (with a warning) instead of stopping.
    #[arg(long)]
    skip_corrupt: bool,
}

fn numbers<const N: usize>(text: &str, what: &str) -> anyhow::Result<[f64; N]> {
    let values: Vec<f64> = text.split(',').map(|v| v.trim().parse::<f64>()).collect::<Result<_, _>>().map_err(|_| anyhow::anyhow!("{what} {text:?}: expected {N} comma-separated numbers"))?;
    <[f64; N]>::try_from(values).map_err(|v| anyhow::anyhow!("{what} {text:?}: expected {N} numbers, got {}", v.len()))
}

pub(crate) fn run(options: &GpuOptions, args: &ExportOccupancyArgs) -> anyhow::Result<()> {
    let dims = numbers::<3>(&args.dims, "--dims")?;
    anyhow::ensure!(dims.iter().all(|d| d.fract() == 0.0 && *d >= 1.0 && *d <= f64::from(u32::MAX)), "--dims {}: three positive whole numbers", args.dims);
    let spec = GridSpec { dims: dims.map(|d| d as u32), cell_m: args.voxel_size, center_m: numbers::<3>(&args.center, "--center")? };
    spec.validate()?;
    anyhow::ensure!(args.out.extension().is_none_or(|e| e != "json"), "--out {}: the grid's description is written as .json beside it; name the grid otherwise (e.g. .bin)", args.out.display());
    let poses = crate::simulate::given_poses(&args.given)?;
    let mut file = if args.skip_corrupt { read_map_file_recovering(&args.map) } else { read_map_file(&args.map) }.with_context(|| format!("reading the map {}", args.map.display()))?;
    if let Some(damage) = &file.damage {
        eprintln!("warning: {}: {damage}; using the intact blocks", args.map.display());
    }
    let header = &file.header.clone();
    let threads = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    let started = std::time::Instant::now();
    let mut builder = OccupancyBuilder::new(&spec, threads)?;
    let (mut render_s, mut carve_s) = (0.0, 0.0);
    let k = crate::simulate::camera(args.intrinsics.as_deref(), args.image_size.as_deref(), (320, 240))?;
    if let Some(poses) = &poses {
        // The map rendered at each pose it was fused from: exact depth from the camera on (no
        // near limit: a nearer surface must stop the carving), far enough for any room.
        let gpu = pollster::block_on(Gpu::new(options))?;
        // A map larger than the device's largest pool is rendered through a window holding
        // each view (map::window); the blocks come back for the marking below.
        let mut viewed = ViewedMap::load(&gpu, header, std::mem::take(&mut file.blocks), None).with_context(|| format!("loading {}", args.map.display()))?;
        let sensor_options = crate::simulate::kinect_sensor(CARVE_UNITS_PER_METRE, false, None, (Some(0.0), Some(args.max_depth)), false)?;
        let mut sensor = VirtualSensor::new(&gpu, viewed.map(), k, sensor_options)?;
        let cone = ViewCone::for_camera(&k, sensor_options.depth_range_m);
        for batch in poses.chunks(CARVE_BATCH) {
            let rendering = std::time::Instant::now();
            let mut depths = Vec::with_capacity(batch.len());
            for p in batch {
                viewed.prepare(&gpu, &p.world_from_camera, &cone)?;
                let frame = pollster::block_on(sensor.render(&gpu, viewed.map(), &p.world_from_camera, 0))?;
                depths.push(frame.depth_units.iter().map(|&u| f32::from(u) / CARVE_UNITS_PER_METRE).collect::<Vec<f32>>());
            }
            let errors = gpu.take_errors();
            anyhow::ensure!(errors.is_empty(), "the GPU reported errors: {}", errors.join("; "));
            render_s += rendering.elapsed().as_secs_f64();
            let carving = std::time::Instant::now();
            let views: Vec<CarveView> = batch.iter().zip(&depths).map(|(p, depth_m)| CarveView { world_from_camera: p.world_from_camera, intrinsics: k, depth_m }).collect();
            builder.carve(&views, f64::from(header.truncation_m))?;
            carve_s += carving.elapsed().as_secs_f64();
        }
        file.blocks = viewed.into_blocks();
    } else {
        eprintln!("note: no --poses: free space is known only within {:.1} cm of the map's surfaces (pass the poses the map was fused from to carve the rest)", header.truncation_m * 100.0);
    }
    let marking = std::time::Instant::now();
    let grid = builder.finish(header, &file.blocks);
    let tsdf_s = marking.elapsed().as_secs_f64();
    let counts = grid.counts();
    std::fs::write(&args.out, &grid.cells).with_context(|| format!("writing {}", args.out.display()))?;
    let frame = frame_name(header.frame);
    let axes = match header.frame {
        MapFrame::FirstCamera => "the first camera's: x right, y down, z forward (optical axis), metres",
        MapFrame::GivenPoses => "the frame of the poses the map was fused at (reconstruct --poses / --robot-poses), metres",
    };
    let corner = spec.corner_m();
    let total = spec.cell_count() as f64;
    let description = serde_json::json!({
        "format": "webfusion occupancy grid 1",
        "file": args.out.file_name().map(|n| n.to_string_lossy().into_owned()),
        "values": { "occupied": OCCUPIED, "free": FREE, "unknown": UNKNOWN },
        "values_meaning": "occupied: the map observed a surface in the cell (or just behind one); free: observed empty; unknown: never observed (not known to be free)",
        "layout": "one byte per cell, x fastest, then y, then z: index = x + nx * (y + ny * z)",
        "dims": spec.dims,
        "cell_size_m": spec.cell_m,
        "center_m": spec.center_m,
        "origin_m": corner.to_array(),
        "origin_is": "the lowest corner of cell (0, 0, 0); cell (x, y, z) spans origin_m + cell_size_m * [x, x+1) x [y, y+1) x [z, z+1)",
        "frame": frame,
        "frame_axes": axes,
        "map": args.map.display().to_string(),
        "map_voxel_size_m": header.voxel_size_m,
        "map_truncation_m": header.truncation_m,
        "carving": {
            "views": poses.as_ref().map_or(0, Vec::len),
            "poses": args.given.file().map(|f| f.display().to_string()),
            "camera": { "fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px, "width_px": k.width_px, "height_px": k.height_px },
            "margin_m": header.truncation_m,
            "max_depth_m": args.max_depth,
        },
        "counts": { "occupied": counts.occupied, "free": counts.free, "unknown": counts.unknown },
        "stages_s": { "render": render_s, "carve": carve_s, "tsdf": tsdf_s, "total": started.elapsed().as_secs_f64() },
    });
    let sidecar = args.out.with_extension("json");
    std::fs::write(&sidecar, serde_json::to_string_pretty(&description)? + "\n").with_context(|| format!("writing {}", sidecar.display()))?;
    println!(
        "{}: {}x{}x{} cells of {:.1} cm in the {frame} frame: {:.2} % occupied, {:.2} % free, {:.2} % unknown ({} carving views; render {render_s:.1} s, carve {carve_s:.1} s, TSDF {tsdf_s:.1} s, total {:.1} s); described in {}",
        args.out.display(),
        spec.dims[0],
        spec.dims[1],
        spec.dims[2],
        spec.cell_m * 100.0,
        100.0 * counts.occupied as f64 / total,
        100.0 * counts.free as f64 / total,
        100.0 * counts.unknown as f64 / total,
        poses.as_ref().map_or(0, Vec::len),
        started.elapsed().as_secs_f64(),
        sidecar.display()
    );
    Ok(())
}

/// A map frame as the grid's description names it (`frame`).
pub(crate) fn frame_name(frame: MapFrame) -> &'static str {
    match frame {
        MapFrame::FirstCamera => "first_camera",
        MapFrame::GivenPoses => "given_poses",
    }
}

/// The unknown mask of a view (`simulate --occupancy`'s unknown/ images, a render reply's
/// mask): a byte per pixel, 255 where the ray of camera `k` at `world_from_camera` crossed
/// space `grid` does not know before its hit `hit_m` (planar depths, 0 or NaN: none) within the
/// sensor's range `range_m`, else 0 ([`OccupancyGrid::rays_through_unknown`] on every core).
pub(crate) fn unknown_mask(grid: &webfusion_core::map::occupancy::OccupancyGrid, k: webfusion_core::PinholeIntrinsics, world_from_camera: &webfusion_core::Se3, hit_m: &[f32], range_m: (f32, f32)) -> webfusion_core::Result<Vec<u8>> {
    let threads = std::thread::available_parallelism().map_or(1, usize::from);
    let marks = grid.rays_through_unknown(k, world_from_camera, hit_m, false, (f64::from(range_m.0), f64::from(range_m.1)), threads)?;
    Ok(marks.iter().map(|&m| if m { 255 } else { 0 }).collect())
}

/// Reads the grid at `path` (as [`read_grid`]) for the map at `map_path`, whose frame is
/// `map_frame`: a grid in another frame is an error naming both.
pub(crate) fn read_grid_for_map(path: &std::path::Path, map_frame: MapFrame, map_path: &std::path::Path) -> anyhow::Result<webfusion_core::map::occupancy::OccupancyGrid> {
    let (grid, grid_frame) = read_grid(path)?;
    let map_frame = frame_name(map_frame);
    anyhow::ensure!(grid_frame == map_frame, "{}: the grid is in the {grid_frame} frame, the map {} in the {map_frame} frame", path.display(), map_path.display());
    Ok(grid)
}

/// Reads a grid `export-occupancy` wrote: its description (`G.json`, or the grid's own path
/// `G.bin` with the description beside it) and the cells it names. A description of another
/// format, a grid of the wrong size or values outside the three states are errors naming the
/// file.
pub(crate) fn read_grid(path: &std::path::Path) -> anyhow::Result<(webfusion_core::map::occupancy::OccupancyGrid, String)> {
    let sidecar = path.with_extension("json");
    let text = std::fs::read_to_string(&sidecar).with_context(|| format!("reading the grid's description {}", sidecar.display()))?;
    let d: serde_json::Value = serde_json::from_str(&text).with_context(|| format!("{}: not JSON", sidecar.display()))?;
    let bad = |what: &str| anyhow::anyhow!("{}: {what}", sidecar.display());
    anyhow::ensure!(d["format"] == "webfusion occupancy grid 1", bad("not a webfusion occupancy grid description (format)"));
    let dims: [u32; 3] = serde_json::from_value(d["dims"].clone()).map_err(|_| bad("dims is not three whole numbers"))?;
    let cell_m = d["cell_size_m"].as_f64().ok_or_else(|| bad("no cell_size_m"))?;
    let center_m: [f64; 3] = serde_json::from_value(d["center_m"].clone()).map_err(|_| bad("center_m is not three numbers"))?;
    let frame = d["frame"].as_str().unwrap_or("unknown").to_owned();
    let spec = GridSpec { dims, cell_m, center_m };
    spec.validate().map_err(|e| bad(&e.to_string()))?;
    let file = d["file"].as_str().ok_or_else(|| bad("no file"))?;
    let cells_path = sidecar.with_file_name(file);
    let cells = std::fs::read(&cells_path).with_context(|| format!("reading the grid {}", cells_path.display()))?;
    anyhow::ensure!(cells.len() as u64 == spec.cell_count(), "{}: {} bytes, but {} describes {}x{}x{} = {} cells", cells_path.display(), cells.len(), sidecar.display(), dims[0], dims[1], dims[2], spec.cell_count());
    if let Some(at) = cells.iter().position(|&c| c != OCCUPIED && c != FREE && c != UNKNOWN) {
        anyhow::bail!("{}: byte {at} is {}, not one of the three states ({OCCUPIED}, {FREE}, {UNKNOWN})", cells_path.display(), cells[at]);
    }
    Ok((webfusion_core::map::occupancy::OccupancyGrid { spec, cells }, frame))
}
