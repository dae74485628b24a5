// SPDX-License-Identifier: MIT
//! `webfusion`: the native command of webfusion: GPU preprocessing of RGB-D logs, benchmarks,
//! recording conversion (the capture bridge and reconstruction land here as they are built).

mod bench_stream;
mod calib;
mod compare;
mod eval;
#[cfg(feature = "openni2")]
mod openni;
mod occupancy;
mod odometry;
mod planes;
mod plot;
mod pose_args;
mod reconstruct;
mod record;
mod serve;
mod simulate;
mod synth;
mod timing;

use std::path::PathBuf;

use anyhow::Context as _;
use clap::{Parser, Subcommand};
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_core::source::{FrameSource, LiveSource, open_source};
use webfusion_core::{Gpu, GpuOptions};

use crate::calib::CalibrationArgs;
use crate::timing::{StageTimes, Stopwatch};

/// The bundled sample log (TUM fr1/rpy, 100 frames, CC BY 4.0; see data/README.md).
pub(crate) const DEFAULT_SAMPLE: &str = "data/sample/fr1_rpy.wfr";

#[derive(Parser)]
#[command(name = "webfusion", version, about = "Real-time RGB-D reconstruction on WebGPU/Vulkan: native tools")]
struct Cli {
    /// Use the GPU adapter whose name contains this (also: env WEBFUSION_ADAPTER).
    #[arg(long, global = true)]
    adapter: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the GPU adapter, its limits and the kernel set.
    Info,
    /// Run the GPU preprocessing (depth -> filtered pyramid, vertex and normal maps, colour)
    /// over every frame of a log and print per-stage timings.
    Preprocess(PreprocessArgs),
    /// Benchmark each preprocessing kernel at the log's resolution: median of N runs after
    /// warm-up, one submission per kernel.
    Bench(BenchArgs),
    /// Reconstruct a log with KinectFusion: trajectory, mesh and per-stage statistics.
    Reconstruct(reconstruct::ReconstructArgs),
    /// Convert any source (TUM directory, recording) into a `.wfr` recording.
    Record(record::RecordArgs),
    /// Write a finished copy (index and footer) of a recording whose writer was killed or that
    /// is damaged: every complete, CRC-checked frame, bytes unchanged, and the counts.
    Repair(record::RepairArgs),
    /// Benchmark depth codecs (RVL, RVL+DEFLATE) against PNG and zstd on the same frames.
    BenchCodecs(bench_stream::BenchCodecsArgs),
    /// Benchmark sustained streaming to 1, 4 and 16 WebSocket clients on loopback.
    BenchClients(bench_stream::BenchClientsArgs),
    /// List the RGB-D devices OpenNI2 sees (Kinect v1 needs libfreenect's OpenNI2 driver).
    #[cfg(feature = "openni2")]
    Devices,
    /// Write a test `.oni` recording from OpenNI2's built-in Dummy device (320x240 depth,
    /// 1 mm units, no colour, no field of view), playable by Debian's OpenNI2 player.
    #[cfg(feature = "openni2")]
    OniDummy(OniDummyArgs),
    /// Serve the web app and stream a source's frames to WebSocket clients on one port.
    Serve(serve::ServeArgs),
    /// Trajectory error of an estimate against ground truth (TUM files): ATE and RPE as evo computes them.
    Eval(eval::EvalArgs),
    /// Render the synthetic furnished room along a loop into a `.wfr` recording with exact
    /// ground truth (room-sized runs of the map).
    SynthRoom(synth::SynthRoomArgs),
    /// Seed 000's virtual depth sensor: render a saved map at given poses into a TUM-layout
    /// directory (exact or Kinect-noise depth, optional colour) that every command reads back.
    Simulate(simulate::SimulateArgs),
    /// Simulated depth against real depth at the same timestamps (seed 000 §6.3): % of pixels
    /// over 10 % relative error, new valid pixels, coverage, absolute errors; difference images
    /// and an error-vs-distance chart.
    Compare(compare::CompareArgs),
    /// Seed 000's occupancy grid of a saved map (1 byte per cell: 255 occupied, 0 free, 128
    /// never observed; x fastest), free space carved from the poses the map was fused from, with
    /// a JSON description beside it.
    ExportOccupancy(occupancy::ExportOccupancyArgs),
    /// Seed 003's plane segmentation of every frame: each frame's planes (normal, offset,
    /// area, extent) in its camera frame as `frames.json`, and optionally label images.
    Planes(planes::PlanesArgs),
    /// Seed 002's feature-based visual odometry, frame to frame: keypoints, descriptors and
    /// matching on the GPU, RANSAC on 3D-3D pairs; `trajectory.txt` (TUM) and `stats.json`
    /// (per-stage times, keypoint/match/inlier counts).
    Odometry(odometry::OdometryArgs),
}

