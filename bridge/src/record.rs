// SPDX-License-Identifier: MIT
//! `webfusion record`: converts a frame source (TUM RGB-D directory or `.wfr` recording) into
//! a `.wfr` recording, ground truth included.

use std::io::{IsTerminal as _, Write as _};
use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use webfusion_core::camera::TUM_DEPTH_UNITS_PER_METRE;
use webfusion_core::codec::{ColorCodec, DEFAULT_JPEG_QUALITY, DepthCodec};
use webfusion_core::recording::{RecordingOptions, RecordingReader, RecordingSummary, RecordingWriter, TakeStats};
use webfusion_core::source::{FrameSource, open_source};
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};

/// Image size assumed when `--intrinsics` gives only `fx,fy,cx,cy` (Kinect-class sensors).
const DEFAULT_WIDTH_PX: u32 = 640;
/// See [`DEFAULT_WIDTH_PX`].
const DEFAULT_HEIGHT_PX: u32 = 480;
/// Bytes per pixel of raw frames, for the compression ratio: 16-bit depth + RGB8 colour.
const RAW_DEPTH_BYTES_PER_PX: u64 = 2;
/// See [`RAW_DEPTH_BYTES_PER_PX`].
const RAW_COLOR_BYTES_PER_PX: u64 = 3;

/// Depth codec of the recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum DepthCodecArg {
    /// RVL, lossless, fastest.
    Rvl,
    /// RVL then DEFLATE, lossless, about 2x smaller.
    RvlDeflate,
}

/// Colour codec of the recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum ColorCodecArg {
    /// Lossy JPEG (see --jpeg-quality).
    Jpeg,
    /// Lossless PNG.
    Png,
}

/// A half-open range of frame indices; either end may be open.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct FrameRange {
    /// First frame, default 0.
    pub(crate) start: Option<usize>,
    /// One past the last frame, default the frame count.
    pub(crate) end: Option<usize>,
}

/// Arguments of `webfusion record`.
#[derive(Clone, Debug, clap::Args)]
pub(crate) struct RecordArgs {
    /// TUM RGB-D directory, .wfr recording, or (feature `openni2`) .oni recording or live
    /// camera: `openni2` (the first) or `openni2:<uri>` (see `webfusion devices`).
    #[arg(long, value_name = "PATH")]
    pub(crate) source: PathBuf,

    /// Recording to write (.wfr); written to FILE.partial first, then renamed.
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,

    /// Frames to convert, half-open: 10..20, 10.., ..20 [default: all].
    #[arg(long, value_name = "A..B", value_parser = parse_frame_range)]
    pub(crate) frames: Option<FrameRange>,

    /// Depth codec.
    #[arg(long, value_enum, default_value_t = DepthCodecArg::RvlDeflate)]
    pub(crate) depth_codec: DepthCodecArg,

    /// Colour codec.
    #[arg(long, value_enum, default_value_t = ColorCodecArg::Jpeg)]
    pub(crate) color_codec: ColorCodecArg,

    /// JPEG quality, 1..=100.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_JPEG_QUALITY, value_parser = clap::value_parser!(u8).range(1..=100))]
    pub(crate) jpeg_quality: u8,

    /// Override the intrinsics: fx,fy,cx,cy in pixels, optionally followed by width,height
    /// [default size: 640,480].
    #[arg(long, value_name = "FX,FY,CX,CY", value_parser = parse_intrinsics)]
    pub(crate) intrinsics: Option<PinholeIntrinsics>,

    /// Override the depth scale, in raw depth units per metre (TUM: 5000) [default with
    /// --intrinsics: 5000; otherwise the source's].
    #[arg(long, value_name = "UNITS_PER_METRE")]
    pub(crate) depth_scale: Option<f32>,

    /// Skip damaged frames of a recording source (counted) instead of stopping at the first.
    #[arg(long)]
    pub(crate) skip_corrupt: bool,

    /// Sync the file to disk (flush + sync_data) at least this often, milliseconds: a crash or
    /// power loss costs at most the frames since the last sync. 0: after every frame.
    #[arg(long, value_name = "MS", default_value_t = 1000)]
    pub(crate) sync_interval_ms: u64,
}

