// SPDX-License-Identifier: MIT
//! `webfusion reconstruct`: KinectFusion over a log, headless. Writes the trajectory (TUM
//! format), the mesh (binary PLY) and per-stage statistics.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use webfusion_core::fusion::{FusionConfig, KinectFusion, TrackingState};
use webfusion_core::io::trajectory::{TimedPose, write_tum_trajectory};
use webfusion_core::tsdf::{DEFAULT_TRUNCATION_VOXELS, TsdfConfig, VolumePlacement};
use webfusion_core::GpuOptions;

use crate::calib::CalibrationArgs;
use crate::timing::StageTimes;

#[derive(clap::Args)]
pub(crate) struct ReconstructArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Output directory (created): trajectory.txt, mesh.ply, mesh.glb, stats.json.
    #[arg(long)]
    out: PathBuf,
    /// Frames to process, `A..B` (end exclusive); default all.
    #[arg(long)]
    frames: Option<String>,
    /// Voxel edge length, metres (default: 3 m / voxels per axis).
    #[arg(long)]
    voxel_size: Option<f32>,
    /// Voxels per axis of the cubic volume.
    #[arg(long, default_value_t = webfusion_core::tsdf::DEFAULT_VOLUME_DIM_VOXELS)]
    volume: u32,
    /// Put the first camera at the volume's centre instead of in front of it (for a camera
    /// that turns in place).
    #[arg(long)]
    centred: bool,
    /// Truncation distance μ, metres (default: 4 voxels).
    #[arg(long)]
    truncation: Option<f32>,
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
    /// Initialise each frame with a constant-velocity motion model.
    #[arg(long)]
    constant_velocity: bool,
    /// Do not fuse colour.
    #[arg(long)]
    no_color: bool,
    /// Skip mesh extraction.
    #[arg(long)]
    no_mesh: bool,
    #[command(flatten)]
    calibration: CalibrationArgs,
}

impl ReconstructArgs {
    fn config(&self) -> anyhow::Result<FusionConfig> {
        let mut config = FusionConfig::default();
        let voxel = self.voxel_size.unwrap_or(webfusion_core::tsdf::DEFAULT_VOLUME_SIZE_M / self.volume as f32);
        config.tsdf = TsdfConfig { truncation_m: self.truncation.unwrap_or(DEFAULT_TRUNCATION_VOXELS * voxel), color: !self.no_color, placement: if self.centred { VolumePlacement::Centred } else { VolumePlacement::InFront }, ..TsdfConfig::cube(self.volume, voxel) };
        config.icp.iterations_per_level = self.icp_iterations.clone();
        config.icp.dist_thresh_m = self.icp_dist;
        config.icp.angle_thresh_rad = self.icp_angle_deg.to_radians();
        config.icp.constant_velocity = self.constant_velocity;
        config.icp.huber_delta_m = self.huber;
        config.icp.rgb_weight = self.rgb_weight;
        config.icp.noise_weighting = !self.no_noise_weighting;
        config.validate()?;
        Ok(config)
    }
}

pub(crate) fn run(options: &GpuOptions, args: &ReconstructArgs) -> anyhow::Result<()> {
    let config = args.config()?;
    let mut source = crate::open(&args.source, &args.calibration)?;
    let range = crate::frame_range(args.frames.as_deref(), source.frame_count())?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating output directory {}", args.out.display()))?;
    let gpu = crate::gpu(options)?;
    let mut fusion = KinectFusion::new(&gpu, source.calibration(), config)?;
    let mut times = StageTimes::default();
    let mut trajectory = Vec::with_capacity(range.len());
    let mut lost = Vec::new();
    let n_frames = range.len();
    for (done, index) in range.enumerate() {
        let frame = source.read_frame(index).with_context(|| format!("reading frame {index} of {}", source.name()))?;
        let report = pollster::block_on(fusion.process_frame(&gpu, &frame)).with_context(|| format!("processing frame {index}"))?;
        let t = report.times_ms;
        times.record("preprocess", t.preprocess);
        if report.state != TrackingState::Initialised {
            times.record("track", t.track);
        }
        if !report.state.is_lost() {
            times.record("integrate", t.integrate);
            times.record("raycast", t.raycast);
        }
        times.record("frame", t.total);
        if let TrackingState::Lost(reason) = report.state {
            eprintln!("\nframe {index}: tracking lost ({reason:?}); keeping the last good pose");
            lost.push(index);
        }
        trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: report.world_from_camera });
        let inliers = report.icp.last().map_or(0, |s| s.inliers);
        eprint!("\rframe {}/{} [{}] {:.0} ms, ICP inliers {inliers}   ", done + 1, n_frames, report.state.name(), t.total);
    }
    eprintln!();
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));

    let trajectory_path = args.out.join("trajectory.txt");
    write_tum_trajectory(&trajectory_path, &trajectory).with_context(|| format!("writing {}", trajectory_path.display()))?;
    if !args.no_mesh {
        write_mesh(&gpu, &fusion, &args.out.join("mesh.ply"), &mut times)?;
    }
    println!("{n_frames} frames of {} on {}; {} lost", source.name(), gpu.adapter_summary(), lost.len());
    times.print();
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
        "adapter": gpu.adapter_summary(),
        "volume": { "dims_voxels": fusion.config().tsdf.dims_voxels, "voxel_size_m": fusion.config().tsdf.voxel_size_m, "truncation_m": fusion.config().tsdf.truncation_m, "memory_bytes": fusion.volume().memory_bytes() },
        "stages_ms": times.to_json(),
    });
    let stats_path = args.out.join("stats.json");
    std::fs::write(&stats_path, serde_json::to_string_pretty(&stats)?).with_context(|| format!("writing {}", stats_path.display()))?;
    println!("wrote {}, {}", trajectory_path.display(), stats_path.display());
    Ok(())
}

/// Extracts the mesh on the GPU and writes it as binary PLY and glTF binary (`.glb` beside).
fn write_mesh(gpu: &webfusion_core::Gpu, fusion: &KinectFusion, path: &Path, times: &mut StageTimes) -> anyhow::Result<()> {
    let sw = crate::timing::Stopwatch::start();
    let mesh = pollster::block_on(webfusion_core::mesh::extract_mesh(gpu, fusion.volume())).context("extracting the mesh")?;
    times.record("mesh extraction", sw.ms());
    let write = |path: &Path, glb: bool| -> anyhow::Result<()> {
        let file = std::fs::File::create(path).with_context(|| format!("creating {}", path.display()))?;
        let mut out = std::io::BufWriter::new(file);
        if glb { webfusion_core::mesh::write_glb(&mesh, &mut out) } else { webfusion_core::mesh::write_ply(&mesh, &mut out) }
            .and_then(|()| std::io::Write::flush(&mut out))
            .with_context(|| format!("writing {}", path.display()))
    };
    write(path, false)?;
    write(&path.with_extension("glb"), true)?;
    println!("mesh: {} vertices, {} triangles -> {} (+ .glb)", mesh.positions_m.len(), mesh.triangles.len(), path.display());
    Ok(())
}
