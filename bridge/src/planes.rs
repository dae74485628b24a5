// SPDX-License-Identifier: MIT
//! `webfusion planes`: seed 003's plane segmentation of every frame (`core::planes`), and the
//! world model of planes built from them.
//!
//! - `DIR/frames.json`: per frame, its planes in that frame's camera coordinates (unit normal n
//!   facing the camera, n·p + d = 0 for points p on it, metres); with `--labels`, an image of
//!   each frame's plane labels.
//! - The world model (unless `--no-world`): each frame's planes, at the frame's camera pose
//!   (`--poses`, or tracked by KinectFusion, which also fuses the map), associated across
//!   frames into world planes with growing textures (`core::planes::world`); written as
//!   `DIR/planes.json` (the poses used: `DIR/trajectory.txt`, TUM format), and with the marching-cubes mesh of the fused map less what the planes
//!   cover (the non-planar remainder) as `DIR/scene.glb` and `DIR/scene.obj` (+ `scene.mtl`,
//!   `scene_textures/`).
//!
//! With `--from-model` each frame's depth is replaced by the fused map's, as a virtual sensor
//! (`core::sim::VirtualSensor`, exact) sees it from the frame's pose after the whole sequence
//! was fused: the planes of the model (noise averaged over every view, holes filled from
//! other views) rather than of one noisy frame; the frame's colour textures them as before.
//! The sensor's raw depth is copied into the preprocessor on the GPU (no readback); the CPU
//! reference reads it back.
//!
//! Preprocessing and segmentation run on the GPU (`core::planes::gpu`: one submission per
//! frame and one readback), or with `--cpu-reference` the CPU reference
//! (`core::planes::reference`) on the CPU twin of the preprocessor; tracking and fusion run on
//! the GPU; meshing and the world model on the CPU.

use std::collections::HashMap;
use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::io::format_timestamp_s;
use webfusion_core::planes::{NO_LABEL, PlaneConfig, reference};
use webfusion_core::cpu::shared::plane_colour;
use webfusion_core::planes::gpu::GpuPlaneSegmenter;
use webfusion_core::preprocess::{DepthPreprocessor, PreprocessConfig};
use webfusion_core::map::Map;
use webfusion_core::sim::sensor::{SensorOptions, VirtualSensor};
use webfusion_core::{ColorImage, DepthImage, Gpu, GpuOptions, RgbdFrame, Se3, codec::png};
use webfusion_core::fusion::{FrameReport, FusionConfig, KinectFusion, pose_driven::PoseDrivenMapper};
use webfusion_core::io::trajectory::{TimedPose, write_tum_trajectory};
use webfusion_core::mesh::Mesh;
use webfusion_core::planes::export::{mesh_remainder, scene_obj, write_scene_glb};
use webfusion_core::planes::mesh::{PlaneMesh, blend_reach_px, complete_labels};
use webfusion_core::planes::world::{PlaneView, PlaneWorld, WorldConfig};

use crate::calib::CalibrationArgs;
use crate::timing::{StageTimes, Stopwatch};

#[derive(clap::Args)]
pub(crate) struct PlanesArgs {
    /// TUM RGB-D directory or `.wfr` recording.
    #[arg(default_value = crate::DEFAULT_SAMPLE)]
    source: PathBuf,
    /// Output directory (created; `frames.json` in it must not exist yet).
    #[arg(long)]
    out: PathBuf,
    /// Frames to segment, `A..B` (end exclusive); default all.
    #[arg(long)]
    frames: Option<String>,
    #[command(flatten)]
    calibration: CalibrationArgs,
    /// Also write each frame's labels as `labels/<timestamp>.png` (a colour per plane, black
    /// where none).
    #[arg(long)]
    labels: bool,
    /// Skip damaged frames of a recording (counted) instead of stopping at the first.
    #[arg(long)]
    skip_corrupt: bool,
    /// Camera-to-world poses for the world model (`--poses` TUM, or seed 000's
    /// `--robot-poses`, as `reconstruct` takes them; frames without one are left out of the
    /// world). Without them the frames are tracked by KinectFusion (the world is then the
    /// first camera's frame).
    #[command(flatten)]
    given: crate::pose_args::PoseFileArgs,
    /// Per-frame planes only: no world model, no tracking or fusion.
    #[arg(long)]
    no_world: bool,
    /// Segment with the CPU reference (f64, on the CPU twin of the preprocessor) instead of the
    /// GPU kernels: slower, for comparison.
    #[arg(long)]
    cpu_reference: bool,
    /// Run the GPU segmentation one kernel at a time, waiting for each, and record each
    /// kernel's time per frame in `frames.json` (`kernels_ms`; slower overall).
    #[arg(long, conflicts_with = "cpu_reference")]
    kernel_times: bool,
    /// Segment the fused map instead of the raw frames: each frame's depth is the map's, as a
    /// virtual sensor at the frame's pose sees it once every frame is fused (frames without a
    /// pose are left out).
    #[arg(long, conflicts_with = "no_world")]
    from_model: bool,
    /// Texels per metre of the world planes' textures (a power of two).
    #[arg(long, default_value_t = WorldConfig::default().px_per_m)]
    texture_px_per_m: f32,
}