#[derive(clap::Args)]
struct PreprocessArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(long, default_value = DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Frames to process, `A..B` (end exclusive); default all.
    #[arg(long)]
    frames: Option<String>,
    #[command(flatten)]
    calibration: CalibrationArgs,
    /// Write per-stage statistics as JSON here.
    #[arg(long)]
    stats_json: Option<PathBuf>,
    /// Skip damaged frames of a recording (counted) instead of stopping at the first.
    #[arg(long)]
    skip_corrupt: bool,
}

#[cfg(feature = "openni2")]
#[derive(clap::Args)]
struct OniDummyArgs {
    /// The `.oni` file to write.
    #[arg(long)]
    out: PathBuf,
    /// Frames to record.
    #[arg(long, default_value_t = 30)]
    frames: usize,
}

#[derive(clap::Args)]
struct BenchArgs {
    /// TUM RGB-D directory or `.wfr` recording (the first frame is used).
    #[arg(long, default_value = DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Timed runs per kernel.
    #[arg(long, default_value_t = 30)]
    iterations: usize,
    /// Untimed runs first (the first pass over new buffers is slow on lavapipe).
    #[arg(long, default_value_t = 5)]
    warmup: usize,
    /// Frames fused with the default KinectFusion pipeline before its stages are timed one
    /// by one on the next frame (0: preprocessing only).
    #[arg(long, default_value_t = 10)]
    fusion_frames: usize,
    /// The map the pipeline fuses into: `sparse` (the default: voxel blocks, the default pool)
    /// or `dense` (the default cube, of the same voxel size).
    #[arg(long, default_value = "sparse")]
    map_kind: webfusion_core::map::MapKind,
    #[command(flatten)]
    calibration: CalibrationArgs,
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    let options = GpuOptions { adapter_name_contains: cli.adapter.clone(), prefer_cpu_adapter: false };
    match cli.command {
        Command::Info => info(&options),
        Command::Preprocess(args) => preprocess(&options, &args),
        Command::Bench(args) => bench(&options, &args),
        Command::Record(args) => record::run(&args),
        Command::Repair(args) => record::repair(&args),
        Command::Eval(args) => eval::run(&args),
        Command::SynthRoom(args) => synth::run(&args),
        Command::Simulate(args) => simulate::run(&options, &args),
        Command::Compare(args) => compare::run(&args),
        Command::ExportOccupancy(args) => occupancy::run(&options, &args),
        Command::Planes(args) => planes::run(&options, &args),
        Command::Odometry(args) => odometry::run(&options, &args),
        Command::Serve(args) => serve::run(&options, args),
        #[cfg(feature = "openni2")]
        Command::Devices => {
            let devices = openni::list_devices()?;
            if devices.is_empty() {
                println!("no OpenNI2 devices found. An Asus Xtion/PrimeSense works with Debian's PS1080 driver; a Kinect v1 needs libfreenect's OpenNI2 driver (libfreenect's OpenNI2-FreenectDriver in the OpenNI2 Drivers folder); check USB permissions (udev rules).");
            }
            for d in devices {
                println!("{}  {} {}  (USB {:04x}:{:04x})", d.uri, d.vendor, d.name, d.usb_id.0, d.usb_id.1);
            }
            Ok(())
        }
        #[cfg(feature = "openni2")]
        Command::OniDummy(args) => {
            let frames = openni::record_dummy(&args.out, args.frames).with_context(|| format!("writing {}", args.out.display()))?;
            println!("wrote {} ({frames} frames, 320x240 depth, no colour; read it with --intrinsics 285,285,159.5,119.5 --depth-scale 1000)", args.out.display());
            Ok(())
        }
        Command::BenchCodecs(args) => bench_stream::bench_codecs(&args),
        Command::BenchClients(args) => bench_stream::bench_clients(&args),
        Command::Reconstruct(args) => reconstruct::run(&options, &args),
    }
}