/// Runs `webfusion record`: progress on stderr, a summary on stdout.
pub(crate) fn run(args: &RecordArgs) -> anyhow::Result<()> {
    let calibration_override = calibration_override(args)?;
    let (mut source, frames) = match crate::live_spec(&args.source) {
        Some(uri) => {
            let Some(end) = args.frames.and_then(|f| f.end) else {
                bail!("recording a live camera needs --frames ..N (how many frames to record)");
            };
            let source: Box<dyn FrameSource> = Box::new(crate::LiveTake::new(crate::open_live(uri, calibration_override)?, end));
            (source, resolve_frame_range(args.frames, end)?)
        }
        None => {
            let source = crate::open_with(&args.source, calibration_override)?;
            let frames = resolve_frame_range(args.frames, source.frame_count())?;
            (source, frames)
        }
    };
    let color_codec = match args.color_codec {
        ColorCodecArg::Jpeg => ColorCodec::Jpeg,
        ColorCodecArg::Png => ColorCodec::Png,
    };
    let depth_codec = match args.depth_codec {
        DepthCodecArg::Rvl => DepthCodec::Rvl,
        DepthCodecArg::RvlDeflate => DepthCodec::RvlDeflate,
    };
    let options = RecordingOptions { depth_codec, color_codec, jpeg_quality: args.jpeg_quality, depth_noise: source.depth_noise() };
    let partial = partial_path(&args.out)?;
    let stop = stop_on_signals()?;
    let sync_interval = std::time::Duration::from_millis(args.sync_interval_ms);

    let mut skipped = Vec::new();
    let Take { summary, ended } = write_recording(source.as_mut(), frames.clone(), options, &partial, sync_interval, &stop, (args.skip_corrupt, &mut skipped))?;
    std::fs::rename(&partial, &args.out).with_context(|| format!("renaming {} to {}", partial.display(), args.out.display()))?;

    let k = source.calibration().intrinsics;
    print_summary(&args.out, &source.name(), frames, &summary, k.pixel_count() as u64, options);
    if !skipped.is_empty() {
        println!("  {}", crate::skipped_note(&skipped).trim_start_matches("; "));
    }
    match ended {
        Ended::AllFrames => Ok(()),
        Ended::Signal => {
            println!("stopped by a signal: {} is complete with the {} frames recorded", args.out.display(), summary.frame_count);
            Ok(())
        }
        Ended::Failed(error) => Err(error.context(format!("the take ended early; {} is complete with the {} frames written before", args.out.display(), summary.frame_count))),
    }
}

/// A flag set by SIGINT or SIGTERM (the take ends cleanly at the next frame). SIGXFSZ (a
/// file-size limit) is caught too, so a write past the limit fails with an error instead of
/// killing the process.
fn stop_on_signals() -> anyhow::Result<std::sync::Arc<std::sync::atomic::AtomicBool>> {
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        signal_hook::flag::register(signal, std::sync::Arc::clone(&stop)).context("installing a signal handler")?;
    }
    signal_hook::flag::register(signal_hook::consts::SIGXFSZ, std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false))).context("installing a signal handler")?;
    Ok(stop)
}

/// How a take ended.
enum Ended {
    AllFrames,
    /// SIGINT or SIGTERM.
    Signal,
    /// Reading the source or writing the file failed; the file holds what came before.
    Failed(anyhow::Error),
}

/// A finished recording and how its take ended.
struct Take {
    summary: RecordingSummary,
    ended: Ended,
}