/// The world model's inputs from the GPU pass: each frame's pose (by source index) and the
/// fused map's mesh.
struct WorldPoses {
    poses: HashMap<u64, Se3>,
    mesh: Mesh,
    voxel_m: f32,
    /// `"given"` or `"tracked"`.
    origin: &'static str,
    /// Frames left out: tracking lost, or no given pose.
    left_out: Vec<u64>,
    /// The fused map, kept for `--from-model`.
    map: Option<FusedMap>,
}

/// The map the world pass fused, with what fused it.
enum FusedMap {
    Tracked(Box<KinectFusion>),
    Given(Box<PoseDrivenMapper>),
}

impl FusedMap {
    fn store(&self) -> &Map {
        match self {
            FusedMap::Tracked(f) => f.volume(),
            FusedMap::Given(m) => m.volume(),
        }
    }
}

/// Tracks (or fuses at the given poses) every frame of `range` on the GPU.
fn world_poses(gpu: &Gpu, args: &PlanesArgs, range: std::ops::Range<usize>) -> anyhow::Result<WorldPoses> {
    let mut source = crate::open(&args.source, &args.calibration)?;
    let config = FusionConfig::default();
    config.validate()?;
    let voxel_m = config.tsdf.voxel_size_m;
    let mut poses = HashMap::new();
    let mut left_out = Vec::new();
    let mut skipped = Vec::new();
    if let Some(given) = args.given.read()? {
        let path = args.given.file().map(|p| p.display().to_string()).unwrap_or_default();
        let mut mapper: Option<PoseDrivenMapper> = None;
        let start = range.start;
        for index in range {
            let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
            let Some(pose) = given.pose_for(index - start, frame.depth_timestamp_ns) else {
                left_out.push(index as u64);
                continue;
            };
            let m = match &mut mapper {
                Some(m) => m,
                None => mapper.insert(PoseDrivenMapper::new(gpu, source.calibration(), config.preprocess, config.tsdf, &pose, false)?),
            };
            pollster::block_on(m.submit_frame(gpu, &frame, &pose)).with_context(|| format!("fusing frame {index}"))?;
            poses.insert(frame.index, pose);
            eprint!("\rframe {index}: fused at its given pose   ");
        }
        eprintln!();
        let Some(mut mapper) = mapper else { anyhow::bail!("no frame of {} has a given pose (within 20 ms, or in the per-frame list) in {path}", source.name()) };
        pollster::block_on(mapper.flush(gpu))?;
        let mesh = pollster::block_on(mapper.extract_mesh(gpu)).context("extracting the mesh")?;
        let map = args.from_model.then(|| FusedMap::Given(Box::new(mapper)));
        return Ok(WorldPoses { poses, mesh, voxel_m, origin: "given", left_out, map });
    }
    let mut fusion = KinectFusion::new(gpu, source.calibration(), config)?;
    let on_report = |r: FrameReport, poses: &mut HashMap<u64, Se3>, left_out: &mut Vec<u64>| {
        if r.state.is_lost() {
            left_out.push(r.index);
        } else {
            poses.insert(r.index, r.world_from_camera);
        }
        eprint!("\rframe {}: tracking {}   ", r.index, r.state.name());
    };
    for index in range {
        let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        pollster::block_on(fusion.submit_frame(gpu, &frame)).with_context(|| format!("tracking frame {index}"))?;
        for r in fusion.poll_reports(gpu)? {
            on_report(r, &mut poses, &mut left_out);
        }
    }
    for r in pollster::block_on(fusion.flush(gpu))? {
        on_report(r, &mut poses, &mut left_out);
    }
    eprintln!();
    let errors = gpu.take_errors();
    anyhow::ensure!(errors.is_empty(), "GPU reported errors: {}", errors.join("; "));
    let mesh = pollster::block_on(fusion.mapper_mut().extract_mesh(gpu)).context("extracting the mesh")?;
    let map = args.from_model.then(|| FusedMap::Tracked(Box::new(fusion)));
    Ok(WorldPoses { poses, mesh, voxel_m, origin: "tracked", left_out, map })
}