pub(crate) fn open(source: &std::path::Path, calibration: &CalibrationArgs) -> anyhow::Result<Box<dyn FrameSource>> {
    open_with(source, calibration.resolve()?)
}

/// `"; N damaged frames skipped (i, j, …)"`, or nothing.
pub(crate) fn skipped_note(skipped: &[usize]) -> String {
    if skipped.is_empty() {
        return String::new();
    }
    let list: Vec<String> = skipped.iter().take(10).map(usize::to_string).collect();
    format!("; {} damaged frames skipped ({}{})", skipped.len(), list.join(", "), if skipped.len() > 10 { ", …" } else { "" })
}

/// Reads frame `index` of `source`. A damaged record (`Error::CorruptFrame`) is an error naming
/// the frame, unless `skip_corrupt`: then it is reported on stderr, added to `skipped` and
/// `None` comes back, so the command goes on with the next frame.
pub(crate) fn read_or_skip(source: &mut dyn FrameSource, index: usize, skip_corrupt: bool, skipped: &mut Vec<usize>) -> anyhow::Result<Option<webfusion_core::RgbdFrame>> {
    match source.read_frame(index) {
        Ok(frame) => Ok(Some(frame)),
        Err(e @ webfusion_core::Error::CorruptFrame { .. }) if skip_corrupt => {
            eprintln!("\nskipping a damaged frame: {e}");
            skipped.push(index);
            Ok(None)
        }
        Err(e @ webfusion_core::Error::CorruptFrame { .. }) => Err(anyhow::Error::new(e).context(format!("reading frame {index} of {} (--skip-corrupt skips damaged frames)", source.name()))),
        Err(e) => Err(anyhow::Error::new(e).context(format!("reading frame {index} of {}", source.name()))),
    }
}

/// Opens a source with an already resolved calibration override.
pub(crate) fn open_with(source: &std::path::Path, calibration: Option<webfusion_core::RgbdCalibration>) -> anyhow::Result<Box<dyn FrameSource>> {
    if source.extension().is_some_and(|e| e.eq_ignore_ascii_case("oni")) {
        #[cfg(feature = "openni2")]
        return Ok(Box::new(openni::OniSource::open(source, calibration).with_context(|| format!("opening source {}", source.display()))?));
        #[cfg(not(feature = "openni2"))]
        anyhow::bail!("{}: this webfusion was built without OpenNI2 support; rebuild with `--features openni2` (needs libopenni2-dev)", source.display());
    }
    if source.is_file() && webfusion_core::source::is_recording(source).unwrap_or(false) {
        let recording = webfusion_core::source::open_recording(source, calibration).with_context(|| format!("opening source {}", source.display()))?;
        if let Some(report) = recording.recovery() {
            eprintln!("warning: {}: {report}; `webfusion repair` writes a finished copy", source.display());
        }
        return Ok(Box::new(recording));
    }
    open_source(source, calibration).with_context(|| format!("opening source {}", source.display()))
}

/// `Some(uri)` when `source` names a live OpenNI2 camera: `openni2` (the first one, `uri`
/// `None`) or `openni2:<uri>`.
pub(crate) fn live_spec(source: &std::path::Path) -> Option<Option<&str>> {
    let text = source.to_str()?;
    match text.strip_prefix("openni2") {
        Some("") => Some(None),
        Some(rest) => rest.strip_prefix(':').map(Some),
        None => None,
    }
}