/// Records `frames` of `source` into `out`, syncing at least every `sync_interval`; a signal,
/// a source error or a failed write (a full disk, a size limit) ends the take early with a
/// finished file holding every frame written (or what fits). Errors only when not even that
/// file can be written.
fn write_recording(
    source: &mut dyn FrameSource,
    frames: Range<usize>,
    options: RecordingOptions,
    out: &Path,
    sync_interval: std::time::Duration,
    stop: &std::sync::atomic::AtomicBool,
    (skip_corrupt, skipped): (bool, &mut Vec<usize>),
) -> anyhow::Result<Take> {
    let mut writer = RecordingWriter::create(out, source.calibration(), options)?;
    // Known before the first frame (a TUM or .wfr source): written at once, so it survives a
    // crash.
    if let Some(poses) = source.ground_truth() {
        writer.set_ground_truth(poses)?;
    }
    let take_start = std::time::Instant::now();
    let mut last_written = take_start;
    let total = frames.len();
    let mut stderr = std::io::stderr();
    // One updating line on a terminal; about ten lines in a log.
    let interactive = stderr.is_terminal();
    let log_every = total.div_ceil(10).max(1);
    let mut last_sync = std::time::Instant::now();
    let mut ended = Ended::AllFrames;
    let mut write_failed = false;
    for (done, index) in (1_usize..).zip(frames) {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            ended = Ended::Signal;
            break;
        }
        let frame = match crate::read_or_skip(source, index, skip_corrupt, skipped) {
            Ok(Some(frame)) => frame,
            Ok(None) => continue,
            Err(e) => {
                ended = Ended::Failed(e);
                break;
            }
        };
        let sync_due = last_sync.elapsed() >= sync_interval;
        if let Err(e) = writer.write_frame(&frame).and_then(|()| if sync_due { writer.sync() } else { Ok(()) }) {
            ended = Ended::Failed(anyhow::Error::new(e).context(format!("writing frame {index}")));
            write_failed = true;
            break;
        }
        last_written = std::time::Instant::now();
        if sync_due {
            last_sync = std::time::Instant::now();
            if !interactive {
                writeln!(stderr, "synced {} frames ({:.1} MB)", writer.frame_count(), writer.bytes_written() as f64 * 1e-6).ok();
            }
        }
        let progress = format!("recording frame {done}/{total} ({:.1} MB)", writer.bytes_written() as f64 * 1e-6);
        if interactive {
            write!(stderr, "\r{progress}").ok();
            stderr.flush().ok();
        } else if done.is_multiple_of(log_every) || done == total {
            writeln!(stderr, "{progress}").ok();
        }
    }
    if interactive {
        writeln!(stderr).ok();
    }
    let duration_ns = u64::try_from(last_written.duration_since(take_start).as_nanos()).unwrap_or(u64::MAX).max(1);
    let frames_dropped_by_source = u32::try_from(source.frames_dropped_by_source()).unwrap_or(u32::MAX);
    writer.set_take_stats(TakeStats { duration_ns, frames_dropped_by_source });
    let summary = if write_failed { writer.finish_keeping_what_fits()? } else { writer.finish()? };
    Ok(Take { summary, ended })
}

fn print_summary(
    out: &Path,
    source_name: &str,
    frames: Range<usize>,
    summary: &RecordingSummary,
    pixels_per_frame: u64,
    options: RecordingOptions,
) {
    let frame_count = summary.frame_count as u64;
    let raw_depth = frame_count * pixels_per_frame * RAW_DEPTH_BYTES_PER_PX;
    let raw_color = frame_count * pixels_per_frame * RAW_COLOR_BYTES_PER_PX;
    let ratio = |raw: u64, packed: u64| if packed == 0 { 0.0 } else { raw as f64 / packed as f64 };
    let mb = |bytes: u64| bytes as f64 * 1e-6;
    let color = match options.color_codec {
        ColorCodec::Jpeg => format!("JPEG q{}", options.jpeg_quality),
        other => other.name().to_uppercase(),
    };
    println!("wrote {} ({} frames {}..{} of {source_name})", out.display(), summary.frame_count, frames.start, frames.end);
    println!(
        "  file:   {} bytes = {:.2} MB, {:.1}:1 vs raw ({:.2} MB)",
        summary.total_bytes,
        mb(summary.total_bytes),
        ratio(raw_depth + raw_color, summary.total_bytes),
        mb(raw_depth + raw_color)
    );
    println!(
        "  depth:  {} {:.2} MB, {:.2}:1 vs raw 16-bit, {:.1} kB/frame",
        options.depth_codec.name(),
        mb(summary.depth_payload_bytes),
        ratio(raw_depth, summary.depth_payload_bytes),
        summary.depth_payload_bytes as f64 / frame_count.max(1) as f64 * 1e-3
    );
    println!(
        "  colour: {color} {:.2} MB, {:.1}:1 vs raw RGB8, {:.1} kB/frame",
        mb(summary.color_payload_bytes),
        ratio(raw_color, summary.color_payload_bytes),
        summary.color_payload_bytes as f64 / frame_count.max(1) as f64 * 1e-3
    );
    println!("  ground truth: {} poses", summary.ground_truth_pose_count);
    if let Some(take) = summary.take {
        println!(
            "  take:   {:.2} s, {:.1} frames/s written, {} frames dropped by the source",
            take.duration_ns as f64 * 1e-9,
            take.frames_per_second(summary.frame_count).unwrap_or(0.0),
            take.frames_dropped_by_source
        );
    }
}

