// SPDX-License-Identifier: MIT
//! `webfusion synth-room`: renders the synthetic furnished room (`core::sim::room`) along its
//! loop into a `.wfr` recording with exact ground truth and exact depth (said in its header), for room-sized runs of the map (and any
//! command that reads a recording: `reconstruct`, `serve`, `eval`).

use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::io::trajectory::TimedPose;
use webfusion_core::recording::{RecordingOptions, RecordingWriter};
use webfusion_core::sim::room::SyntheticRoom;
use webfusion_core::source::DepthNoise;
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};

#[derive(clap::Args)]
pub(crate) struct SynthRoomArgs {
    /// The recording to write.
    #[arg(long)]
    out: PathBuf,
    /// Room size, metres: width (x), height (y), depth (z), comma-separated (`--size 4,2.5,4`).
    #[arg(long, value_delimiter = ',', default_values_t = [10.0, 3.0, 10.0])]
    size: Vec<f64>,
    /// Frames along the loop.
    #[arg(long, default_value_t = 600)]
    frames: usize,
    /// Image width, pixels (the focal length scales with it: TUM's 525 px at 640).
    #[arg(long, default_value_t = 640)]
    width: u32,
    /// Image height, pixels.
    #[arg(long, default_value_t = 480)]
    height: u32,
}

pub(crate) fn run(args: &SynthRoomArgs) -> anyhow::Result<()> {
    let [w, h, d] = <[f64; 3]>::try_from(args.size.as_slice()).map_err(|_| anyhow::anyhow!("--size takes three numbers (width, height, depth in metres), not {}", args.size.len()))?;
    anyhow::ensure!([w, h, d].iter().all(|s| s.is_finite() && *s >= 2.0), "--size {w},{h},{d}: a room of at least 2 m each way");
    anyhow::ensure!(args.frames >= 2, "--frames {}: a path needs at least 2", args.frames);
    anyhow::ensure!((16..=4096).contains(&args.width) && (16..=4096).contains(&args.height), "--width/--height {}x{} must be 16..=4096 pixels", args.width, args.height);
    let room = SyntheticRoom::new(w, h, d);
    let k = PinholeIntrinsics::nominal_kinect(args.width, args.height);
    let path = room.path(args.frames);
    let calibration = RgbdCalibration { intrinsics: k, depth_units_per_metre: 5000.0 };
    // The room's depth is exact (quantised to the TUM scale): a replay tracks and fuses it so.
    let options = RecordingOptions { depth_noise: DepthNoise::None, ..RecordingOptions::default() };
    let mut writer = RecordingWriter::create(&args.out, calibration, options).with_context(|| format!("creating {}", args.out.display()))?;
    let poses: Vec<TimedPose> = path.iter().enumerate().map(|(i, p)| TimedPose { timestamp_ns: i as i64 * 33_333_333, world_from_camera: *p }).collect();
    writer.set_ground_truth(&poses)?;
    let started = std::time::Instant::now();
    for i in 0..args.frames {
        writer.write_frame(&room.frame(&k, &path, i)).with_context(|| format!("writing frame {i}"))?;
        if i % 50 == 49 {
            eprint!("\rrendered {}/{} frames", i + 1, args.frames);
        }
    }
    let summary = writer.finish()?;
    eprintln!();
    println!("{}: a {w} x {h} x {d} m room, {} frames of {}x{} along a {:.1} m loop, rendered in {:.1} s ({} bytes)", args.out.display(), summary.frame_count, k.width_px, k.height_px, 2.0 * std::f64::consts::PI * 0.25 * w.min(d), started.elapsed().as_secs_f64(), std::fs::metadata(&args.out).map_or(0, |m| m.len()));
    Ok(())
}
