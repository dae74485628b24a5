// SPDX-License-Identifier: MIT
//! `webfusion reconstruct`: KinectFusion over a log, headless. Writes the trajectory (TUM
//! format), the mesh (binary PLY) and per-stage statistics.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use webfusion_core::fusion::{FrameReport, FusionConfig, KinectFusion, TrackingState};
use webfusion_core::io::trajectory::{MAX_POSE_GAP_NS, TimedPose, write_tum_trajectory};
use webfusion_core::tsdf::{DEFAULT_TRUNCATION_VOXELS, TsdfConfig, TsdfStore as _, VolumePlacement};
use webfusion_core::fusion::mapper::Mapper;
use webfusion_core::map::{MapKind, MapStats};
use webfusion_core::map::file::{MapFile, MapFileHeader, MapFrame, mean_camera_up, read_map_file, read_map_file_recovering, write_map_file};
use webfusion_core::odometry::assist::{FeatureAssist, Guess};
use webfusion_core::odometry::tracker::OdometryConfig;
use webfusion_core::source::DepthNoise;
use webfusion_core::{GpuOptions, Se3};

use crate::calib::CalibrationArgs;
use crate::pose_args::GivenPoses;
use crate::timing::StageTimes;

#[derive(clap::Args)]
pub(crate) struct ReconstructArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Output directory (created): trajectory.txt, mesh.ply, mesh.glb, stats.json, and the
    /// source's ground truth as groundtruth.txt when it has one (a recording carries it
    /// inside; `--poses OUT/groundtruth.txt` then fuses at it).
    #[arg(long)]
    out: PathBuf,
    /// Frames to process, `A..B` (end exclusive); default all.
    #[arg(long)]
    frames: Option<String>,
    /// Voxel edge length, metres (default: 3 m / voxels per axis).
    #[arg(long)]
    voxel_size: Option<f32>,
    /// Voxels per axis of the cubic volume (`--map-kind dense`).
    #[arg(long, default_value_t = webfusion_core::tsdf::DEFAULT_VOLUME_DIM_VOXELS)]
    volume: u32,
    /// The map: `sparse` (voxel blocks allocated wherever surfaces are seen, centred on the
    /// first camera, swapped to host memory when the pool fills) or `dense` (a cube of
    /// `--volume`³ voxels placed by the first camera).
    #[arg(long, default_value = "sparse")]
    map_kind: webfusion_core::map::MapKind,
    /// Do not swap a sparse map's blocks to host memory: a full pool refuses new blocks.
    #[arg(long)]
    no_swap: bool,
    /// GPU memory for a sparse map's voxel pool and colour, MiB (default: 65536 blocks of 8³,
    /// 261 MiB, the largest pool every device holds; more where the device's storage bindings
    /// allow, up to 524,288 blocks, 2088 MiB: `webfusion info` prints the binding; the browser's
    /// default is 32768 blocks, 130 MiB).
    #[arg(long)]
    map_budget_mib: Option<u64>,
    /// Put the first camera at a dense cube's centre instead of in front of it (for a camera
    /// that turns in place; a sparse map is always centred on it).
    #[arg(long)]
    centred: bool,
    /// Truncation distance μ, metres (default: 4 voxels).
    #[arg(long)]
    truncation: Option<f32>,
    /// Where the Kinect noise model's σ_z(z) says a depth sample is noisier than μ, widen its
    /// truncation band to this many σ (at most 16 voxels); without it the fused surface drifts
    /// behind far measurements (13 mm at 5 m with μ = 4.7 cm). 0: μ at every depth (a sensor far
    /// less noisy than a Kinect v1, or maps as fused before). Default 3, or 0 for a source that
    /// says its depth is exact (a simulated log without noise).
    #[arg(long)]
    noise_band_sigmas: Option<f32>,
    /// ICP iterations per pyramid level, finest first.
    #[arg(long, value_delimiter = ',', default_values_t = webfusion_core::fusion::DEFAULT_ICP_ITERATIONS)]
    icp_iterations: Vec<u32>,
    /// Largest ICP correspondence distance, metres.
    #[arg(long, default_value_t = webfusion_core::fusion::DEFAULT_ICP_DIST_THRESH_M)]
    icp_dist: f32,
    /// Largest ICP normal angle, degrees.
    #[arg(long, default_value_t = 20.0)]
    icp_angle_deg: f32,
    /// Huber threshold on ICP residuals, metres (0: off).
    #[arg(long, default_value_t = webfusion_core::fusion::DEFAULT_HUBER_DELTA_M)]
    huber: f32,
    /// Do not weight ICP pairs by the Kinect noise model.
    #[arg(long)]
    no_noise_weighting: bool,
    /// Weight of the photometric term (0: depth-only ICP).
    #[arg(long, default_value_t = webfusion_core::fusion::DEFAULT_RGB_WEIGHT)]
    rgb_weight: f32,
    /// ICP convergence: a level stops once an update moves no point within 3 m by more than
    /// this at full resolution, metres (2^l times this at level l).
    #[arg(long, default_value_t = webfusion_core::fusion::DEFAULT_CONVERGED_UPDATE_M)]
    icp_converged: f32,
    /// Initialise each frame with a constant-velocity motion model.
    #[arg(long)]
    constant_velocity: bool,
    /// Do not fuse colour.
    #[arg(long)]
    no_color: bool,
    /// Skip mesh extraction.
    #[arg(long)]
    no_mesh: bool,
    /// Skip damaged frames of a recording (listed in stats.json) instead of stopping at the
    /// first.
    #[arg(long)]
    skip_corrupt: bool,
    #[command(flatten)]
    given: crate::pose_args::PoseFileArgs,
    /// With `--poses`: use them only as each frame's initial guess for tracking, and report how
    /// far tracking moved each one (`refine.txt`, stats.json).
    #[arg(long)]
    refine: bool,
    /// Turn off seed 002's feature odometry beside ICP. By default each frame's features,
    /// matched against the last tracked frame, give ICP its initial guess, and after a loss
    /// the frame is relocalised against stored keyframes and ICP verifies it
    /// (`core::odometry::assist`; one host wait per frame: frames are processed one at a time).
    /// Off by itself with given poses (they are the guess) and for images too small for
    /// keypoints.
    #[arg(long)]
    no_features: bool,
    /// Keep only every N-th frame of the range (fast motion as a slower camera would see it).
    #[arg(long, default_value_t = 1)]
    every: usize,
    /// Leave out the frames `A..B` of the source (a gap in the stream).
    #[arg(long)]
    drop: Option<String>,
    /// Save the fused map (`.wfm`: every block, on the GPU and swapped out, in the map's frame,
    /// with a CRC per block; see ARCHITECTURE.md).
    #[arg(long)]
    save_map: Option<PathBuf>,
    /// Continue fusing into a saved map, at `--poses` (its own settings replace --map-kind,
    /// --voxel-size, --volume, --truncation and --noise-band-sigmas). A damaged map file is an error unless
    /// --skip-corrupt (then its intact blocks are loaded, with a warning).
    #[arg(long)]
    load_map: Option<PathBuf>,
    /// Farthest depth fused and tracked, metres (default 5: beyond it a Kinect's noise, σ > 4 cm,
    /// blurs more than it adds; a map for simulating a whole room may want the sensor's full
    /// range).
    #[arg(long)]
    max_depth: Option<f32>,
    #[command(flatten)]
    calibration: CalibrationArgs,
}

