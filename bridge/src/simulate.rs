// SPDX-License-Identifier: MIT
//! `webfusion simulate`: seed 000's virtual depth sensor. Renders a saved map (`.wfm`) at every
//! given pose into a TUM-layout directory (depth/, optional rgb/, the lists, the poses as
//! ground truth and a calibration file the reader picks up), so that `reconstruct`, `serve`
//! and `compare` read it with no flags: a closed loop for planners and trackers.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use webfusion_core::io::trajectory::{TimedPose, write_tum_trajectory};
use webfusion_core::io::tum::ImageListWriter;
use webfusion_core::io::{CALIBRATION_FILE, WrittenCalibration, format_calibration_file, format_timestamp_s};
use webfusion_core::source::DepthNoise;
use webfusion_core::map::file::{MapFileHeader, read_map_file, read_map_file_recovering};
use webfusion_core::map::occupancy::OccupancyGrid;
use webfusion_core::map::window::{ViewCone, ViewedMap};
use webfusion_core::sim::sensor::{KinectModel, SensorOptions, SimulatedFrame, VirtualSensor};
use webfusion_core::tsdf::TsdfStore as _;
use webfusion_core::{ColorImage, DepthImage, Gpu, GpuOptions, PinholeIntrinsics, RgbdCalibration};

use crate::timing::StageTimes;

/// Frame period given to poses without timestamps (`--robot-poses` in frame order): 30 Hz.
const FRAME_PERIOD_NS: i64 = 33_333_333;