/// The calibration to impose on the source, from `--intrinsics` and `--depth-scale`.
fn calibration_override(args: &RecordArgs) -> anyhow::Result<Option<RgbdCalibration>> {
    if let Some(scale) = args.depth_scale
        && !(scale.is_finite() && scale > 0.0)
    {
        bail!("--depth-scale must be a positive number of depth units per metre, got {scale}");
    }
    Ok(match (args.intrinsics, args.depth_scale) {
        (None, None) => None,
        (Some(intrinsics), scale) => {
            Some(RgbdCalibration { intrinsics, depth_units_per_metre: scale.unwrap_or(TUM_DEPTH_UNITS_PER_METRE) })
        }
        (None, Some(depth_units_per_metre)) => {
            let source = open_source(&args.source, None)
                .with_context(|| format!("reading the calibration of {} to change its depth scale", args.source.display()))?;
            Some(RgbdCalibration { depth_units_per_metre, ..source.calibration() })
        }
    })
}

/// `FILE.partial` next to `out`.
fn partial_path(out: &Path) -> anyhow::Result<PathBuf> {
    let Some(name) = out.file_name() else { bail!("--out {} does not name a file", out.display()) };
    let mut partial = name.to_os_string();
    partial.push(".partial");
    Ok(out.with_file_name(partial))
}

fn resolve_frame_range(range: Option<FrameRange>, frame_count: usize) -> anyhow::Result<Range<usize>> {
    let range = range.unwrap_or(FrameRange { start: None, end: None });
    let (start, end) = (range.start.unwrap_or(0), range.end.unwrap_or(frame_count));
    if start >= end || end > frame_count {
        bail!("--frames {start}..{end} is empty or outside the source's {frame_count} frames");
    }
    Ok(start..end)
}

fn parse_frame_range(text: &str) -> Result<FrameRange, String> {
    let (start, end) = text.split_once("..").ok_or_else(|| format!("expected A..B, A.. or ..B, got {text:?}"))?;
    let bound = |s: &str| -> Result<Option<usize>, String> {
        if s.is_empty() { Ok(None) } else { s.parse().map(Some).map_err(|_| format!("{s:?} is not a frame index")) }
    };
    Ok(FrameRange { start: bound(start)?, end: bound(end)? })
}

fn parse_intrinsics(text: &str) -> Result<PinholeIntrinsics, String> {
    let fields: Vec<&str> = text.split(',').map(str::trim).collect();
    if fields.len() != 4 && fields.len() != 6 {
        return Err(format!("expected fx,fy,cx,cy or fx,fy,cx,cy,width,height, got {text:?}"));
    }
    let number = |s: &str| -> Result<f32, String> {
        s.parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("{s:?} is not a number"))
    };
    let size = |s: &str| -> Result<u32, String> {
        s.parse::<u32>().ok().filter(|&v| v > 0).ok_or_else(|| format!("{s:?} is not a positive pixel count"))
    };
    let (width_px, height_px) =
        if fields.len() == 6 { (size(fields[4])?, size(fields[5])?) } else { (DEFAULT_WIDTH_PX, DEFAULT_HEIGHT_PX) };
    let intrinsics = PinholeIntrinsics {
        fx_px: number(fields[0])?,
        fy_px: number(fields[1])?,
        cx_px: number(fields[2])?,
        cy_px: number(fields[3])?,
        width_px,
        height_px,
    };
    if intrinsics.fx_px <= 0.0 || intrinsics.fy_px <= 0.0 {
        return Err(format!("focal lengths must be positive, got {text:?}"));
    }
    Ok(intrinsics)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_frame_ranges() {
        assert_eq!(parse_frame_range("10..20"), Ok(FrameRange { start: Some(10), end: Some(20) }), "closed");
        assert_eq!(parse_frame_range("10.."), Ok(FrameRange { start: Some(10), end: None }), "open end");
        assert_eq!(parse_frame_range("..5"), Ok(FrameRange { start: None, end: Some(5) }), "open start");
        assert!(parse_frame_range("10").is_err(), "no dots");
        assert!(parse_frame_range("a..b").is_err(), "not numbers");
        assert_eq!(resolve_frame_range(None, 100).expect("all"), 0..100, "default");
        assert_eq!(resolve_frame_range(parse_frame_range("..5").ok(), 100).expect("prefix"), 0..5, "prefix");
        assert!(resolve_frame_range(parse_frame_range("5..5").ok(), 100).is_err(), "empty");
        assert!(resolve_frame_range(parse_frame_range("90..101").ok(), 100).is_err(), "past the end");
    }

    #[test]
    fn parses_intrinsics() {
        let k = parse_intrinsics("517.3,516.5,318.6,255.3").expect("four values");
        assert_eq!((k.fx_px, k.cy_px, k.width_px, k.height_px), (517.3, 255.3, 640, 480), "default size");
        let k = parse_intrinsics("100, 100, 80, 60, 160, 120").expect("six values");
        assert_eq!((k.width_px, k.height_px), (160, 120), "explicit size");
        assert!(parse_intrinsics("1,2,3").is_err(), "too few");
        assert!(parse_intrinsics("1,2,3,x").is_err(), "not a number");
        assert!(parse_intrinsics("-1,2,3,4").is_err(), "negative focal length");
        assert!(parse_intrinsics("1,2,3,4,0,480").is_err(), "zero width");
    }

    #[test]
    fn partial_path_appends_a_suffix() {
        assert_eq!(partial_path(Path::new("data/x.wfr")).expect("file"), Path::new("data/x.wfr.partial"), "suffix");
        assert!(partial_path(Path::new("/")).is_err(), "no file name");
    }
}