impl ReconstructArgs {
    fn config(&self) -> anyhow::Result<FusionConfig> {
        let mut config = FusionConfig::default();
        let voxel = self.voxel_size.unwrap_or(webfusion_core::tsdf::DEFAULT_VOLUME_SIZE_M / self.volume as f32);
        config.tsdf = TsdfConfig { truncation_m: self.truncation.unwrap_or(DEFAULT_TRUNCATION_VOXELS * voxel), noise_band_sigmas: self.noise_band_sigmas.unwrap_or(webfusion_core::tsdf::DEFAULT_NOISE_BAND_SIGMAS), color: !self.no_color, placement: if self.centred { VolumePlacement::Centred } else { VolumePlacement::InFront }, kind: self.map_kind, pool_blocks: self.map_budget_mib.map_or(webfusion_core::map::NATIVE_POOL_BLOCKS, |mib| webfusion_core::map::pool_blocks_for_budget(mib.saturating_mul(1 << 20), webfusion_core::map::max_pool_blocks(u64::MAX))), swap: !self.no_swap, ..TsdfConfig::cube(self.volume, voxel) };
        config.icp.iterations_per_level = self.icp_iterations.clone();
        config.icp.dist_thresh_m = self.icp_dist;
        config.icp.angle_thresh_rad = self.icp_angle_deg.to_radians();
        config.icp.constant_velocity = self.constant_velocity;
        config.icp.huber_delta_m = self.huber;
        config.icp.rgb_weight = self.rgb_weight;
        config.icp.noise_weighting = !self.no_noise_weighting;
        config.icp.converged_update_m = self.icp_converged;
        if let Some(m) = self.max_depth {
            anyhow::ensure!(m.is_finite() && m > config.preprocess.min_depth_m, "--max-depth {m}: beyond the nearest depth {} m", config.preprocess.min_depth_m);
            config.preprocess.max_depth_m = m;
        }
        config.validate()?;
        Ok(config)
    }
}

impl ReconstructArgs {
    /// The file of `--poses` or `--robot-poses`.
    fn pose_file(&self) -> Option<&PathBuf> {
        self.given.file()
    }
}