#[derive(clap::Args)]
pub(crate) struct SimulateArgs {
    /// The saved map to render (`reconstruct --save-map`).
    #[arg(long)]
    map: PathBuf,
    /// The poses to render at (`--poses`: `reconstruct`'s trajectory.txt holds the poses of the
    /// frames it fused, at their depth timestamps).
    #[command(flatten)]
    given: crate::pose_args::PoseFileArgs,
    /// The output directory (TUM layout; must not hold a simulation already).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Intrinsics `fx,fy,cx,cy` in pixels (optionally `,W,H`). Default: the camera the map was
    /// fused from (`reconstruct --save-map` records it), else (or with --image-size alone) the
    /// Kinect's nominal 525 px at 640x480, scaled to --image-size.
    #[arg(long, value_name = "FX,FY,CX,CY[,W,H]")]
    intrinsics: Option<String>,
    /// Image size `WxH` (default 640x480).
    #[arg(long, value_name = "WxH")]
    image_size: Option<String>,
    /// Raw depth units per metre (TUM: 5000).
    #[arg(long, default_value_t = 5000.0)]
    depth_scale: f32,
    /// Write distances along each pixel's ray instead of depth along z.
    #[arg(long)]
    radial: bool,
    /// The depth noise: `none` (exact) or `kinect` (Kinect v1: Nguyen et al. 2012 axial and
    /// lateral noise, 1/8-pixel disparity quantisation, projector shadows, dropouts at grazing
    /// angles and depth edges; see ARCHITECTURE.md).
    #[arg(long, default_value = "none")]
    noise: NoiseKind,
    /// Seed of the noise (a frame's noise depends only on the seed, its index and the pixel).
    #[arg(long, default_value_t = 0)]
    seed: u32,
    /// Also write the map's colour (rgb/, rgb.txt, rgbd_assoc.txt).
    #[arg(long)]
    color: bool,
    /// Nearest depth with a return, metres.
    #[arg(long)]
    min_depth: Option<f32>,
    /// Farthest depth with a return, metres.
    #[arg(long)]
    max_depth: Option<f32>,
    /// Load the intact blocks of a damaged map file (with a warning) instead of stopping.
    #[arg(long)]
    skip_corrupt: bool,
    /// GPU memory for a sparse map's pool, MiB (default: the largest pool the device binds,
    /// 65,536 blocks of 8³ on a 128 MiB binding). A map with more blocks than the pool is
    /// rendered through a window: before each view the pool holds every block that view can
    /// reach, re-filled from host memory when the camera turns or moves away (exact: the same
    /// depth as the whole map on the GPU).
    #[arg(long)]
    map_budget_mib: Option<f64>,
    /// The map's occupancy grid (`export-occupancy`'s G.json or G.bin): also write, per frame,
    /// which pixels looked through never-observed space between the sensor's near range and
    /// their return (or the far range, without one): unknown/*.png, 255 marked, 0 not, listed
    /// in unknown.txt.
    #[arg(long, value_name = "GRID")]
    occupancy: Option<PathBuf>,
    /// Time the renders (submit to readback, one frame at a time, nothing written) and print the
    /// rate instead of writing a directory.
    #[arg(long)]
    bench: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum NoiseKind {
    None,
    Kinect,
}

/// The intrinsics of `--intrinsics` / `--image-size`; with neither, the camera the map was
/// fused from (its creation parameters' `camera`, written by `reconstruct --save-map`), else the
/// nominal Kinect at 640x480.
fn intrinsics(args: &SimulateArgs, map: &MapFileHeader) -> anyhow::Result<(PinholeIntrinsics, &'static str)> {
    if args.intrinsics.is_none() && args.image_size.is_none()
        && let Some(k) = map.fused_camera()
    {
        return Ok((k, "the camera the map was fused from"));
    }
    let what = if args.intrinsics.is_some() { "--intrinsics" } else { "the nominal Kinect" };
    Ok((camera(args.intrinsics.as_deref(), args.image_size.as_deref(), (640, 480))?, what))
}

/// A virtual camera from `--intrinsics fx,fy,cx,cy[,W,H]` and `--image-size WxH`: without
/// intrinsics, the Kinect's nominal 525 px at 640x480 scaled to the size (`default_size` when
/// none is given).
pub(crate) fn camera(intrinsics: Option<&str>, image_size: Option<&str>, default_size: (u32, u32)) -> anyhow::Result<PinholeIntrinsics> {
    let size = image_size.map(crate::calib::parse_image_size).transpose()?;
    let Some(spec) = intrinsics else {
        let (w, h) = size.unwrap_or(default_size);
        return Ok(PinholeIntrinsics::nominal_kinect(w, h));
    };
    let calibration = crate::calib::CalibrationArgs { intrinsics: Some(spec.to_owned()), depth_scale: None, image_size: image_size.map(str::to_owned) }.resolve()?.expect("--intrinsics given");
    Ok(calibration.intrinsics)
}

/// The poses to render at, with their timestamps.
fn poses(args: &SimulateArgs) -> anyhow::Result<Vec<TimedPose>> {
    given_poses(&args.given)?.context("give the poses to render at: --poses FILE (TUM trajectory) or --robot-poses FILE")
}

/// The poses of `--poses` or `--robot-poses` with their timestamps (robot poses without any:
/// 30 Hz from 0), checked non-empty and increasing in time; `None` when neither is given.
pub(crate) fn given_poses(given: &crate::pose_args::PoseFileArgs) -> anyhow::Result<Option<Vec<TimedPose>>> {
    let poses = match (given.tum()?, given.robot()?) {
        (Some(poses), _) => poses,
        (None, Some(robot)) => robot.into_iter().enumerate().map(|(i, p)| TimedPose { timestamp_ns: p.timestamp_ns.unwrap_or(i as i64 * FRAME_PERIOD_NS), world_from_camera: p.world_from_camera }).collect(),
        (None, None) => return Ok(None),
    };
    anyhow::ensure!(!poses.is_empty(), "no poses in {}", given.file().map_or_else(String::new, |f| f.display().to_string()));
    for pair in poses.windows(2) {
        anyhow::ensure!(pair[1].timestamp_ns > pair[0].timestamp_ns, "the poses' timestamps must increase (two frames at {} s)", format_timestamp_s(pair[1].timestamp_ns));
    }
    Ok(Some(poses))
}

fn sensor_options(args: &SimulateArgs) -> anyhow::Result<SensorOptions> {
    kinect_sensor(args.depth_scale, args.radial, (args.noise == NoiseKind::Kinect).then_some(args.seed), (args.min_depth, args.max_depth), args.color)
}

/// A virtual Kinect's options: depth at `units_per_metre` (radial or along z), within
/// `range_m` (each end the Kinect model's where `None`), with the model's seeded noise when
/// `noise_seed` is given, and the map's colour when `color`. `simulate` and `serve --map` share it.
pub(crate) fn kinect_sensor(units_per_metre: f32, radial: bool, noise_seed: Option<u32>, range_m: (Option<f32>, Option<f32>), color: bool) -> anyhow::Result<SensorOptions> {
    let model = KinectModel::default();
    let near = range_m.0.unwrap_or(model.min_depth_m);
    let far = range_m.1.unwrap_or(model.max_depth_m);
    anyhow::ensure!(near.is_finite() && far.is_finite() && near >= 0.0 && far > near, "--min-depth {near} / --max-depth {far}: an empty range");
    let model = KinectModel { min_depth_m: near.max(0.01), ..model };
    Ok(SensorOptions { units_per_metre, radial, noise: noise_seed.map(|seed| (model, seed)), depth_range_m: (near, far), color, hits: false, timed: false })
}

/// A TUM-layout directory being written: depth (and colour) image folders with their lists, the
/// association list, and at the end the poses and the calibration.
struct SimDir {
    dir: PathBuf,
    depth: ImageListWriter,
    rgb: Option<ImageListWriter>,
    assoc: String,
    /// `--occupancy`: the grid, the mask list, and the pixels marked so far.
    unknown: Option<(OccupancyGrid, ImageListWriter, u64)>,
}

impl SimDir {
    fn create(dir: &Path, color: bool, grid: Option<OccupancyGrid>) -> anyhow::Result<Self> {
        anyhow::ensure!(!dir.join("depth.txt").exists(), "{} holds a simulation already (depth.txt): choose an empty directory", dir.display());
        let depth = ImageListWriter::create(dir, "depth", "# simulated depth (webfusion simulate)").with_context(|| format!("creating {}", dir.display()))?;
        let rgb = color.then(|| ImageListWriter::create(dir, "rgb", "# map colour (webfusion simulate)")).transpose().with_context(|| format!("creating {}", dir.display()))?;
        let unknown = grid
            .map(|g| ImageListWriter::create(dir, "unknown", "# pixels whose ray crossed never-observed space before its return: 255 (webfusion simulate --occupancy)").map(|list| (g, list, 0)))
            .transpose()
            .with_context(|| format!("creating {}", dir.display()))?;
        Ok(Self { dir: dir.to_owned(), depth, rgb, assoc: String::new(), unknown })
    }