/// A plane's colour in the label images (the browser's plane view uses the same).
fn label_colour(i: u32) -> [u8; 3] {
    plane_colour(i).map(|c| (c * 255.0).round() as u8)
}

pub(crate) fn run(options: &GpuOptions, args: &PlanesArgs) -> anyhow::Result<()> {
    let mut source = crate::open(&args.source, &args.calibration)?;
    let range = crate::frame_range(args.frames.as_deref(), source.frame_count())?;
    let frames_json = args.out.join("frames.json");
    anyhow::ensure!(!frames_json.exists(), "{} exists already: choose another --out", frames_json.display());
    let px = args.texture_px_per_m;
    anyhow::ensure!(px.is_finite() && px >= 1.0 && (px as u32).is_power_of_two() && px.fract() == 0.0, "--texture-px-per-m {px}: a power of two, at least 1");
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    // One device for the world pass and the segmentation (the CPU reference without a world
    // needs none).
    let gpu = if args.cpu_reference && args.no_world { None } else { Some(crate::gpu(options)?) };
    let sw = Stopwatch::start();
    let world_input = match &gpu {
        Some(gpu) if !args.no_world => Some(world_poses(gpu, args, range.clone())?),
        _ => None,
    };
    let gpu_pass_s = sw.ms() * 1e-3;
    let mut world = PlaneWorld::new(WorldConfig { px_per_m: px, ..WorldConfig::default() });
    let mut clipped_texels = 0u64;
    let mut merged_planes = 0usize;
    // The pose of each frame added to the world, at its depth timestamp.
    let mut trajectory = Vec::new();
    if args.labels {
        std::fs::create_dir_all(args.out.join("labels")).with_context(|| format!("creating {}", args.out.display()))?;
    }
    let calibration = source.calibration();
    let k = calibration.intrinsics;
    let (pre_config, config) = (PreprocessConfig::default(), PlaneConfig::default());
    let on_gpu = match &gpu {
        Some(gpu) if !args.cpu_reference => {
            let pre = DepthPreprocessor::new(gpu, calibration, pre_config)?;
            let segmenter = GpuPlaneSegmenter::new(gpu, &pre, &config)?;
            Some((gpu, pre, segmenter))
        }
        _ => None,
    };
    // With --from-model, the fused map's depth at each frame's pose (exact: no noise).
    let mut model_view = match (&gpu, world_input.as_ref().and_then(|w| w.map.as_ref().map(|m| (m, &w.poses)))) {
        (Some(gpu), Some((map, poses))) => Some((VirtualSensor::new(gpu, map.store(), k, SensorOptions { units_per_metre: calibration.depth_units_per_metre, ..SensorOptions::default() })?, gpu, map.store(), poses)),
        _ => None,
    };
    let mut without_pose = 0usize;
    // Without the world model, the labels leave the GPU only for the label images (with it,
    // they come back beside their completion).
    let read_labels = args.labels;
    let mut overflow = 0u32;
    let mut times = StageTimes::default();
    let mut frames = Vec::with_capacity(range.len());
    let mut skipped = Vec::new();
    let mut counts = Vec::with_capacity(range.len());
    let started = std::time::Instant::now();
    for index in range.clone() {
        let sw = Stopwatch::start();
        let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        let read_ms = sw.ms();
        let mut model_ms = None;
        // With the GPU chain, the pose the map's depth is rendered at, into the preprocessor.
        let mut model_pose = None;
        let frame = match &mut model_view {
            Some((sensor, gpu, store, poses)) => {
                let Some(pose) = poses.get(&frame.index) else {
                    without_pose += 1;
                    continue;
                };
                if on_gpu.is_some() {
                    model_pose = Some(*pose);
                    frame
                } else {
                    // The CPU reference reads the map's depth back.
                    let sw = Stopwatch::start();
                    let model = pollster::block_on(sensor.render(gpu, *store, pose, index as u32)).with_context(|| format!("rendering the model at frame {index}"))?;
                    model_ms = Some(sw.ms());
                    RgbdFrame { depth: DepthImage::new(k.width_px, k.height_px, model.depth_units)?, ..frame }
                }
            }
            None => frame,
        };
        let mut kernels_ms: Vec<(&str, f64)> = Vec::new();
        // For the world model, the labels completed for meshing (kernel `plane_complete`, or
        // its twin with the CPU reference).
        let mut complete_ms = None;
        let (seg, completed, preprocess_ms, segment_ms) = match &on_gpu {
            None => {
                let sw = Stopwatch::start();
                let pre = preprocess(&calibration, &pre_config, &frame);
                let preprocess_ms = sw.ms();
                let sw = Stopwatch::start();
                let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
                let segment_ms = sw.ms();
                let sw = Stopwatch::start();
                let completed = world_input.is_some().then(|| complete_labels(&seg, &pre.depth_unfiltered_m, &k, &config, blend_reach_px(&pre_config)));
                complete_ms = completed.as_ref().map(|_| sw.ms());
                (seg, completed, preprocess_ms, segment_ms)
            }
            Some((gpu, pre, segmenter)) => {
                if let (Some(pose), Some((sensor, _, store, _))) = (&model_pose, &mut model_view) {
                    // The map's depth at the frame's pose replaces the frame's on the GPU (the
                    // sensor's raw depth has the preprocessor's layout: two u16 a word), with
                    // no readback; the frame's colour stays.
                    let sw = Stopwatch::start();
                    pre.upload_color(gpu, &frame.color)?;
                    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("planes.model_depth") });
                    sensor.encode_into(gpu, &mut encoder, *store, pose, index as u32, pre).with_context(|| format!("rendering the model at frame {index}"))?;
                    pollster::block_on(gpu.submit_and_wait(encoder))?;
                    model_ms = Some(sw.ms());
                }
                // Two submissions, so that each stage's time is its own.
                let sw = Stopwatch::start();
                if model_pose.is_none() {
                    pre.upload(gpu, &frame)?;
                }
                let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("planes.preprocess") });
                pre.encode(gpu, &mut encoder);
                pollster::block_on(gpu.submit_and_wait(encoder))?;
                let preprocess_ms = sw.ms();
                let sw = Stopwatch::start();
                if args.kernel_times {
                    kernels_ms = pollster::block_on(segmenter.run_profiled(gpu))?;
                } else {
                    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("planes.segment") });
                    segmenter.encode(gpu, &mut encoder);
                    pollster::block_on(gpu.submit_and_wait(encoder))?;
                }
                let (seg, completed, stats, segment_ms) = if world_input.is_some() {
                    // The completion (and the readback of both label images) as a stage of its own.
                    let segment_ms = sw.ms();
                    let sw = Stopwatch::start();
                    let (seg, completed, stats) = pollster::block_on(segmenter.read_with_completed(gpu))?;
                    complete_ms = Some(sw.ms());
                    (seg, Some(completed), stats, segment_ms)
                } else {
                    let (seg, stats) = if read_labels { pollster::block_on(segmenter.read(gpu)) } else { pollster::block_on(segmenter.read_table(gpu)) }?;
                    (seg, None, stats, sw.ms())
                };
                overflow += stats.overflow;
                (seg, completed, preprocess_ms, segment_ms)
            }
        };
        for (stage, ms) in [("read+decode", read_ms), ("preprocess", preprocess_ms), ("segment", segment_ms)] {
            times.record(stage, ms);
        }
        if let Some(ms) = complete_ms {
            times.record("complete labels", ms);
        }
        if let Some(ms) = model_ms {
            times.record("model depth", ms);
        }
        counts.push(seg.planes.len());
        let mut world_ids = None;
        let mut world_ms = None;
        if let Some(pose) = world_input.as_ref().and_then(|w| w.poses.get(&frame.index))
            && let Some(labels) = &completed
        {
            trajectory.push(TimedPose { timestamp_ns: frame.depth_timestamp_ns, world_from_camera: *pose });
            let sw = Stopwatch::start();
            let view = PlaneView { index: frame.index, world_from_camera: *pose, segmentation: &seg, labels, colour: &frame.color, intrinsics: k };
            let association = world.add_frame(&view, &config);
            clipped_texels += association.clipped_texels;
            merged_planes += association.merged;
            world_ids = Some(association.world_plane);
            let ms = sw.ms();
            times.record("world model", ms);
            world_ms = Some(ms);
        }
        if args.labels {
            let rgb: Vec<u8> = seg.labels.iter().flat_map(|&l| if l == NO_LABEL { [0, 0, 0] } else { label_colour(l) }).collect();
            let name = args.out.join(format!("labels/{}.png", format_timestamp_s(frame.depth_timestamp_ns)));
            std::fs::write(&name, png::encode_rgb8(&ColorImage::new(k.width_px, k.height_px, rgb)?)?).with_context(|| format!("writing {}", name.display()))?;
        }
        let planes: Vec<serde_json::Value> = seg
            .planes
            .iter()
            .enumerate()
            .map(|(i, p)| {
                serde_json::json!({
                    "world_plane": world_ids.as_ref().map(|ids| ids[i]),
                    "normal": p.normal,
                    "offset_m": p.offset_m,
                    "pixels": p.pixels,
                    "area_m2": p.area_m2,
                    "centroid_m": p.centroid_m,
                    "tangent": p.tangent,
                    "extent_m": p.extent_m,
                    "rms_m": p.rms_m,
                    "bend_deg": p.bend_deg,
                })
            })
            .collect();
        frames.push(serde_json::json!({
            "index": index,
            "timestamp": frame.depth_timestamp_ns as f64 * 1e-9,
            "planes": planes,
            "curved_rejected": seg.curved_rejected,
            "stages_ms": {"model_depth": model_ms, "preprocess": preprocess_ms, "segment": segment_ms, "complete_labels": complete_ms, "world": world_ms},
            "kernels_ms": (!kernels_ms.is_empty()).then(|| kernels_ms.iter().map(|(k, ms)| ((*k).to_owned(), serde_json::json!(ms))).collect::<serde_json::Map<_, _>>()),
        }));
        eprint!("\rframe {index}: {} planes", seg.planes.len());
    }
    eprintln!();
    // A world plane merged into another after a frame named it: name the plane it is part of.
    for frame in &mut frames {
        for p in frame["planes"].as_array_mut().into_iter().flatten() {
            if let Some(j) = p["world_plane"].as_u64() {
                p["world_plane"] = world.resolve(j as usize).into();
            }
        }
    }
    let json = serde_json::json!({
        "source": source.name(),
        "implementation": if args.cpu_reference { "cpu-reference" } else { "gpu" },
        "depth": if args.from_model { "model" } else { "sensor" },
        "frames_without_pose": args.from_model.then_some(without_pose),
        "adapter": on_gpu.as_ref().map(|(gpu, _, _)| gpu.adapter_summary()),
        "planes_overflow": overflow,
        "frames": frames,
    });
    std::fs::write(&frames_json, serde_json::to_string_pretty(&json)?).with_context(|| format!("writing {}", frames_json.display()))?;
    counts.sort_unstable();
    let n = counts.len().max(1);
    println!(
        "{} frames in {:.1} s: planes per frame median {} (min {}, max {}){}",
        counts.len(),
        started.elapsed().as_secs_f64(),
        counts.get(n / 2).copied().unwrap_or(0),
        counts.first().copied().unwrap_or(0),
        counts.last().copied().unwrap_or(0),
        crate::skipped_note(&skipped)
    );
    times.print();
    println!("wrote {}", frames_json.display());
    if let Some(input) = world_input {
        let path = args.out.join("trajectory.txt");
        write_tum_trajectory(&path, &trajectory).with_context(|| format!("writing {}", path.display()))?;
        write_world(args, &world, &input, clipped_texels, merged_planes, gpu_pass_s)?;
    }
    Ok(())
}