/// The given poses of `--poses` or `--robot-poses`, read and checked.
fn given_poses(args: &ReconstructArgs) -> anyhow::Result<Option<GivenPoses>> {
    anyhow::ensure!(args.pose_file().is_some() || !(args.refine || args.load_map.is_some()), "--refine and --load-map need --poses or --robot-poses (relocalising into a map needs feature odometry, not built yet)");
    args.given.read()
}

/// `--load-map`'s file, read (strictly, or keeping its intact blocks with --skip-corrupt).
fn loaded_map(args: &ReconstructArgs) -> anyhow::Result<Option<MapFile>> {
    let Some(path) = &args.load_map else { return Ok(None) };
    let file = if args.skip_corrupt { read_map_file_recovering(path)? } else { read_map_file(path)? };
    if let Some(damage) = &file.damage {
        eprintln!("warning: {}: {damage}; loading its {} intact blocks", path.display(), file.blocks.len());
    }
    println!("loaded map {}: {} blocks, {} map of {:.1} mm voxels", path.display(), file.blocks.len(), file.header.kind.name(), file.header.voxel_size_m * 1e3);
    Ok(Some(file))
}

/// A loaded map's up direction, weighted as the frames it was made from (as its creation
/// parameters say; 1 if they do not).
fn up_of(file: &MapFile) -> Option<([f32; 3], usize)> {
    let made_from = serde_json::from_str::<serde_json::Value>(&file.header.creation).ok().and_then(|c| c["fused_frames"].as_u64()).unwrap_or(1);
    file.header.up_in_map.map(|up| (up, made_from as usize))
}

/// The map settings of a loaded map, in place of the command line's.
fn apply_map_settings(config: &mut FusionConfig, header: &MapFileHeader) -> anyhow::Result<()> {
    let t = &mut config.tsdf;
    t.kind = header.kind;
    t.voxel_size_m = header.voxel_size_m;
    t.truncation_m = header.truncation_m;
    t.noise_band_sigmas = header.noise_band_sigmas;
    t.max_weight = header.max_weight;
    t.color = header.color;
    if header.kind == MapKind::Dense {
        t.dims_voxels = header.dims_voxels;
    }
    config.validate()?;
    Ok(())
}

/// What the source says of its depth's noise settles what the flags leave open
/// ([`FusionConfig::for_depth_noise`]): exact depth is tracked with unweighted residuals and
/// fused with a band of μ, unless `--noise-band-sigmas` is given or a loaded map brings its own
/// band.
fn apply_depth_noise(config: &mut FusionConfig, args: &ReconstructArgs, noise: DepthNoise, loaded_map: bool) {
    *config = config.clone().for_depth_noise(noise, args.noise_band_sigmas.is_some() || loaded_map);
    if noise == DepthNoise::None {
        println!("depth noise: none (the source's calibration file): residuals not weighted by depth, truncation band {} σ", config.tsdf.noise_band_sigmas);
    }
}

/// `--save-map`: every block of the mapper's map, with its settings and how it was made.
/// `loaded_up`: a loaded map's up direction and how many frames it was made from.
fn save_map(gpu: &webfusion_core::Gpu, mapper: &mut Mapper, config: &FusionConfig, args: &ReconstructArgs, source: &dyn webfusion_core::source::FrameSource, trajectory: &[TimedPose], loaded_up: Option<([f32; 3], usize)>) -> anyhow::Result<()> {
    let Some(path) = &args.save_map else { return Ok(()) };
    let fused_frames = trajectory.len();
    let blocks = pollster::block_on(mapper.download_blocks(gpu)).context("downloading the map")?;
    let t = &config.tsdf;
    let c = source.calibration();
    let k = &c.intrinsics;
    let creation = serde_json::json!({
        "webfusion": env!("CARGO_PKG_VERSION"),
        "source": source.name(),
        // The camera it was fused from: `simulate` renders with it unless told otherwise.
        "camera": { "fx_px": k.fx_px, "fy_px": k.fy_px, "cx_px": k.cx_px, "cy_px": k.cy_px, "width_px": k.width_px, "height_px": k.height_px, "depth_units_per_metre": c.depth_units_per_metre },
        "fused_frames": fused_frames,
        "poses": args.pose_file().map(|p| p.display().to_string()),
        "refine": args.refine,
        "loaded_from": args.load_map.as_ref().map(|p| p.display().to_string()),
    });
    let frame = if args.pose_file().is_some() { MapFrame::GivenPoses } else { MapFrame::FirstCamera };
    let header = MapFileHeader::for_map(t, mapper.origin_in_world(), frame, mean_camera_up(trajectory.iter().map(|p| &p.world_from_camera), loaded_up), creation.to_string());
    write_map_file(path, &header, &blocks).with_context(|| format!("saving the map to {}", path.display()))?;
    println!("map: {} blocks -> {} ({:.1} MiB)", blocks.len(), path.display(), std::fs::metadata(path).map_or(0, |m| m.len()) as f64 / 1048576.0);
    if t.kind == MapKind::Sparse {
        let sizes = webfusion_core::map::BlockSizeComparison::of(&blocks);
        let (f8, f16) = sizes.observed_fractions();
        println!("block size: {} blocks of 8³ hold the band; blocks of 16³ would be {} ({:.2}x the voxels); observed voxels {:.0} % of those allocated at 8³, {:.0} % at 16³", sizes.blocks_8, sizes.blocks_16, sizes.voxel_ratio(), 100.0 * f8, 100.0 * f16);
    }
    Ok(())
}