/// Arguments of `webfusion repair`.
#[derive(Clone, Debug, clap::Args)]
pub(crate) struct RepairArgs {
    /// The recording to recover (an unfinished `.wfr.partial`, or a damaged `.wfr`).
    #[arg(value_name = "IN")]
    pub(crate) input: PathBuf,

    /// The finished recording to write; written to FILE.partial first, then renamed.
    #[arg(long, value_name = "FILE")]
    pub(crate) out: PathBuf,
}

/// `webfusion repair`: scans `IN` for every complete, CRC-checked record (and the ground truth,
/// if its block survived) and writes them, bytes unchanged, into a finished recording.
pub(crate) fn repair(args: &RepairArgs) -> anyhow::Result<()> {
    let same = |a: &Path, b: &Path| a.canonicalize().ok().zip(b.canonicalize().ok()).is_some_and(|(a, b)| a == b);
    if same(&args.input, &args.out) {
        bail!("--out {} is the input: write the repaired copy somewhere else", args.out.display());
    }
    let mut reader = RecordingReader::open_recovering(&args.input).with_context(|| format!("opening {}", args.input.display()))?;
    match reader.recovery() {
        Some(report) => eprintln!("{}: {report}", args.input.display()),
        None => eprintln!("{}: intact ({} frames); writing a copy", args.input.display(), reader.frame_count()),
    }
    let options = RecordingOptions { depth_codec: reader.depth_codec(), color_codec: reader.color_codec(), depth_noise: reader.depth_noise(), ..RecordingOptions::default() };
    let partial = partial_path(&args.out)?;
    let written = (|| -> anyhow::Result<RecordingSummary> {
        let mut writer = RecordingWriter::create(&partial, reader.calibration(), options)?;
        // Ground truth first: it survives even if this copy is interrupted too.
        if let Some(poses) = reader.ground_truth() {
            writer.set_ground_truth(poses)?;
        }
        if let Some(take) = reader.take_stats() {
            writer.set_take_stats(take);
        }
        for i in 0..reader.frame_count() {
            writer.write_encoded_frame(&reader.read_encoded_frame(i)?)?;
        }
        Ok(writer.finish()?)
    })();
    let summary = match written {
        Ok(summary) => summary,
        Err(e) => {
            std::fs::remove_file(&partial).ok();
            return Err(e.context(format!("writing {}", partial.display())));
        }
    };
    std::fs::rename(&partial, &args.out).with_context(|| format!("renaming {} to {}", partial.display(), args.out.display()))?;
    let report = reader.recovery();
    println!(
        "wrote {}: {} frames, {} ground-truth poses, {} bytes ({} damaged records dropped, {} bytes of unfinished tail dropped)",
        args.out.display(),
        summary.frame_count,
        summary.ground_truth_pose_count,
        summary.total_bytes,
        report.map_or(0, |r| r.records_dropped),
        report.map_or(0, |r| r.tail_bytes_dropped),
    );
    Ok(())
}