    fn write(&mut self, k: &PinholeIntrinsics, index: usize, pose: &TimedPose, range_m: (f32, f32), frame: &SimulatedFrame) -> anyhow::Result<()> {
        let t_ns = pose.timestamp_ns;
        let depth = DepthImage::new(k.width_px, k.height_px, frame.depth_units.clone())?;
        let name = self.depth.write(index, t_ns, &webfusion_core::codec::png::encode_depth16(&depth)?)?;
        if let (Some(list), Some(rgb)) = (&mut self.rgb, &frame.color_rgb8) {
            let color = ColorImage::new(k.width_px, k.height_px, rgb.as_flattened().to_vec())?;
            let rgb_name = list.write(index, t_ns, &webfusion_core::codec::png::encode_rgb8(&color)?)?;
            let t = format_timestamp_s(t_ns);
            self.assoc.push_str(&format!("{t} {rgb_name} {t} {name}\n"));
        }
        if let (Some((grid, list, marked)), Some(hit_m)) = (&mut self.unknown, &frame.hit_m) {
            let mask = crate::occupancy::unknown_mask(grid, *k, &pose.world_from_camera, hit_m, range_m)?;
            *marked += mask.iter().filter(|&&m| m == 255).count() as u64;
            list.write(index, t_ns, &webfusion_core::codec::png::encode_gray8(k.width_px, k.height_px, &mask)?)?;
        }
        Ok(())
    }