pub(crate) fn run(options: &GpuOptions, args: &ReconstructArgs) -> anyhow::Result<()> {
    let mut config = args.config()?;
    let given = given_poses(args)?;
    let loaded = loaded_map(args)?;
    if let Some(file) = &loaded {
        apply_map_settings(&mut config, &file.header)?;
    }
    let mut source = crate::open(&args.source, &args.calibration)?;
    apply_depth_noise(&mut config, args, source.depth_noise(), loaded.is_some());
    let range = crate::frame_range(args.frames.as_deref(), source.frame_count())?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating output directory {}", args.out.display()))?;
    let gpu = crate::gpu(options)?;
    if let (Some(given), false) = (&given, args.refine) {
        return run_pose_driven(&gpu, args, &config, source.as_mut(), range, given, loaded);
    }
    let loaded_up = loaded.as_ref().and_then(up_of);
    let mut fusion = match loaded {
        Some(file) => {
            let mut fusion = KinectFusion::new_at(&gpu, source.calibration(), config.clone(), file.header.origin_in_world)?;
            let near = given.as_ref().and_then(GivenPoses::first);
            fusion.mapper_mut().upload_blocks(&gpu, file.blocks, near.as_ref())?;
            fusion
        }
        None => KinectFusion::new(&gpu, source.calibration(), config.clone())?,
    };
    // --refine: how far tracking moved each frame's given pose (kept with its timestamp).
    let mut refined: Vec<(u64, f64, f64)> = Vec::new();
    let mut without_pose = Vec::new();
    let mut times = StageTimes::default();
    let mut trajectory = Vec::with_capacity(range.len());
    let mut lost = Vec::new();
    let start = range.start;
    let frames = crate::selected_frames(range, args.every, args.drop.as_deref())?;
    let n_frames = frames.len();
    let mut timestamps = std::collections::HashMap::new();
    let mut iterations = [0u64; 4];
    // The finest level's condition number (of the scaled system) per tracked frame: not a time.
    let mut conditions = Vec::new();
    let mut tracked_frames = 0u64;
    let mut host = webfusion_core::GpuCounts::default();
    // A sparse map's counters, as the last report carried them.
    let mut map_stats = None;
    let mut last_done: Option<std::time::Instant> = None;
    let started = std::time::Instant::now();
    // Frames stream through the GPU: the next frame is read and submitted while the GPU still
    // works on the previous one, and each report arrives a frame or so late.
    let (mut assist, features_off) = feature_assist(args, &gpu, &fusion, given.is_some())?;
    let features_on = assist.is_some();
    let feature_stage_names = webfusion_core::fusion::FEATURE_STAGES.map(|stage| format!("gpu features: {stage}"));
    let mut on_report = |report: FrameReport, times: &mut StageTimes, trajectory: &mut Vec<TimedPose>, timestamps: &mut std::collections::HashMap<u64, (i64, Option<Se3>)>| {
        let now = std::time::Instant::now();
        if let Some(prev) = last_done.replace(now) {
            times.record("frame", (now - prev).as_secs_f64() * 1e3);
        }
        if let Some(g) = report.gpu_ms {
            times.record("gpu preprocess", g.preprocess);
            if features_on {
                times.record("gpu features", g.features.iter().sum());
                for (stage, ms) in feature_stage_names.iter().zip(g.features) {
                    times.record(stage, ms);
                }
            }
            if report.state != TrackingState::Initialised {
                times.record("gpu track", g.track);
            }
            times.record("gpu integrate", g.integrate);
            times.record("gpu raycast", g.raycast);
            times.record("gpu frame", g.total);
        }
        times.record("encode + submit", report.encode_ms);
        for s in &report.icp {
            iterations[s.level] += u64::from(s.iterations);
            if s.level == 0 && s.condition < 1e29 {
                conditions.push(s.condition);
            }
        }
        if !report.icp.is_empty() {
            tracked_frames += 1;
        }
        host.submits += report.host.submits;
        host.host_waits += report.host.host_waits;
        host.readbacks += report.host.readbacks;
        map_stats = report.map.or(map_stats);
        if let TrackingState::Lost(reason) = report.state {
            eprintln!("\nframe {}: tracking lost ({reason:?}); keeping the last good pose", report.index);
            lost.push(report.index);
        }
        let (timestamp_ns, guess) = timestamps.remove(&report.index).unwrap_or_default();
        if let Some(guess) = guess {
            let moved = guess.inverse() * report.world_from_camera;
            refined.push((report.index, moved.translation_m.length(), moved.rotation_angle_rad().to_degrees()));
        }
        trajectory.push(TimedPose { timestamp_ns, world_from_camera: report.world_from_camera });
        let inliers = report.icp.last().map_or(0, |s| s.inliers);
        eprint!("\rframe {}/{} [{}], ICP inliers {inliers}   ", trajectory.len(), n_frames, report.state.name());
    };
    let mut skipped = Vec::new();
    for index in frames {
        let sw = crate::timing::Stopwatch::start();
        let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        times.record("read", sw.ms());
        let mut guess: Option<Se3> = None;
        if let Some(given) = &given {
            let Some(pose) = given.pose_for(index - start, frame.depth_timestamp_ns) else {
                without_pose.push(index);
                continue;
            };
            fusion.set_initial_guess(&gpu, &pose);
            guess = Some(pose);
        }
        timestamps.insert(frame.index, (frame.depth_timestamp_ns, guess));
        if let Some(assist) = &mut assist {
            // Features and tracking in one submission; the frame's outcome is needed before the
            // next one's features.
            let assisted = pollster::block_on(assist.process_frame(&gpu, &mut fusion, &frame)).with_context(|| format!("processing frame {index}"))?;
            if let Some(Guess::Relocalised { keyframe, inliers, .. }) = assisted.guess {
                eprintln!("\nframe {index}: relocalised against frame {keyframe} ({inliers} feature inliers); ICP: {}", assisted.report.state.name());
            }
            on_report(FrameReport { host: assisted.host, ..assisted.report }, &mut times, &mut trajectory, &mut timestamps);
            continue;
        }
        pollster::block_on(fusion.submit_frame(&gpu, &frame)).with_context(|| format!("processing frame {index}"))?;
        for report in fusion.poll_reports(&gpu)? {
            on_report(report, &mut times, &mut trajectory, &mut timestamps);
        }
    }
    for report in pollster::block_on(fusion.flush(&gpu))? {
        on_report(report, &mut times, &mut trajectory, &mut timestamps);
    }
    let wall_s = started.elapsed().as_secs_f64();
    eprintln!();
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));

    if let Some(stats) = &map_stats {
        print_map_stats(stats, fusion.volume().memory_bytes());
    }
    let trajectory_path = args.out.join("trajectory.txt");
    write_tum_trajectory(&trajectory_path, &trajectory).with_context(|| format!("writing {}", trajectory_path.display()))?;
    write_ground_truth(args, &*source)?;
    let given_json = given.as_ref().map(|_| given_report(args, &without_pose, Some(&refined))).transpose()?;
    save_map(&gpu, fusion.mapper_mut(), &config, args, &*source, &trajectory, loaded_up)?;
    if !args.no_mesh {
        let sw = crate::timing::Stopwatch::start();
        let mesh = pollster::block_on(fusion.mapper_mut().extract_mesh(&gpu)).context("extracting the mesh")?;
        times.record("mesh extraction", sw.ms());
        write_mesh(&mesh, &args.out.join("mesh.ply"))?;
    }
    println!(
        "{n_frames} frames of {} on {}; {} lost; {:.2} frames/s over {:.1} s{}",
        source.name(),
        gpu.adapter_summary(),
        lost.len(),
        n_frames as f64 / wall_s,
        wall_s,
        crate::skipped_note(&skipped)
    );
    if fusion.timer_available() {
        println!("stage times: \"gpu …\" from GPU timestamps; \"frame\" is the wall-clock interval between consecutive frames (reading and decoding overlapped)");
    } else {
        println!("the adapter has no timestamp queries: only wall-clock times");
    }
    times.print();
    let per_frame = |n: u64| if n_frames == 0 { 0.0 } else { n as f64 / n_frames as f64 };
    let mean_iterations: Vec<f64> = iterations.iter().map(|&n| if tracked_frames == 0 { 0.0 } else { n as f64 / tracked_frames as f64 }).collect();
    println!(
        "host per frame: {:.2} submissions, {:.2} waits, {:.2} readbacks; ICP iterations per tracked frame (level 0, 1, 2): {:.2}, {:.2}, {:.2}",
        per_frame(host.submits),
        per_frame(host.host_waits),
        per_frame(host.readbacks),
        mean_iterations[0],
        mean_iterations[1],
        mean_iterations[2]
    );
    let condition = (!conditions.is_empty()).then(|| crate::timing::summarize(&conditions));
    if let Some(c) = &condition {
        println!("finest-level condition number of the scaled ICP system: median {:.0}, p95 {:.0}, max {:.0}", c.median_ms, c.p95_ms, c.max_ms);
    }
    // Sources with ground truth (TUM directories, recordings that carry it) are scored at once.
    let ate = source.ground_truth().and_then(|gt| match webfusion_core::eval::ate(gt, &trajectory, &Default::default()) {
        Ok(report) => {
            let e = &report.error_m;
            println!("ATE against the source's ground truth ({} pairs): RMSE {:.2} cm, mean {:.2} cm, max {:.2} cm", e.count, e.rmse * 100.0, e.mean * 100.0, e.max * 100.0);
            Some(serde_json::json!({ "pairs": e.count, "rmse_m": e.rmse, "mean_m": e.mean, "median_m": e.median, "max_m": e.max }))
        }
        Err(error) => {
            eprintln!("ATE not computed: {error}");
            None
        }
    });
    let stats = serde_json::json!({
        "ate": ate,
        "frames": n_frames,
        "lost_frames": lost,
        "skipped_corrupt_frames": skipped,
        "adapter": gpu.adapter_summary(),
        "gpu_timestamps": fusion.timer_available(),
        "icp_noise_weighting": fusion.config().icp.noise_weighting,
        "wall_s": wall_s,
        "frames_per_s": n_frames as f64 / wall_s,
        "host_per_frame": { "submits": per_frame(host.submits), "waits": per_frame(host.host_waits), "readbacks": per_frame(host.readbacks) },
        "icp_iterations_per_frame": mean_iterations,
        "finest_condition_number": condition.map(|c| serde_json::json!({ "median": c.median_ms, "p95": c.p95_ms, "min": c.min_ms, "max": c.max_ms, "n": conditions.len() })),
        "volume": {
            "kind": fusion.config().tsdf.kind.name(),
            "dims_voxels": fusion.config().tsdf.box_dims_voxels(),
            "voxel_size_m": fusion.config().tsdf.voxel_size_m,
            "truncation_m": fusion.config().tsdf.truncation_m,
            "noise_band_sigmas": fusion.config().tsdf.noise_band_sigmas,
            "memory_bytes": fusion.volume().memory_bytes(),
            "sparse": map_stats.as_ref().map(map_stats_json),
        },
        "stages_ms": times.to_json(),
        "given_poses": given_json,
        "features": match &assist {
            Some(a) => {
                let s = a.stats();
                let ms = a.frame_ms();
                serde_json::json!({
                    "guesses": s.guesses,
                    "relocalisations": s.relocalisations,
                    "relocalisations_confirmed": s.relocalisations_confirmed,
                    "recoveries": s.recoveries,
                    "keyframes_added": s.keyframes_added,
                    "withheld": s.withheld,
                    "keyframes": a.keyframes(),
                    "ms_median": if ms.is_empty() { 0.0 } else { crate::timing::summarize(ms).median_ms },
                })
            }
            None => serde_json::json!({ "off": features_off }),
        },
        "every": args.every,
        "dropped": args.drop,
    });
    let stats_path = args.out.join("stats.json");
    std::fs::write(&stats_path, serde_json::to_string_pretty(&stats)?).with_context(|| format!("writing {}", stats_path.display()))?;
    println!("wrote {}, {}", trajectory_path.display(), stats_path.display());
    Ok(())
}