/// Opens a live camera named by [`live_spec`].
pub(crate) fn open_live(uri: Option<&str>, calibration: Option<webfusion_core::RgbdCalibration>) -> anyhow::Result<Box<dyn LiveSource>> {
    #[cfg(feature = "openni2")]
    return Ok(Box::new(openni::LiveDevice::open(uri, calibration).with_context(|| format!("opening the live camera openni2{}", uri.map(|u| format!(":{u}")).unwrap_or_default()))?));
    #[cfg(not(feature = "openni2"))]
    {
        let _ = (uri, calibration);
        anyhow::bail!("live cameras need OpenNI2: rebuild webfusion with `--features openni2` (needs libopenni2-dev)");
    }
}

/// The first frames of a live source as a [`FrameSource`] read forwards only (for `record`).
pub(crate) struct LiveTake {
    live: Box<dyn LiveSource>,
    count: usize,
    next: usize,
}

impl LiveTake {
    pub(crate) fn new(live: Box<dyn LiveSource>, count: usize) -> Self {
        Self { live, count, next: 0 }
    }
}

impl FrameSource for LiveTake {
    fn name(&self) -> String {
        self.live.name()
    }
    fn calibration(&self) -> webfusion_core::RgbdCalibration {
        self.live.calibration()
    }
    fn frame_count(&self) -> usize {
        self.count
    }
    fn read_frame(&mut self, index: usize) -> webfusion_core::Result<webfusion_core::RgbdFrame> {
        if index < self.next || index >= self.count {
            return Err(webfusion_core::Error::InvalidConfig(format!("a live source is read forwards: asked for frame {index}, next is {} of {}", self.next, self.count)));
        }
        while self.next < index {
            self.live.next_frame()?;
            self.next += 1;
        }
        self.next += 1;
        self.live.next_frame()
    }
    fn ground_truth(&self) -> Option<&[webfusion_core::source::TimedPose]> {
        None
    }
    fn frames_dropped_by_source(&self) -> u64 {
        self.live.frames_dropped()
    }
}

fn gpu(options: &GpuOptions) -> anyhow::Result<Gpu> {
    let gpu = pollster::block_on(Gpu::new(options))?;
    eprintln!("GPU: {}", gpu.adapter_summary());
    Ok(gpu)
}

fn info(options: &GpuOptions) -> anyhow::Result<()> {
    let gpu = gpu(options)?;
    let l = &gpu.limits;
    println!("adapter: {}", gpu.adapter_summary());
    println!("driver: {} {}", gpu.adapter_info.driver, gpu.adapter_info.driver_info);
    println!("max_storage_buffer_binding_size: {} MiB", l.max_storage_buffer_binding_size >> 20);
    let pool = webfusion_core::map::max_pool_blocks(l.max_storage_buffer_binding_size);
    println!("largest sparse pool: {pool} blocks of 8³ ({:.0} MiB with colour)", webfusion_core::map::pool_budget_mib(pool));
    println!("max_compute_workgroup_storage_size: {} KiB", l.max_compute_workgroup_storage_size >> 10);
    println!("kernels:");
    for k in webfusion_shaders::ALL {
        println!("  {:<20} workgroup {:?}, {} bindings", k.name, k.workgroup_size, k.bindings.len());
    }
    Ok(())
}

/// The frames of `range` kept by `--every N` (every N-th from its start) and `--drop A..B`
/// (a stretch left out), in order.
pub(crate) fn selected_frames(range: std::ops::Range<usize>, every: usize, drop: Option<&str>) -> anyhow::Result<Vec<usize>> {
    anyhow::ensure!(every >= 1, "--every must be at least 1");
    let drop = drop.map(|d| odometry::parse_range(d, "--drop")).transpose()?;
    Ok(range.step_by(every).filter(|i| drop.as_ref().is_none_or(|d| !d.contains(i))).collect())
}

fn frame_range(spec: Option<&str>, count: usize) -> anyhow::Result<std::ops::Range<usize>> {
    let Some(spec) = spec else { return Ok(0..count) };
    let (a, b) = spec.split_once("..").with_context(|| format!("--frames {spec:?}: expected A..B"))?;
    let start: usize = if a.is_empty() { 0 } else { a.parse().with_context(|| format!("--frames start {a:?}"))? };
    let end: usize = if b.is_empty() { count } else { b.parse().with_context(|| format!("--frames end {b:?}"))? };
    anyhow::ensure!(start < end && end <= count, "--frames {spec}: the source has frames 0..{count}");
    Ok(start..end)
}