/// Writes the world model: `planes.json`, `scene.glb` and `scene.obj` (+ `.mtl`, textures).
fn write_world(args: &PlanesArgs, world: &PlaneWorld, input: &WorldPoses, clipped_texels: u64, merged_planes: usize, gpu_pass_s: f64) -> anyhow::Result<()> {
    let sw = Stopwatch::start();
    let meshes: Vec<Option<PlaneMesh>> = (0..world.planes.len()).map(|j| world.mesh(j)).collect();
    let planar: Vec<PlaneMesh> = meshes.iter().flatten().cloned().collect();
    let rest = mesh_remainder(&input.mesh, &planar, input.voxel_m);
    let replaced = input.mesh.triangles.len() - rest.triangles.len();
    let planar_triangles: usize = planar.iter().map(|m| m.triangles.len()).sum();
    let mesh_ms = sw.ms();
    let write = |name: &str, bytes: &[u8]| -> anyhow::Result<()> {
        let path = args.out.join(name);
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        std::fs::write(&path, bytes).with_context(|| format!("writing {}", path.display()))
    };
    let mut glb = Vec::new();
    write_scene_glb(&planar, Some(&rest), &mut glb).context("encoding scene.glb")?;
    write("scene.glb", &glb)?;
    let obj = scene_obj("scene", &planar, Some(&rest)).context("encoding scene.obj")?;
    write("scene.obj", obj.obj.as_bytes())?;
    write("scene.mtl", obj.mtl.as_bytes())?;
    for (name, bytes) in &obj.textures {
        write(name, bytes)?;
    }
    let texture_bytes: usize = planar.iter().map(|m| m.texture.rgb8.len()).sum();
    let planes: Vec<serde_json::Value> = world
        .planes
        .iter()
        .zip(&meshes)
        .enumerate()
        .filter(|(_, (w, _))| w.merged_into.is_none())
        .map(|(j, (w, m))| {
            serde_json::json!({
                "id": j,
                "normal": w.normal,
                "offset_m": w.offset_m,
                "centroid_m": w.centroid_m,
                "area_m2": m.as_ref().map_or(0.0, |m| m.area_m2),
                "triangles": m.as_ref().map_or(0, |m| m.triangles.len()),
                "quads": m.as_ref().map_or(0, |m| m.quads),
                "texture_size": m.as_ref().map_or([0, 0], |m| [m.texture.width_px, m.texture.height_px]),
                "texture_px_per_m": m.as_ref().map_or(0.0, |m| m.texture.width_px as f32 / m.grid.width.next_power_of_two() as f32 * m.grid.px_per_m),
                "views": w.views,
                "pixels": w.pixels,
                "frames": w.frames,
            })
        })
        .collect();
    let json = serde_json::json!({
        "source": args.source.display().to_string(),
        "world_frame": if input.origin == "given" { "the given poses' frame" } else { "the first tracked camera's frame" },
        "poses": input.origin,
        "depth": if args.from_model { "model" } else { "sensor" },
        "frames_with_pose": input.poses.len(),
        "frames_left_out": input.left_out,
        "texel_grid_px_per_m": world.config.px_per_m,
        "clipped_texels": clipped_texels,
        "merged_planes": merged_planes,
        "planes": planes,
        "remainder": {"voxel_m": input.voxel_m, "triangles": rest.triangles.len()},
        "compactness": {
            "planar_triangles": planar_triangles,
            "marching_cubes_triangles_replaced": replaced,
            "texture_bytes": texture_bytes,
        },
        "stages_s": {"gpu_pass": gpu_pass_s, "meshes_and_remainder": mesh_ms * 1e-3},
    });
    write("planes.json", serde_json::to_string_pretty(&json)?.as_bytes())?;
    println!(
        "world: {} planes ({merged_planes} merged into others) from {} posed frames ({}); {planar_triangles} planar triangles replace {replaced} marching-cubes triangles ({:.0}x fewer), textures {:.1} MB, remainder {} triangles",
        world.live().count(),
        input.poses.len(),
        input.origin,
        replaced as f64 / planar_triangles.max(1) as f64,
        texture_bytes as f64 / 1e6,
        rest.triangles.len()
    );
    println!("wrote {} (scene.glb, scene.obj, planes.json)", args.out.display());
    Ok(())
}