/// Writes the mesh (of every block: a swapping map's on the host too) as binary PLY and glTF
/// binary (`.glb` beside).
fn write_mesh(mesh: &webfusion_core::mesh::Mesh, path: &Path) -> anyhow::Result<()> {
    let write = |path: &Path, glb: bool| -> anyhow::Result<()> {
        let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut out = std::io::BufWriter::new(file);
        if glb { webfusion_core::mesh::write_glb(mesh, &mut out) } else { webfusion_core::mesh::write_ply(mesh, &mut out) }
            .and_then(|()| std::io::Write::flush(&mut out))
            .with_context(|| format!("writing {}", path.display()))
    };
    write(path, false)?;
    write(&path.with_extension("glb"), true)?;
    println!("mesh: {} vertices, {} triangles -> {} (+ .glb)", mesh.positions_m.len(), mesh.triangles.len(), path.display());
    Ok(())
}

/// Prints a sparse map's use (GPU and host) and warns when it ran out of room.
fn print_map_stats(stats: &MapStats, memory_bytes: u64) {
    let used_mib = (u64::from(stats.blocks_used) * webfusion_core::map::BLOCK_BYTES_WITH_COLOR) as f64 / 1048576.0;
    println!("sparse map: {} of {} blocks used ({used_mib:.1} MiB of {:.1} MiB)", stats.blocks_used, stats.pool_blocks, memory_bytes as f64 / 1048576.0);
    if stats.swapped_out_total > 0 {
        println!("swapping: {} blocks on the host ({:.1} MiB of host memory); {} swapped out, {} swapped in; {} band samples met a block still on the host; margins shrank {} times under pressure (now {} %)", stats.blocks_on_host, stats.host_bytes as f64 / 1048576.0, stats.swapped_out_total, stats.swapped_in_total, stats.swapped_hits, stats.swap_margin_shrinks, stats.swap_margin_percent);
    }
    if stats.exhausted() {
        eprintln!("warning: the map ran out of room ({} insertions without a hash slot, {} blocks refused by the full pool): surfaces there were not fused; raise --map-budget-mib or the voxel size", stats.hash_full, stats.pool_full);
    }
}