fn preprocess(options: &GpuOptions, args: &PreprocessArgs) -> anyhow::Result<()> {
    let mut source = open(&args.source, &args.calibration)?;
    let range = frame_range(args.frames.as_deref(), source.frame_count())?;
    let gpu = gpu(options)?;
    let pre = DepthPreprocessor::new(&gpu, source.calibration(), PreprocessConfig::default())?;
    let mut times = StageTimes::default();
    let n_frames = range.len();
    let mut skipped = Vec::new();
    for (done, index) in range.enumerate() {
        let sw = Stopwatch::start();
        let Some(frame) = read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        times.record("read+decode", sw.ms());
        let sw = Stopwatch::start();
        pre.upload(&gpu, &frame)?;
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("webfusion.preprocess") });
        pre.encode(&gpu, &mut encoder);
        pollster::block_on(gpu.submit_and_wait(encoder))?;
        times.record("gpu preprocess (upload + all kernels)", sw.ms());
        if (done + 1) % 10 == 0 || done + 1 == n_frames {
            eprint!("\rframe {}/{}", done + 1, n_frames);
        }
    }
    eprintln!();
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));
    println!("{} frames of {} on {}{}", n_frames - skipped.len(), source.name(), gpu.adapter_summary(), skipped_note(&skipped));
    times.print();
    if let Some(path) = &args.stats_json {
        let json = serde_json::json!({ "frames": n_frames, "adapter": gpu.adapter_summary(), "stages_ms": times.to_json() });
        std::fs::write(path, serde_json::to_string_pretty(&json)?).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn bench(options: &GpuOptions, args: &BenchArgs) -> anyhow::Result<()> {
    anyhow::ensure!(args.iterations > 0, "--iterations must be > 0");
    let mut source = open(&args.source, &args.calibration)?;
    let frame = source.read_frame(0)?;
    let gpu = gpu(options)?;
    let pre = DepthPreprocessor::new(&gpu, source.calibration(), PreprocessConfig::default())?;
    let k = source.calibration().intrinsics;
    pre.upload(&gpu, &frame)?;
    let mut times = StageTimes::default();
    for iteration in 0..args.warmup + args.iterations {
        let timed = iteration >= args.warmup;
        let sw = Stopwatch::start();
        pre.upload(&gpu, &frame)?;
        pollster::block_on(gpu.wait(None))?;
        if timed {
            times.record("upload (depth + colour)", sw.ms());
        }
        for (ix, stage) in pre.stages().iter().enumerate() {
            let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("webfusion.bench") });
            pre.encode_stage(&gpu, &mut encoder, ix);
            let sw = Stopwatch::start();
            pollster::block_on(gpu.submit_and_wait(encoder))?;
            if timed {
                times.record(&stage.name, sw.ms());
            }
        }
        let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("webfusion.bench.all") });
        pre.encode(&gpu, &mut encoder);
        let sw = Stopwatch::start();
        pollster::block_on(gpu.submit_and_wait(encoder))?;
        if timed {
            times.record("whole chain, one submission", sw.ms());
        }
    }
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));
    println!("preprocessing kernels at {}x{} on {}", k.width_px, k.height_px, gpu.adapter_summary());
    println!("wall-clock per submission (submit + wait), median of {} after {} warm-up runs", args.iterations, args.warmup);
    times.print();
    if args.fusion_frames > 0 {
        bench_fusion(&gpu, source.as_mut(), args)?;
    }
    Ok(())
}

