// SPDX-License-Identifier: MIT
//! `webfusion planes`: seed 003's plane segmentation of every frame (`core::planes`), written
//! as `DIR/frames.json` (per frame, its planes in that frame's camera coordinates: unit normal
//! n facing the camera, n·p + d = 0 for points p on it, metres) and, with `--labels`, an image
//! of each frame's plane labels. This runs the CPU reference of the pipeline
//! (`core::planes::reference`) on the CPU twin of the preprocessor; the GPU kernels, the world
//! model (planes merged across frames, `planes.json`) and the textured meshes (`scene.glb`) are
//! not built yet.

use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::cpu::preprocess::chain::preprocess;
use webfusion_core::io::format_timestamp_s;
use webfusion_core::planes::{NO_LABEL, PlaneConfig, reference};
use webfusion_core::preprocess::PreprocessConfig;
use webfusion_core::{ColorImage, codec::png};

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
}

/// A distinct colour for plane `i` (golden-angle hues).
fn label_colour(i: u32) -> [u8; 3] {
    let h = (i as f32 * 0.618_034).fract() * 6.0;
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c: f32| (40.0 + 215.0 * c) as u8)
}

pub(crate) fn run(args: &PlanesArgs) -> anyhow::Result<()> {
    let mut source = crate::open(&args.source, &args.calibration)?;
    let range = crate::frame_range(args.frames.as_deref(), source.frame_count())?;
    let frames_json = args.out.join("frames.json");
    anyhow::ensure!(!frames_json.exists(), "{} exists already: choose another --out", frames_json.display());
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    if args.labels {
        std::fs::create_dir_all(args.out.join("labels")).with_context(|| format!("creating {}", args.out.display()))?;
    }
    let calibration = source.calibration();
    let k = calibration.intrinsics;
    let (pre_config, config) = (PreprocessConfig::default(), PlaneConfig::default());
    let mut times = StageTimes::default();
    let mut frames = Vec::with_capacity(range.len());
    let mut skipped = Vec::new();
    let mut counts = Vec::with_capacity(range.len());
    let started = std::time::Instant::now();
    for index in range.clone() {
        let sw = Stopwatch::start();
        let Some(frame) = crate::read_or_skip(source.as_mut(), index, args.skip_corrupt, &mut skipped)? else { continue };
        let read_ms = sw.ms();
        let sw = Stopwatch::start();
        let pre = preprocess(&calibration, &pre_config, &frame);
        let preprocess_ms = sw.ms();
        let sw = Stopwatch::start();
        let seg = reference::segment(&pre.levels, Some(&pre.depth_unfiltered_m), &config);
        let segment_ms = sw.ms();
        for (stage, ms) in [("read+decode", read_ms), ("preprocess", preprocess_ms), ("segment", segment_ms)] {
            times.record(stage, ms);
        }
        counts.push(seg.planes.len());
        if args.labels {
            let rgb: Vec<u8> = seg.labels.iter().flat_map(|&l| if l == NO_LABEL { [0, 0, 0] } else { label_colour(l) }).collect();
            let name = args.out.join(format!("labels/{}.png", format_timestamp_s(frame.depth_timestamp_ns)));
            std::fs::write(&name, png::encode_rgb8(&ColorImage::new(k.width_px, k.height_px, rgb)?)?).with_context(|| format!("writing {}", name.display()))?;
        }
        let planes: Vec<serde_json::Value> = seg
            .planes
            .iter()
            .map(|p| {
                serde_json::json!({
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
            "stages_ms": {"preprocess": preprocess_ms, "segment": segment_ms},
        }));
        eprint!("\rframe {index}: {} planes", seg.planes.len());
    }
    eprintln!();
    let json = serde_json::json!({
        "source": source.name(),
        "implementation": "cpu-reference",
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
    Ok(())
}