/// A sparse map's part of stats.json.
fn map_stats_json(m: &MapStats) -> serde_json::Value {
    serde_json::json!({ "blocks_used": m.blocks_used, "pool_blocks": m.pool_blocks, "used_bytes": u64::from(m.blocks_used) * webfusion_core::map::BLOCK_BYTES_WITH_COLOR, "hash_full": m.hash_full, "pool_full": m.pool_full, "out_of_range": m.out_of_range, "blocks_on_host": m.blocks_on_host, "host_bytes": m.host_bytes, "swapped_out_total": m.swapped_out_total, "swapped_in_total": m.swapped_in_total, "swapped_hits": m.swapped_hits, "swap_in_refused": m.swap_in_refused, "swap_margin_shrinks": m.swap_margin_shrinks, "swap_margin_percent": m.swap_margin_percent })
}

/// `--poses`' part of stats.json: the file, the frames without a pose and, with `--refine`, how
/// far tracking moved the given poses (also written to `refine.txt` and summarised on stdout).
fn given_report(args: &ReconstructArgs, without_pose: &[usize], refined: Option<&[(u64, f64, f64)]>) -> anyhow::Result<serde_json::Value> {
    if !without_pose.is_empty() {
        println!("{} frames had no given pose (within {} ms, or past the end of a per-frame list) and were skipped", without_pose.len(), MAX_POSE_GAP_NS / 1_000_000);
    }
    let refine = match refined {
        Some(refined) if !refined.is_empty() => {
            let path = args.out.join("refine.txt");
            let mut text = String::from("# frame moved_m moved_deg: how far tracking moved each given pose\n");
            for (index, m, deg) in refined {
                text += &format!("{index} {m:.6} {deg:.5}\n");
            }
            std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
            let stat = |values: Vec<f64>| {
                let mut v = values;
                v.sort_by(f64::total_cmp);
                (v[v.len() / 2], v[v.len() - 1])
            };
            let (median_m, max_m) = stat(refined.iter().map(|r| r.1).collect());
            let (median_deg, max_deg) = stat(refined.iter().map(|r| r.2).collect());
            println!("refine: tracking moved the given poses by {:.1} mm / {:.2}° (median), {:.1} mm / {:.2}° (max) -> {}", median_m * 1e3, median_deg, max_m * 1e3, max_deg, path.display());
            serde_json::json!({ "frames": refined.len(), "median_moved_m": median_m, "max_moved_m": max_m, "median_moved_deg": median_deg, "max_moved_deg": max_deg })
        }
        _ => serde_json::Value::Null,
    };
    Ok(serde_json::json!({ "file": args.pose_file().map(|p| p.display().to_string()), "robot_pose_form": args.given.robot_poses.as_ref().map(|_| format!("{:?}", args.given.robot_pose_form)), "frames_without_pose": without_pose, "refine": refine }))
}