    fn finish(self, calibration: WrittenCalibration, poses: &[TimedPose]) -> anyhow::Result<()> {
        let write = |name: &str, text: &str| std::fs::write(self.dir.join(name), text).with_context(|| format!("writing {}", self.dir.join(name).display()));
        self.depth.finish()?;
        if let Some((_, list, _)) = self.unknown {
            list.finish()?;
        }
        if let Some(list) = self.rgb {
            list.finish()?;
            write("rgbd_assoc.txt", &self.assoc)?;
        }
        write_tum_trajectory(&self.dir.join("groundtruth.txt"), poses)?;
        write(CALIBRATION_FILE, &format_calibration_file(&calibration))
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

pub(crate) fn run(options: &GpuOptions, args: &SimulateArgs) -> anyhow::Result<()> {
    let poses = poses(args)?;
    let sensor_options = SensorOptions { hits: args.occupancy.is_some(), timed: args.bench, ..sensor_options(args)? };
    anyhow::ensure!(args.bench || args.out.is_some(), "--out DIR is needed (or --bench)");
    let mut file = if args.skip_corrupt { read_map_file_recovering(&args.map) } else { read_map_file(&args.map) }.with_context(|| format!("reading the map {}", args.map.display()))?;
    if let Some(damage) = &file.damage {
        eprintln!("warning: {}: {damage}; rendering the intact blocks", args.map.display());
    }
    let (k, camera_from) = intrinsics(args, &file.header)?;
    println!("camera: {camera_from}, {}x{}, f = ({}, {}) px, c = ({}, {}) px", k.width_px, k.height_px, k.fx_px, k.fy_px, k.cx_px, k.cy_px);
    let gpu = pollster::block_on(Gpu::new(options))?;
    let max_pool = args.map_budget_mib.map(webfusion_core::map::pool_blocks_for_budget_mib).transpose()?;
    let n_blocks = file.blocks.len();
    let mut viewed = ViewedMap::load(&gpu, &file.header, std::mem::take(&mut file.blocks), max_pool).with_context(|| format!("loading {}", args.map.display()))?;
    let windowed = viewed.window().map(|w| format!(", rendered through a window of {} of them", w.capacity())).unwrap_or_default();
    println!("map {}: {n_blocks} blocks of {:.1} mm voxels ({} map, {:.1} MiB on the GPU{windowed}); {} poses, {}x{}, noise {:?}", args.map.display(), file.header.voxel_size_m * 1e3, file.header.kind.name(), viewed.map().memory_bytes() as f64 / 1048576.0, poses.len(), k.width_px, k.height_px, args.noise);
    let mut sensor = VirtualSensor::new(&gpu, viewed.map(), k, sensor_options)?;
    let cone = ViewCone::for_camera(&k, sensor_options.depth_range_m);
    if args.bench {
        // One warm-up render, then each pose alone: (a new window where one is needed,) submit,
        // wait, read back.
        viewed.prepare(&gpu, &poses[0].world_from_camera, &cone)?;
        pollster::block_on(sensor.render(&gpu, viewed.map(), &poses[0].world_from_camera, 0))?;
        let mut ms = Vec::with_capacity(poses.len());
        let mut window_ms = Vec::new();
        let mut gpu_stages = StageTimes::default();
        let started = std::time::Instant::now();
        for (i, p) in poses.iter().enumerate() {
            let t = std::time::Instant::now();
            if viewed.prepare(&gpu, &p.world_from_camera, &cone)? {
                window_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
            let frame = pollster::block_on(sensor.render(&gpu, viewed.map(), &p.world_from_camera, i as u32))?;
            ms.push(t.elapsed().as_secs_f64() * 1e3);
            for stage in frame.stages {
                gpu_stages.record(stage.name, stage.gpu_ms);
            }
        }
        let total_s = started.elapsed().as_secs_f64();
        let mut sorted = ms.clone();
        sorted.sort_by(f64::total_cmp);
        println!("simulated {} frames in {total_s:.2} s: {:.1} frames/s; per frame median {:.1} ms, p95 {:.1} ms (render + readback, noise {:?})", poses.len(), poses.len() as f64 / total_s, percentile(&sorted, 0.5), percentile(&sorted, 0.95), args.noise);
        if gpu_stages.is_empty() {
            println!("(no GPU stage times: the device has no timestamp queries)");
        } else {
            println!("GPU time per stage:");
            gpu_stages.print();
        }
        if viewed.window().is_some() {
            window_ms.sort_by(f64::total_cmp);
            println!("windows: {} uploaded for {} frames (median {:.0} ms each, in the frame times above)", window_ms.len(), poses.len(), if window_ms.is_empty() { 0.0 } else { percentile(&window_ms, 0.5) });
        }
        return Ok(());
    }
    let out = args.out.as_ref().expect("checked");
    let grid = args.occupancy.as_deref().map(|path| crate::occupancy::read_grid_for_map(path, file.header.frame, &args.map)).transpose()?;
    let mut dir = SimDir::create(out, args.color, grid)?;
    let started = std::time::Instant::now();
    let mut returns = 0u64;
    let mut write = |frame: SimulatedFrame, dir: &mut SimDir| -> anyhow::Result<()> {
        returns += frame.depth_units.iter().filter(|&&u| u > 0).count() as u64;
        dir.write(&k, frame.tag as usize, &poses[frame.tag as usize], sensor_options.depth_range_m, &frame)
    };
    for (i, p) in poses.iter().enumerate() {
        while !sensor.can_submit() {
            let frame = pollster::block_on(sensor.wait(&gpu))?.context("a frame in flight")?;
            write(frame, &mut dir)?;
        }
        // A new window waits for nothing: uploads are ordered after the frames in flight.
        viewed.prepare(&gpu, &p.world_from_camera, &cone)?;
        sensor.submit(&gpu, viewed.map(), &p.world_from_camera, i as u32, i as u64)?;
        for frame in sensor.collect(&gpu)? {
            write(frame, &mut dir)?;
        }
    }
    while let Some(frame) = pollster::block_on(sensor.wait(&gpu))? {
        write(frame, &mut dir)?;
    }
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "the GPU reported errors: {}", errors.join("; "));
    // The calibration file says which noise the depth has, so `reconstruct` weights it right.
    let depth_noise = match args.noise {
        NoiseKind::None => DepthNoise::None,
        NoiseKind::Kinect => DepthNoise::KinectV1,
    };
    let calibration = WrittenCalibration { calibration: RgbdCalibration { intrinsics: k, depth_units_per_metre: args.depth_scale }, radial_depth: args.radial, depth_noise };
    let marked = dir.unknown.as_ref().map(|(_, _, marked)| *marked);
    dir.finish(calibration, &poses)?;
    let elapsed = started.elapsed().as_secs_f64();
    if let Some(w) = viewed.window() {
        println!("windows: {} uploaded for {} frames (a pool of {} of the map's {} blocks; {} blocks written, each window writing only the blocks entering it)", w.uploads(), poses.len(), w.capacity(), w.blocks(), w.blocks_written());
    }
    if let Some(marked) = marked {
        println!("{:.2} % of the pixels looked through never-observed space (unknown/)", 100.0 * marked as f64 / (poses.len() as f64 * k.pixel_count() as f64));
    }
    println!(
        "{}: {} frames in {elapsed:.1} s ({:.1} frames/s with PNG writing); {:.1} % of the pixels have a return",
        out.display(),
        poses.len(),
        poses.len() as f64 / elapsed,
        100.0 * returns as f64 / (poses.len() as f64 * k.pixel_count() as f64)
    );
    Ok(())
}