/// Fuses the first frames with the default pipeline, then times each stage of the next frame
/// alone (one submission each, repeated): what a frame's GPU time is made of.
fn bench_fusion(gpu: &Gpu, source: &mut dyn FrameSource, args: &BenchArgs) -> anyhow::Result<()> {
    use webfusion_core::engine::FrameEncoder;
    use webfusion_core::fusion::mapper::IntegratePart;
    use webfusion_core::fusion::predictor::RaycastPart;
    use webfusion_core::fusion::{FusionConfig, KinectFusion};
    let n = args.fusion_frames.min(source.frame_count().saturating_sub(1));
    let mut config = FusionConfig::default();
    config.tsdf.kind = args.map_kind;
    let mut fusion = KinectFusion::new(gpu, source.calibration(), config)?;
    println!("map: {} ({:.0} MiB)", args.map_kind.name(), webfusion_core::tsdf::TsdfStore::memory_bytes(fusion.volume()) as f64 / 1048576.0);
    for i in 0..n {
        pollster::block_on(fusion.submit_frame(gpu, &source.read_frame(i)?))?;
    }
    pollster::block_on(fusion.flush(gpu))?;
    let frame = source.read_frame(n)?;
    fusion.preprocessor().upload(gpu, &frame)?;
    type Stage<'a> = (&'static str, Box<dyn Fn(&mut FrameEncoder<'_>) + 'a>);
    const ITERATION_NAMES: [&str; 4] =
        ["one ICP iteration, level 0", "one ICP iteration, level 1", "one ICP iteration, level 2", "one ICP iteration, level 3"];
    let mut stages: Vec<Stage> = vec![
        ("preprocess (whole chain)", Box::new(|fe| fusion.preprocessor().encode_in(gpu, &mut fe.stage("preprocess")))),
        ("track (every level, to convergence)", Box::new(|fe| fusion.tracker().encode_in(gpu, &mut fe.stage("track"), false))),
        ("keep the reference", Box::new(|fe| fusion.tracker().encode_keep_previous(gpu, &mut fe.stage("keep")))),
        ("integrate", Box::new(|fe| fusion.mapper().encode(gpu, fe, "integrate"))),
        ("  allocation (sparse)", Box::new(|fe| fusion.mapper().encode_part(gpu, fe, "integrate", IntegratePart::Allocate))),
        ("  visible blocks (sparse)", Box::new(|fe| fusion.mapper().encode_part(gpu, fe, "integrate", IntegratePart::Visible))),
        ("  voxel update", Box::new(|fe| fusion.mapper().encode_part(gpu, fe, "integrate", IntegratePart::Blocks))),
        ("raycast + prediction pyramid", Box::new(|fe| fusion.predictor().encode(gpu, fe, "predict"))),
        ("  depth-range tiles", Box::new(|fe| fusion.predictor().finest().encode_part(gpu, fe, "predict", RaycastPart::RangeTiles))),
        ("  rays (finest level)", Box::new(|fe| fusion.predictor().finest().encode_part(gpu, fe, "predict", RaycastPart::Rays))),
        ("  surface normals", Box::new(|fe| fusion.predictor().finest().encode_part(gpu, fe, "predict", RaycastPart::Normals))),
        ("  prediction pyramid (downsampling)", Box::new(|fe| fusion.predictor().encode_downsampling(gpu, fe, "predict"))),
    ];
    let tracker = fusion.tracker();
    for (level, name) in ITERATION_NAMES.iter().enumerate().take(tracker.levels()) {
        stages.push((name, Box::new(move |fe| tracker.encode_iteration(gpu, &mut fe.stage("iteration"), level))));
    }
    let mut times = StageTimes::default();
    for iteration in 0..args.warmup + args.iterations {
        for (name, encode) in &stages {
            let mut fe = FrameEncoder::new(gpu, "webfusion.bench.fusion", None);
            encode(&mut fe);
            let (commands, _) = fe.finish(None);
            let sw = Stopwatch::start();
            let index = gpu.submit([commands]);
            pollster::block_on(gpu.wait(Some(index)))?;
            if iteration >= args.warmup {
                times.record(name, sw.ms());
            }
        }
    }
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));
    let t = &fusion.config().tsdf;
    println!("\nKinectFusion stages after {n} fused frames, default settings ({}³ voxels of {:.1} mm), each stage alone", t.dims_voxels[0], t.voxel_size_m * 1e3);
    times.print();
    Ok(())
}