/// `reconstruct --poses` without `--refine`: fuses every frame at its given pose (no tracking),
/// then writes the poses used, the mesh and the statistics as the tracked run does.
fn run_pose_driven(gpu: &webfusion_core::Gpu, args: &ReconstructArgs, config: &FusionConfig, source: &mut dyn webfusion_core::source::FrameSource, range: std::ops::Range<usize>, given: &GivenPoses, mut loaded: Option<MapFile>) -> anyhow::Result<()> {
    let loaded_up = loaded.as_ref().and_then(up_of);
    use webfusion_core::fusion::pose_driven::PoseDrivenMapper;
    let n_frames = range.len();
    let mut times = StageTimes::default();
    let mut trajectory = Vec::with_capacity(n_frames);
    let (mut without_pose, mut skipped) = (Vec::new(), Vec::new());
    let mut mapper: Option<PoseDrivenMapper> = None;
    let started = std::time::Instant::now();
    let mut last = started;
    let start = range.start;
    for index in range {
        let sw = crate::timing::Stopwatch::start();
        let Some(frame) = crate::read_or_skip(source, index, args.skip_corrupt, &mut skipped)? else { continue };
        times.record("read", sw.ms());
        let Some(pose) = given.pose_for(index - start, frame.depth_timestamp_ns) else {
            without_pose.push(index);
            continue;
        };
        // The map is placed around the first fused frame's camera, in the poses' frame (a
        // loaded map where it was).
        let m = match &mut mapper {
            Some(m) => m,
            None => match loaded.take() {
                Some(file) => {
                    let mut m = PoseDrivenMapper::new_at(gpu, source.calibration(), config.preprocess, config.tsdf, file.header.origin_in_world, false)?;
                    m.mapper_mut().upload_blocks(gpu, file.blocks, Some(&pose))?;
                    mapper.insert(m)
                }
                None => mapper.insert(PoseDrivenMapper::new(gpu, source.calibration(), config.preprocess, config.tsdf, &pose, false)?),
            },
        };
        pollster::block_on(m.submit_frame(gpu, &frame, &pose)).with_context(|| format!("fusing frame {index}"))?;
        trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: pose });
        let now = std::time::Instant::now();
        times.record("frame", (now - last).as_secs_f64() * 1e3);
        last = now;
        eprint!("\rframe {}/{n_frames} fused at its given pose   ", trajectory.len());
    }
    eprintln!();
    let Some(mut mapper) = mapper else {
        anyhow::bail!("no frame of {} has a given pose (within {} ms) in {}", source.name(), MAX_POSE_GAP_NS / 1_000_000, args.pose_file().map_or(String::new(), |p| p.display().to_string()));
    };
    pollster::block_on(mapper.flush(gpu))?;
    let wall_s = started.elapsed().as_secs_f64();
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));
    let map_stats = mapper.map_stats();
    if let Some(stats) = &map_stats {
        print_map_stats(stats, mapper.volume().memory_bytes());
    }
    let trajectory_path = args.out.join("trajectory.txt");
    write_tum_trajectory(&trajectory_path, &trajectory).with_context(|| format!("writing {}", trajectory_path.display()))?;
    write_ground_truth(args, &*source)?;
    let given_json = given_report(args, &without_pose, None)?;
    save_map(gpu, mapper.mapper_mut(), config, args, &*source, &trajectory, loaded_up)?;
    if !args.no_mesh {
        let sw = crate::timing::Stopwatch::start();
        let mesh = pollster::block_on(mapper.extract_mesh(gpu)).context("extracting the mesh")?;
        times.record("mesh extraction", sw.ms());
        write_mesh(&mesh, &args.out.join("mesh.ply"))?;
    }
    println!("{} of {n_frames} frames of {} fused at given poses on {}; {:.2} frames/s over {:.1} s{}", trajectory.len(), source.name(), gpu.adapter_summary(), trajectory.len() as f64 / wall_s, wall_s, crate::skipped_note(&skipped));
    times.print();
    let stats = serde_json::json!({
        "frames": n_frames,
        "fused_frames": trajectory.len(),
        "skipped_corrupt_frames": skipped,
        "adapter": gpu.adapter_summary(),
        "wall_s": wall_s,
        "given_poses": given_json,
        "volume": {
            "kind": config.tsdf.kind.name(),
            "voxel_size_m": config.tsdf.voxel_size_m,
            "truncation_m": config.tsdf.truncation_m,
            "noise_band_sigmas": config.tsdf.noise_band_sigmas,
            "memory_bytes": mapper.volume().memory_bytes(),
            "sparse": map_stats.as_ref().map(map_stats_json),
        },
        "stages_ms": times.to_json(),
    });
    let stats_path = args.out.join("stats.json");
    std::fs::write(&stats_path, serde_json::to_string_pretty(&stats)?).with_context(|| format!("writing {}", stats_path.display()))?;
    println!("wrote {}, {}", trajectory_path.display(), stats_path.display());
    Ok(())
}

/// The feature assistant of a reconstruction, or why there is none.
fn feature_assist(args: &ReconstructArgs, gpu: &webfusion_core::Gpu, fusion: &KinectFusion, given_poses: bool) -> anyhow::Result<(Option<FeatureAssist>, &'static str)> {
    if args.no_features {
        return Ok((None, "--no-features"));
    }
    if given_poses {
        return Ok((None, "poses given"));
    }
    match FeatureAssist::new(gpu, fusion.preprocessor(), OdometryConfig::default()) {
        Ok(mut assist) => {
            let icp = &fusion.config().icp;
            assist.set_jump_limits(f64::from(icp.max_jump_m), f64::from(icp.max_jump_rad));
            Ok((Some(assist), ""))
        }
        // Too small an image or too few pyramid levels for the keypoint grid: ICP alone.
        Err(webfusion_core::Error::InvalidConfig(why)) => {
            eprintln!("feature odometry off: {why}");
            Ok((None, "the frames are too small for keypoints"))
        }
        Err(e) => Err(e.into()),
    }
}

/// Writes the source's ground truth (all of it, in its own frame) as `groundtruth.txt`, if it
/// has one: a recording's is otherwise only inside the file.
fn write_ground_truth(args: &ReconstructArgs, source: &dyn webfusion_core::source::FrameSource) -> anyhow::Result<()> {
    let Some(gt) = source.ground_truth() else { return Ok(()) };
    let path = args.out.join("groundtruth.txt");
    write_tum_trajectory(&path, gt).with_context(|| format!("writing {}", path.display()))
}
