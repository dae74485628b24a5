// SPDX-License-Identifier: MIT
//! TUM RGB-D benchmark directories (Sturm et al., IROS 2012).
//!
//! A directory holds `rgb.txt` and `depth.txt` (`timestamp filename` per line), the PNGs they
//! name (colour RGB8, depth 16-bit with 5000 units per metre) and, for most sequences,
//! `groundtruth.txt`. Depth and colour are captured at slightly different times; they are
//! paired the way the benchmark's `associate.py` does it.
//!
//! Directories webfusion writes (`simulate`) may also hold [`CALIBRATION_FILE`], which the
//! reader takes before any calibration named by the path, and may hold depth only (no
//! `rgb.txt`: every frame's colour is black, its timestamp the depth's).

use std::path::{Component, Path, PathBuf};

use super::data_fields;
use super::parse_timestamp_ns;
use super::format_timestamp_s;
use super::trajectory::{TimedPose, read_tum_trajectory, write_tum_trajectory};
use crate::camera::{TUM_DEPTH_UNITS_PER_METRE, TUM_FREIBURG1, TUM_FREIBURG2, TUM_FREIBURG3};
use crate::codec::png;
use crate::source::{DepthNoise, FrameSource};
use crate::{Error, Result, RgbdCalibration, RgbdFrame};

/// Default largest time difference between a depth image and the colour image paired with it:
/// 20 ms, as in the benchmark's tools.
pub const DEFAULT_MAX_TIME_DIFFERENCE_NS: i64 = 20_000_000;

/// How to open a TUM directory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TumOptions {
    /// Depth and colour images are paired only if their timestamps differ by less than this.
    pub max_time_difference_ns: i64,
    /// Calibration to use instead of the one recognised from the directory name.
    pub calibration_override: Option<RgbdCalibration>,
}

impl Default for TumOptions {
    fn default() -> Self {
        Self { max_time_difference_ns: DEFAULT_MAX_TIME_DIFFERENCE_NS, calibration_override: None }
    }
}

/// The files of one associated depth/colour pair.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TumFrameFiles {
    /// Depth timestamp, nanoseconds since the Unix epoch.
    pub depth_timestamp_ns: i64,
    /// Depth PNG.
    pub depth_path: PathBuf,
    /// Colour timestamp, nanoseconds since the Unix epoch.
    pub color_timestamp_ns: i64,
    /// Colour PNG (`None` in a depth-only directory: the colour is black).
    pub color_path: Option<PathBuf>,
}

/// A TUM RGB-D sequence on disk, as a [`FrameSource`] of its associated frames.
#[derive(Clone, Debug)]
pub struct TumDataset {
    dir: PathBuf,
    name: String,
    calibration: RgbdCalibration,
    /// The depth images hold distances along each pixel's ray (converted to depth along z on
    /// reading).
    radial_depth: bool,
    /// What its calibration file says of the depth's noise (a Kinect's without one).
    depth_noise: DepthNoise,
    frames: Vec<TumFrameFiles>,
    ground_truth: Option<Vec<TimedPose>>,
}

impl TumDataset {
    /// Opens a TUM directory with default [`TumOptions`] and an optional calibration override.
    pub fn open(dir: impl AsRef<Path>, calibration_override: Option<RgbdCalibration>) -> Result<Self> {
        Self::open_with(dir, TumOptions { calibration_override, ..TumOptions::default() })
    }

    /// Opens a TUM directory: reads the image lists and the ground truth, pairs depth with
    /// colour, and settles the calibration. Images are read later, by [`FrameSource::read_frame`].
    ///
    /// Without an override the calibration comes from the directory's [`CALIBRATION_FILE`],
    /// else from the path: the nearest path component (the directory itself first, then its
    /// parents; symlinks resolved, else as given) naming `freiburg1`/`fr1`, 2 or 3 selects the
    /// published calibration; otherwise this is [`Error::UnknownCalibration`].
    pub fn open_with(dir: impl AsRef<Path>, options: TumOptions) -> Result<Self> {
        let dir = dir.as_ref();
        if options.max_time_difference_ns <= 0 {
            return Err(Error::InvalidConfig(format!("max_time_difference_ns must be positive, got {}", options.max_time_difference_ns)));
        }
        // The resolved path names `.` and `..`; the path as given names symlinks.
        let resolved_dir = std::fs::canonicalize(dir).map_err(|source| Error::Io { path: dir.to_owned(), source })?;
        let name = dir
            .file_name()
            .or(resolved_dir.file_name())
            .map_or_else(|| resolved_dir.display().to_string(), |n| n.to_string_lossy().into_owned());
        let file = dir.join(CALIBRATION_FILE);
        let written = if file.is_file() { Some(read_calibration_file(&file)?) } else { None };
        let radial_depth = written.is_some_and(|w| w.radial_depth);
        let depth_noise = written.map_or(DepthNoise::KinectV1, |w| w.depth_noise);
        let calibration = match (options.calibration_override, written) {
            (Some(calibration), _) => calibration,
            (None, Some(w)) => w.calibration,
            (None, None) => calibration_from_path(&resolved_dir)
                .or_else(|| calibration_from_path(dir))
                .ok_or_else(|| Error::UnknownCalibration { source_name: dir.display().to_string() })?,
        };
        let depth_list = read_image_list(&dir.join("depth.txt"))?;
        let rgb_list = dir.join("rgb.txt");
        if !rgb_list.is_file() && written.is_some() {
            let frames = depth_list
                .into_iter()
                .map(|(t, name)| TumFrameFiles { depth_timestamp_ns: t, depth_path: dir.join(name), color_timestamp_ns: t, color_path: None })
                .collect();
            let ground_truth_path = dir.join("groundtruth.txt");
            let ground_truth = if ground_truth_path.is_file() { Some(read_tum_trajectory(&ground_truth_path)?) } else { None };
            return Ok(Self { dir: dir.to_owned(), name, calibration, radial_depth, depth_noise, frames, ground_truth });
        }
        let color_list = read_image_list(&rgb_list)?;
        let depth_timestamps: Vec<i64> = depth_list.iter().map(|(t, _)| *t).collect();
        let color_timestamps: Vec<i64> = color_list.iter().map(|(t, _)| *t).collect();
        let pairs = associate(&depth_timestamps, &color_timestamps, options.max_time_difference_ns);
        if pairs.is_empty() {
            return Err(Error::Dataset {
                path: dir.to_owned(),
                message: format!(
                    "no depth image ({} listed) has a colour image ({} listed) within {} ms",
                    depth_list.len(),
                    color_list.len(),
                    options.max_time_difference_ns as f64 * 1e-6
                ),
            });
        }
        let frames = pairs
            .into_iter()
            .map(|(depth_ix, color_ix)| TumFrameFiles {
                depth_timestamp_ns: depth_list[depth_ix].0,
                depth_path: dir.join(&depth_list[depth_ix].1),
                color_timestamp_ns: color_list[color_ix].0,
                color_path: Some(dir.join(&color_list[color_ix].1)),
            })
            .collect();
        let ground_truth_path = dir.join("groundtruth.txt");
        let ground_truth = if ground_truth_path.is_file() { Some(read_tum_trajectory(&ground_truth_path)?) } else { None };
        Ok(Self { dir: dir.to_owned(), name, calibration, radial_depth, depth_noise, frames, ground_truth })
    }

    /// The directory, as given to `open`.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The associated pairs, sorted by depth timestamp.
    pub fn frames(&self) -> &[TumFrameFiles] {
        &self.frames
    }
}

impl FrameSource for TumDataset {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn calibration(&self) -> RgbdCalibration {
        self.calibration
    }

    fn depth_noise(&self) -> DepthNoise {
        self.depth_noise
    }

    fn frame_count(&self) -> usize {
        self.frames.len()
    }

    fn read_frame(&mut self, index: usize) -> Result<RgbdFrame> {
        let files = self.frames.get(index).ok_or_else(|| Error::Dataset {
            path: self.dir.clone(),
            message: format!("frame {index} does not exist ({} frames)", self.frames.len()),
        })?;
        let (width_px, height_px) = (self.calibration.intrinsics.width_px, self.calibration.intrinsics.height_px);
        let depth_bytes = read_file(&files.depth_path)?;
        let mut depth = png::decode_depth16(&depth_bytes, width_px, height_px).map_err(|e| image_error(&files.depth_path, e))?;
        if self.radial_depth {
            radial_to_planar(&mut depth.units, &self.calibration.intrinsics);
        }
        let color = match &files.color_path {
            Some(path) => {
                let color_bytes = read_file(path)?;
                png::decode_rgb8(&color_bytes, width_px, height_px).map_err(|e| image_error(path, e))?
            }
            None => crate::ColorImage::new(width_px, height_px, vec![0; 3 * width_px as usize * height_px as usize])?,
        };
        Ok(RgbdFrame {
            index: index as u64,
            depth_timestamp_ns: files.depth_timestamp_ns,
            color_timestamp_ns: files.color_timestamp_ns,
            depth,
            color,
        })
    }

    fn ground_truth(&self) -> Option<&[TimedPose]> {
        self.ground_truth.as_deref()
    }

    fn frame_timestamp_ns(&mut self, index: usize) -> Result<i64> {
        self.frames.get(index).map(|f| f.depth_timestamp_ns).ok_or_else(|| Error::Dataset { path: self.dir.clone(), message: format!("frame {index} does not exist ({} frames)", self.frames.len()) })
    }
}

/// Writes frames `frames` of `source` as a TUM RGB-D directory at `dir` (created if missing;
/// files it would write must not exist yet): `depth/<t>.png` (16-bit, the source's depth units),
/// `rgb/<t>.png`, `depth.txt`, `rgb.txt` (named by each image's own timestamp, so
/// [`TumDataset`] pairs them back as they were) and, when the source has ground truth,
/// `groundtruth.txt` (every pose of the source). Returns the number of frames written.
///
/// The directory carries no calibration: [`TumDataset::open`] finds it from a path that names
/// the camera (`..._freiburg1_...`) or takes an override. An image file that exists already
/// (two frames with one timestamp, or a directory written before) is [`Error::InvalidConfig`].
pub fn write_tum_dataset(dir: &Path, source: &mut dyn FrameSource, frames: std::ops::Range<usize>) -> Result<usize> {
    if frames.end > source.frame_count() || frames.start > frames.end {
        return Err(Error::InvalidConfig(format!("frames {frames:?} are not within the source's {} frames", source.frame_count())));
    }
    let mut depth = ImageListWriter::create(dir, "depth", "# depth images")?;
    let mut rgb = ImageListWriter::create(dir, "rgb", "# colour images")?;
    for index in frames.clone() {
        let frame = source.read_frame(index)?;
        depth.write(index, frame.depth_timestamp_ns, &png::encode_depth16(&frame.depth)?)?;
        rgb.write(index, frame.color_timestamp_ns, &png::encode_rgb8(&frame.color)?)?;
    }
    depth.finish()?;
    rgb.finish()?;
    if let Some(poses) = source.ground_truth() {
        write_tum_trajectory(&dir.join("groundtruth.txt"), poses)?;
    }
    Ok(frames.len())
}

/// One image folder of a TUM directory being written (`<dir>/<sub>/<t>.png`), and its list file
/// `<dir>/<sub>.txt`, written by [`ImageListWriter::finish`].
pub struct ImageListWriter {
    dir: PathBuf,
    sub: &'static str,
    list: String,
}

impl ImageListWriter {
    /// Creates `<dir>/<sub>/`; `header` is the list file's first comment line.
    pub fn create(dir: &Path, sub: &'static str, header: &str) -> Result<Self> {
        let folder = dir.join(sub);
        std::fs::create_dir_all(&folder).map_err(|source| Error::Io { path: folder, source })?;
        Ok(Self { dir: dir.to_owned(), sub, list: format!("{header}\n# timestamp filename\n") })
    }

    /// Writes `<sub>/<t>.png` (never over an existing file) and lists it; returns the name
    /// relative to the directory. `index` names the frame in the error for an existing file.
    pub fn write(&mut self, index: usize, timestamp_ns: i64, png_bytes: &[u8]) -> Result<String> {
        use std::io::Write as _;
        let name = format!("{}/{}.png", self.sub, format_timestamp_s(timestamp_ns));
        let path = self.dir.join(&name);
        let io_error = |source| Error::Io { path: path.clone(), source };
        let mut file = std::fs::OpenOptions::new().write(true).create_new(true).open(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::AlreadyExists => {
                Error::InvalidConfig(format!("frame {index}: {} exists already (a repeated timestamp, or a directory written before)", path.display()))
            }
            _ => io_error(e),
        })?;
        file.write_all(png_bytes).map_err(io_error)?;
        self.list.push_str(&format!("{} {name}\n", format_timestamp_s(timestamp_ns)));
        Ok(name)
    }

    /// Writes the list file.
    pub fn finish(self) -> Result<()> {
        let path = self.dir.join(format!("{}.txt", self.sub));
        std::fs::write(&path, &self.list).map_err(|source| Error::Io { path, source })
    }
}

fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|source| Error::Io { path: path.to_owned(), source })
}

/// Turns a codec error into an image error that names the file.
fn image_error(path: &Path, error: Error) -> Error {
    match error {
        Error::Codec { message, .. } => Error::ImageDecode { path: path.to_owned(), message },
        other => other,
    }
}

/// Reads `rgb.txt` or `depth.txt`: `timestamp filename` per data line.
fn read_image_list(path: &Path) -> Result<Vec<(i64, String)>> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    let mut entries = Vec::new();
    for (line_ix, line) in text.lines().enumerate() {
        let Some(fields) = data_fields(line) else { continue };
        let parse_error = |message: String| Error::Parse { path: path.to_owned(), line: line_ix + 1, message };
        let [timestamp, filename] = fields[..] else {
            return Err(parse_error(format!("expected 2 fields `timestamp filename`, found {}", fields.len())));
        };
        let timestamp_ns = parse_timestamp_ns(timestamp)
            .ok_or_else(|| parse_error(format!("invalid timestamp {timestamp:?}: expected decimal seconds")))?;
        entries.push((timestamp_ns, filename.to_owned()));
    }
    Ok(entries)
}

/// Pairs depth with colour timestamps like the benchmark's `associate.py`: all pairs closer
/// than `max_difference_ns` are candidates; the closest candidate is taken first and each
/// timestamp is used at most once. Ties go to the earlier depth, then the earlier colour
/// timestamp. Returns `(depth_ix, color_ix)` sorted by depth timestamp. Any two timestamp lists
/// pair the same way (`webfusion compare` pairs simulated with real depth by it).
pub fn associate(depth_ns: &[i64], color_ns: &[i64], max_difference_ns: i64) -> Vec<(usize, usize)> {
    let max_difference = max_difference_ns.unsigned_abs();
    let mut color_order: Vec<usize> = (0..color_ns.len()).collect();
    color_order.sort_by_key(|&ix| (color_ns[ix], ix));
    let mut candidates: Vec<(u64, i64, i64, usize, usize)> = Vec::new();
    for (depth_ix, &t_depth) in depth_ns.iter().enumerate() {
        let first = color_order.partition_point(|&ix| t_depth.abs_diff(color_ns[ix]) >= max_difference && color_ns[ix] < t_depth);
        for &color_ix in &color_order[first..] {
            let t_color = color_ns[color_ix];
            let difference = t_depth.abs_diff(t_color);
            if difference >= max_difference {
                if t_color > t_depth {
                    break;
                }
                continue;
            }
            candidates.push((difference, t_depth, t_color, depth_ix, color_ix));
        }
    }
    candidates.sort_unstable();
    let mut depth_used = vec![false; depth_ns.len()];
    let mut color_used = vec![false; color_ns.len()];
    let mut pairs = Vec::new();
    for (_, _, _, depth_ix, color_ix) in candidates {
        if !depth_used[depth_ix] && !color_used[color_ix] {
            depth_used[depth_ix] = true;
            color_used[color_ix] = true;
            pairs.push((depth_ix, color_ix));
        }
    }
    pairs.sort_unstable_by_key(|&(depth_ix, color_ix)| (depth_ns[depth_ix], color_ns[color_ix], depth_ix, color_ix));
    pairs
}

/// The calibration file of a directory webfusion wrote: `key value` lines (`#` comments):
/// `fx_px`, `fy_px`, `cx_px`, `cy_px` (pixels, pixel centres at integer coordinates),
/// `width_px`, `height_px`, `depth_units_per_metre`, `depth` (`planar`: along the camera's z,
/// the TUM convention; `radial`: along each pixel's ray) and, optionally, `depth_noise`
/// (`kinect`, the default: a Kinect v1's noise; `none`: exact depth, as `simulate` renders
/// without `--noise`).
pub const CALIBRATION_FILE: &str = "calibration.txt";

/// What a [`CALIBRATION_FILE`] says.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WrittenCalibration {
    /// The camera and depth scale.
    pub calibration: RgbdCalibration,
    /// The depth images hold distances along each ray.
    pub radial_depth: bool,
    /// The noise of the depth images.
    pub depth_noise: DepthNoise,
}

/// The text of a [`CALIBRATION_FILE`].
pub fn format_calibration_file(w: &WrittenCalibration) -> String {
    let k = &w.calibration.intrinsics;
    format!(
        "# webfusion camera calibration: pinhole, pixel centres at integer coordinates\nfx_px {}\nfy_px {}\ncx_px {}\ncy_px {}\nwidth_px {}\nheight_px {}\ndepth_units_per_metre {}\ndepth {}\ndepth_noise {}\n",
        k.fx_px,
        k.fy_px,
        k.cx_px,
        k.cy_px,
        k.width_px,
        k.height_px,
        w.calibration.depth_units_per_metre,
        if w.radial_depth { "radial" } else { "planar" },
        w.depth_noise.name()
    )
}

/// Reads a [`CALIBRATION_FILE`]; every key must be present once, with a valid value.
pub fn read_calibration_file(path: &Path) -> Result<WrittenCalibration> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    parse_calibration_file(&text, path)
}

/// Parses the text of a [`CALIBRATION_FILE`] (`path` names it in errors).
pub fn parse_calibration_file(text: &str, path: &Path) -> Result<WrittenCalibration> {
    const KEYS: [&str; 9] = ["fx_px", "fy_px", "cx_px", "cy_px", "width_px", "height_px", "depth_units_per_metre", "depth", "depth_noise"];
    let mut values: [Option<&str>; 9] = [None; 9];
    for (line_ix, line) in text.lines().enumerate() {
        let Some(fields) = data_fields(line) else { continue };
        let parse_error = |message: String| Error::Parse { path: path.to_owned(), line: line_ix + 1, message };
        let [key, value] = fields[..] else {
            return Err(parse_error(format!("expected `key value`, found {} fields", fields.len())));
        };
        let slot = KEYS.iter().position(|k| *k == key).ok_or_else(|| parse_error(format!("unknown key {key:?} (expected one of {})", KEYS.join(", "))))?;
        if values[slot].replace(value).is_some() {
            return Err(parse_error(format!("{key} is given twice")));
        }
    }
    let bad = |message: String| Error::Parse { path: path.to_owned(), line: 0, message };
    let get = |i: usize| values[i].ok_or_else(|| bad(format!("{} is missing", KEYS[i])));
    let positive = |i: usize| -> Result<f32> {
        let v = get(i)?;
        v.parse::<f32>().ok().filter(|x| x.is_finite() && (*x > 0.0 || (i == 2 || i == 3))).ok_or_else(|| bad(format!("{} {v:?} is not a valid number", KEYS[i])))
    };
    let size = |i: usize| -> Result<u32> {
        let v = get(i)?;
        v.parse::<u32>().ok().filter(|&x| x > 0).ok_or_else(|| bad(format!("{} {v:?} is not a positive whole number of pixels", KEYS[i])))
    };
    let radial_depth = match get(7)? {
        "planar" => false,
        "radial" => true,
        other => return Err(bad(format!("depth {other:?}: expected planar or radial"))),
    };
    // Optional (files written before it had none: a Kinect's noise, what they were read with).
    let depth_noise = match values[8] {
        None => DepthNoise::KinectV1,
        Some(v) => DepthNoise::from_name(v).ok_or_else(|| bad(format!("depth_noise {v:?}: expected kinect or none")))?,
    };
    let intrinsics = crate::PinholeIntrinsics { fx_px: positive(0)?, fy_px: positive(1)?, cx_px: positive(2)?, cy_px: positive(3)?, width_px: size(4)?, height_px: size(5)? };
    Ok(WrittenCalibration { calibration: RgbdCalibration { intrinsics, depth_units_per_metre: positive(6)? }, radial_depth, depth_noise })
}

/// Distances along each pixel's ray to depths along z, in place (raw units, rounded).
fn radial_to_planar(units: &mut [u16], k: &crate::PinholeIntrinsics) {
    let w = k.width_px as usize;
    for (i, u) in units.iter_mut().enumerate() {
        if *u == 0 {
            continue;
        }
        let rx = ((i % w) as f64 - f64::from(k.cx_px)) / f64::from(k.fx_px);
        let ry = ((i / w) as f64 - f64::from(k.cy_px)) / f64::from(k.fy_px);
        *u = (f64::from(*u) / (rx * rx + ry * ry + 1.0).sqrt()).round() as u16;
    }
}

/// The published calibration named by the nearest path component that mentions exactly one
/// of `freiburg1`/`fr1`, `freiburg2`/`fr2`, `freiburg3`/`fr3` (case-insensitive).
fn calibration_from_path(dir: &Path) -> Option<RgbdCalibration> {
    const CAMERAS: [(&str, &str, crate::PinholeIntrinsics); 3] =
        [("freiburg1", "fr1", TUM_FREIBURG1), ("freiburg2", "fr2", TUM_FREIBURG2), ("freiburg3", "fr3", TUM_FREIBURG3)];
    for component in dir.components().rev() {
        let Component::Normal(name) = component else { continue };
        let name = name.to_string_lossy().to_lowercase();
        let mut matches = CAMERAS.iter().filter(|(long, short, _)| name.contains(long) || name.contains(short));
        match (matches.next(), matches.next()) {
            (Some((_, _, intrinsics)), None) => {
                return Some(RgbdCalibration { intrinsics: *intrinsics, depth_units_per_metre: TUM_DEPTH_UNITS_PER_METRE });
            }
            (Some(_), Some(_)) => return None,
            (None, _) => {}
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{SAMPLE_RECORDING, ScratchDir, sample_as_tum, shared_tum_fr1_rpy_dir};
    use crate::recording::RecordingReader;
    use crate::{ColorImage, DepthImage, PinholeIntrinsics};

    #[test]
    fn associates_greedily_by_smallest_difference() {
        // Colour 6 is 6 from depth 0 and 4 from depth 10: depth 10 wins; depth 0 takes colour -3.
        assert_eq!(associate(&[0, 10], &[6, -3], 20), vec![(0, 1), (1, 0)], "greedy by difference");
        // Strictly less than the tolerance.
        assert_eq!(associate(&[0], &[20], 20), vec![], "difference equal to the tolerance");
        assert_eq!(associate(&[0], &[19], 20), vec![(0, 0)], "difference below the tolerance");
        // One-to-one: the second depth gets nothing.
        assert_eq!(associate(&[0, 1], &[0], 20), vec![(0, 0)], "one to one");
        // Output sorted by depth time, whatever the input order.
        assert_eq!(associate(&[100, 0, 50], &[49, 101, 2], 20), vec![(1, 2), (2, 0), (0, 1)], "sorted by depth time");
        // Extreme timestamps do not overflow.
        assert_eq!(associate(&[i64::MIN, i64::MAX], &[i64::MAX - 1, i64::MIN + 1], 20), vec![(0, 1), (1, 0)], "extremes");
    }

    #[test]
    fn association_matches_a_brute_force_reference() {
        let mut state = 12_345_u64;
        let mut next = move |n: u64| {
            state = state.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1_442_695_040_888_963_407);
            (state >> 33) % n
        };
        for _ in 0..200 {
            let depth: Vec<i64> = (0..next(30)).map(|_| next(1000) as i64).collect();
            let color: Vec<i64> = (0..next(30)).map(|_| next(1000) as i64).collect();
            let max = 1 + next(60) as i64;
            let mut candidates = Vec::new();
            for (d, &td) in depth.iter().enumerate() {
                for (c, &tc) in color.iter().enumerate() {
                    if td.abs_diff(tc) < max as u64 {
                        candidates.push((td.abs_diff(tc), td, tc, d, c));
                    }
                }
            }
            candidates.sort_unstable();
            let (mut used_d, mut used_c, mut want) = (vec![false; depth.len()], vec![false; color.len()], Vec::new());
            for (_, _, _, d, c) in candidates {
                if !used_d[d] && !used_c[c] {
                    used_d[d] = true;
                    used_c[c] = true;
                    want.push((d, c));
                }
            }
            want.sort_unstable_by_key(|&(d, c)| (depth[d], color[c], d, c));
            assert_eq!(associate(&depth, &color, max), want, "depth {depth:?} colour {color:?} max {max}");
        }
    }

    #[test]
    fn recognises_freiburg_cameras_from_the_path() {
        let fr = |p: &str| calibration_from_path(Path::new(p)).map(|c| c.intrinsics);
        assert_eq!(fr("/data/rgbd_dataset_freiburg1_rpy"), Some(TUM_FREIBURG1), "freiburg1");
        assert_eq!(fr("/data/tum_fr2_desk"), Some(TUM_FREIBURG2), "fr2");
        assert_eq!(fr("/data/FR3/office/seq"), Some(TUM_FREIBURG3), "parent FR3");
        assert_eq!(fr("/data/fr3/rgbd_dataset_freiburg1_xyz"), Some(TUM_FREIBURG1), "nearest component wins");
        assert_eq!(fr("/data/my_sequence"), None, "unknown");
        assert_eq!(fr("/data/fr1_vs_fr2"), None, "ambiguous");
        let calibration = calibration_from_path(Path::new("/x/fr1")).expect("fr1");
        assert_eq!(calibration.depth_units_per_metre, TUM_DEPTH_UNITS_PER_METRE, "TUM depth units");
    }

    /// Expected pairs from the benchmark's own `rgbd_assoc.txt`: `ts_rgb rgb ts_depth depth`.
    fn reference_association(dir: &Path) -> Vec<(i64, String, i64, String)> {
        let text = std::fs::read_to_string(dir.join("rgbd_assoc.txt")).expect("reading rgbd_assoc.txt");
        text.lines()
            .filter_map(data_fields)
            .map(|f| {
                let ts = |s: &str| parse_timestamp_ns(s).expect("timestamp in rgbd_assoc.txt");
                (ts(f[0]), f[1].to_owned(), ts(f[2]), f[3].to_owned())
            })
            .collect()
    }

    #[test]
    #[ignore = "optional: needs ../shared/data (scripts/test.sh --extras)"]
    fn opens_the_real_fr1_rpy_excerpt() {
        let dir = &shared_tum_fr1_rpy_dir();
        let mut dataset = TumDataset::open(dir, None).expect("opening the TUM excerpt");
        assert_eq!(dataset.name(), "tum_fr1_rpy_0-99", "name");
        assert_eq!(dataset.frame_count(), 100, "associated frames");
        assert_eq!(dataset.frames()[0].depth_timestamp_ns, 1_305_031_229_528_784_000, "first depth timestamp");
        assert_eq!(dataset.frames()[0].color_timestamp_ns, 1_305_031_229_528_748_000, "first colour timestamp");
        assert_eq!(dataset.calibration(), RgbdCalibration { intrinsics: TUM_FREIBURG1, depth_units_per_metre: 5000.0 }, "fr1");
        let ground_truth = dataset.ground_truth().expect("ground truth present");
        assert_eq!(ground_truth.len(), 430, "ground-truth poses");
        assert!(ground_truth.windows(2).all(|w| w[0].timestamp_ns < w[1].timestamp_ns), "ground truth sorted");

        let reference = reference_association(dir);
        assert_eq!(reference.len(), 100, "pairs in rgbd_assoc.txt");
        for (files, (ts_rgb, rgb, ts_depth, depth)) in dataset.frames().iter().zip(&reference) {
            assert_eq!((files.color_timestamp_ns, files.depth_timestamp_ns), (*ts_rgb, *ts_depth), "timestamps of {depth}");
            assert_eq!((files.color_path.clone(), files.depth_path.clone()), (Some(dir.join(rgb)), dir.join(depth)), "files of {depth}");
        }

        let frame = dataset.read_frame(99).expect("reading the last frame");
        assert_eq!(frame.index, 99, "index");
        assert_eq!(frame.depth_timestamp_ns, reference[99].2, "depth timestamp");
        assert_eq!((frame.depth.width_px, frame.depth.height_px, frame.depth.units.len()), (640, 480, 640 * 480), "depth size");
        assert_eq!(frame.color.rgb8.len(), 640 * 480 * 3, "colour size");
        let valid = frame.depth.units.iter().filter(|&&u| u != 0).count();
        assert!(valid > 640 * 480 / 2, "most pixels have depth ({valid})");
        let mean_m = frame.depth.units.iter().filter(|&&u| u != 0).map(|&u| f64::from(u) / 5000.0).sum::<f64>() / valid as f64;
        assert!((0.5..5.0).contains(&mean_m), "mean depth {mean_m} m is plausible for an office");
        assert!(matches!(dataset.read_frame(100), Err(Error::Dataset { .. })), "out of range");
    }

    #[test]
    fn the_sample_round_trips_through_a_tum_directory() {
        let (scratch, dir) = sample_as_tum(10..14);
        let mut sample = RecordingReader::open(SAMPLE_RECORDING).expect("opening the sample");
        let mut dataset = TumDataset::open(&dir, None).expect("opening what was written");
        assert_eq!(dataset.name(), "rgbd_dataset_freiburg1_rpy", "name");
        assert_eq!(dataset.calibration(), sample.calibration(), "fr1, found from the path");
        assert_eq!(dataset.frame_count(), 4, "frames");
        assert_eq!(dataset.ground_truth(), sample.ground_truth(), "ground truth, exactly");
        for i in 0..4 {
            let (mut want, got) = (sample.read_frame(10 + i).expect("sample frame"), dataset.read_frame(i).expect("written frame"));
            want.index = i as u64;
            assert_eq!(got, want, "frame {i}: images and timestamps");
        }
        let again = write_tum_dataset(&dir, &mut sample, 10..11).expect_err("writing over existing images");
        assert!(matches!(&again, Error::InvalidConfig(m) if m.contains("exists already")), "{again:?}");
        let beyond = write_tum_dataset(&scratch.path().join("other"), &mut sample, 99..101).expect_err("frames past the end");
        assert!(matches!(&beyond, Error::InvalidConfig(m) if m.contains("99..101")), "{beyond:?}");
    }

    /// Writes a small TUM-like directory with 4x3 images.
    fn write_small_dataset(dir: &Path, rgb_txt: &str, depth_txt: &str) {
        std::fs::create_dir_all(dir.join("rgb")).expect("mkdir rgb");
        std::fs::create_dir_all(dir.join("depth")).expect("mkdir depth");
        std::fs::write(dir.join("rgb.txt"), rgb_txt).expect("writing rgb.txt");
        std::fs::write(dir.join("depth.txt"), depth_txt).expect("writing depth.txt");
        for (i, line) in rgb_txt.lines().filter_map(data_fields).enumerate() {
            let image = ColorImage::new(4, 3, vec![i as u8; 36]).expect("size");
            std::fs::write(dir.join(line[1]), png::encode_rgb8(&image).expect("encoding")).expect("writing colour");
        }
        for (i, line) in depth_txt.lines().filter_map(data_fields).enumerate() {
            let image = DepthImage::new(4, 3, vec![1000 + i as u16; 12]).expect("size");
            std::fs::write(dir.join(line[1]), png::encode_depth16(&image).expect("encoding")).expect("writing depth");
        }
    }

    fn small_calibration() -> RgbdCalibration {
        RgbdCalibration {
            intrinsics: PinholeIntrinsics { fx_px: 4.0, fy_px: 4.0, cx_px: 1.5, cy_px: 1.0, width_px: 4, height_px: 3 },
            depth_units_per_metre: 1000.0,
        }
    }

    #[test]
    fn a_calibration_file_is_picked_up_and_a_depth_only_radial_directory_reads_as_planar() {
        let scratch = ScratchDir::new("tum-calibration-file");
        let dir = scratch.path().join("simulated");
        std::fs::create_dir_all(dir.join("depth")).expect("mkdir");
        let k = PinholeIntrinsics { fx_px: 2.0, fy_px: 2.0, cx_px: 1.5, cy_px: 1.0, width_px: 4, height_px: 3 };
        let written = WrittenCalibration { calibration: RgbdCalibration { intrinsics: k, depth_units_per_metre: 1000.0 }, radial_depth: true, depth_noise: DepthNoise::None };
        std::fs::write(dir.join(CALIBRATION_FILE), format_calibration_file(&written)).expect("calibration");
        assert_eq!(read_calibration_file(&dir.join(CALIBRATION_FILE)).expect("reads back"), written, "round trip");
        // Distances of 2 m along every ray: the corner (0, 0) ray is (-0.75, -0.5, 1).
        let depth = DepthImage::new(4, 3, vec![2000; 12]).expect("depth");
        std::fs::write(dir.join("depth/a.png"), png::encode_depth16(&depth).expect("png")).expect("write");
        std::fs::write(dir.join("depth.txt"), "# depth\n5.000 depth/a.png\n").expect("list");
        let mut dataset = TumDataset::open(&dir, None).expect("opens with its own calibration, no rgb.txt");
        assert_eq!(dataset.calibration(), written.calibration);
        assert_eq!(dataset.depth_noise(), DepthNoise::None, "the file's depth noise");
        let frame = dataset.read_frame(0).expect("frame");
        assert_eq!(frame.color_timestamp_ns, frame.depth_timestamp_ns, "depth only: colour at the depth's time");
        assert_eq!(frame.color.rgb8, vec![0; 36], "black colour");
        let norm = (0.75f64 * 0.75 + 0.25 + 1.0).sqrt();
        assert_eq!(frame.depth.units[0], (2000.0 / norm).round() as u16, "radial -> planar at the corner");
        assert_eq!(dataset.frame_timestamp_ns(0).expect("timestamp"), 5_000_000_000);
        // Without the calibration file the same directory needs rgb.txt (and a calibration).
        std::fs::remove_file(dir.join(CALIBRATION_FILE)).expect("rm");
        assert!(TumDataset::open(&dir, Some(written.calibration)).is_err(), "no rgb.txt, no calibration file");
    }

    #[test]
    fn a_bad_calibration_file_is_a_typed_error_naming_the_problem() {
        let path = Path::new("calibration.txt");
        let good = format_calibration_file(&WrittenCalibration { calibration: small_calibration(), radial_depth: false, depth_noise: DepthNoise::KinectV1 });
        assert!(parse_calibration_file(&good, path).is_ok());
        // A file without `depth_noise` (written before it) is a Kinect's.
        let old = parse_calibration_file(&good.replace("depth_noise kinect\n", ""), path).expect("no depth_noise line");
        assert_eq!(old.depth_noise, DepthNoise::KinectV1);
        for (text, needle) in [
            (good.replace("fx_px 4\n", ""), "fx_px is missing"),
            (good.replace("depth planar", "depth spherical"), "planar or radial"),
            (good.replace("depth_noise kinect", "depth_noise gaussian"), "kinect or none"),
            (good.replace("width_px 4", "width_px -4"), "width_px"),
            (good.replace("fy_px 4", "fy_px NaN"), "fy_px"),
            (format!("{good}fx_px 5\n"), "twice"),
            (format!("{good}skew 0\n"), "unknown key"),
            (good.replace("cx_px 1.5", "cx_px 1.5 2"), "key value"),
        ] {
            let err = parse_calibration_file(&text, path).expect_err(needle);
            assert!(matches!(err, Error::Parse { .. }) && err.to_string().contains(needle), "{needle}: {err}");
        }
    }

    #[test]
    fn reads_a_synthetic_dataset_with_override_and_tolerance() {
        let scratch = ScratchDir::new("tum-small");
        let dir = scratch.path().join("my_sequence");
        let rgb_txt = "# colour\n\n10.000 rgb/a.png\n10.050 rgb/b.png\n10.100 rgb/c.png\n";
        let depth_txt = "# depth\n10.010 depth/a.png\n10.045 depth/b.png\n10.200 depth/c.png\n";
        write_small_dataset(&dir, rgb_txt, depth_txt);

        let err = TumDataset::open(&dir, None).expect_err("no calibration for an unknown name");
        assert!(matches!(&err, Error::UnknownCalibration { source_name } if source_name.contains("my_sequence")), "{err:?}");

        let mut dataset = TumDataset::open(&dir, Some(small_calibration())).expect("opening with an override");
        assert_eq!(dataset.calibration(), small_calibration(), "override wins");
        assert!(dataset.ground_truth().is_none(), "no groundtruth.txt");
        assert_eq!(dataset.frame_count(), 2, "10.200 has no colour within 20 ms");
        let frame = dataset.read_frame(1).expect("reading");
        assert_eq!((frame.depth_timestamp_ns, frame.color_timestamp_ns), (10_045_000_000, 10_050_000_000), "timestamps");
        assert_eq!(frame.depth.units, vec![1001; 12], "second depth image");
        assert_eq!(frame.color.rgb8, vec![1; 36], "second colour image");

        let options = TumOptions { max_time_difference_ns: 150_000_000, calibration_override: Some(small_calibration()) };
        let wide = TumDataset::open_with(&dir, options).expect("opening with a wide tolerance");
        assert_eq!(wide.frame_count(), 3, "10.200 pairs with 10.100 within 150 ms");
    }

    #[cfg(unix)]
    #[test]
    fn recognises_the_camera_from_a_symlink_name() {
        let scratch = ScratchDir::new("tum-symlink");
        let link = scratch.path().join("rgbd_dataset_freiburg2_desk");
        let (_sample_scratch, fr1_dir) = sample_as_tum(0..1);
        std::os::unix::fs::symlink(&fr1_dir, &link).expect("creating a symlink");
        let dataset = TumDataset::open(&link, None).expect("opening through the symlink");
        assert_eq!(dataset.calibration().intrinsics, TUM_FREIBURG1, "the resolved name (..._freiburg1_...) is nearer the data");
        assert_eq!(dataset.name(), "rgbd_dataset_freiburg2_desk", "name as given");
        let unnamed = scratch.path().join("sequence");
        std::fs::create_dir(&unnamed).expect("mkdir");
        let fr3_link = scratch.path().join("fr3_office");
        std::os::unix::fs::symlink(&unnamed, &fr3_link).expect("creating a symlink");
        write_small_dataset(&unnamed, "1.0 rgb/a.png\n", "1.0 depth/a.png\n");
        let dataset = TumDataset::open(&fr3_link, None).expect("opening an unnamed target through an fr3 link");
        assert_eq!(dataset.calibration().intrinsics, TUM_FREIBURG3, "falls back to the name as given");
    }

    #[test]
    fn image_errors_name_the_file() {
        let scratch = ScratchDir::new("tum-bad-images");
        let dir = scratch.path().join("seq");
        write_small_dataset(&dir, "1.0 rgb/a.png\n2.0 rgb/b.png\n", "1.0 depth/a.png\n2.0 depth/b.png\n");
        let mut wrong_size_calibration = small_calibration();
        wrong_size_calibration.intrinsics.width_px = 5;
        let mut dataset = TumDataset::open(&dir, Some(wrong_size_calibration)).expect("opening");
        match dataset.read_frame(0) {
            Err(Error::ImageDecode { path, message }) => {
                assert_eq!(path, dir.join("depth/a.png"), "path");
                assert!(message.contains("4x3 px but 5x3 px"), "{message}");
            }
            other => panic!("expected an image error, got {other:?}"),
        }

        std::fs::write(dir.join("depth/b.png"), b"not a png").expect("corrupting");
        let mut dataset = TumDataset::open(&dir, Some(small_calibration())).expect("opening");
        assert!(matches!(dataset.read_frame(1), Err(Error::ImageDecode { path, .. }) if path == dir.join("depth/b.png")), "garbage PNG");
        // A colour PNG where depth is expected.
        std::fs::copy(dir.join("rgb/a.png"), dir.join("depth/b.png")).expect("copying");
        assert!(matches!(dataset.read_frame(1), Err(Error::ImageDecode { path, .. }) if path == dir.join("depth/b.png")), "RGB as depth");
        std::fs::remove_file(dir.join("rgb/a.png")).expect("removing");
        assert!(matches!(dataset.read_frame(0), Err(Error::Io { path, .. }) if path == dir.join("rgb/a.png")), "missing file");
    }

    #[test]
    fn list_errors_name_file_and_line() {
        let scratch = ScratchDir::new("tum-bad-lists");
        let dir = scratch.path().join("fr1_bad");
        write_small_dataset(&dir, "1.0 rgb/a.png\n", "1.0 depth/a.png\n");
        for (depth_txt, want_line, want_message) in [
            ("# c\n1.0 depth/a.png extra\n", 2, "expected 2 fields"),
            ("\n\nabc depth/a.png\n", 3, "invalid timestamp"),
            ("1.0\n", 1, "expected 2 fields"),
        ] {
            std::fs::write(dir.join("depth.txt"), depth_txt).expect("writing depth.txt");
            match TumDataset::open(&dir, None) {
                Err(Error::Parse { path, line, message }) => {
                    assert_eq!(path, dir.join("depth.txt"), "path for {depth_txt:?}");
                    assert_eq!(line, want_line, "line for {depth_txt:?}");
                    assert!(message.contains(want_message), "{message}");
                }
                other => panic!("expected a parse error for {depth_txt:?}, got {other:?}"),
            }
        }
        std::fs::write(dir.join("depth.txt"), "1.0 depth/a.png\n").expect("writing depth.txt");
        std::fs::write(dir.join("groundtruth.txt"), "1.0 0 0 0\n").expect("writing groundtruth.txt");
        assert!(matches!(TumDataset::open(&dir, None), Err(Error::Parse { line: 1, .. })), "bad ground truth");
        std::fs::write(dir.join("groundtruth.txt"), "1.0 1 2 3 0 0 0 1\n").expect("writing groundtruth.txt");
        let dataset = TumDataset::open(&dir, None).expect("opening");
        assert_eq!(dataset.ground_truth().map(<[TimedPose]>::len), Some(1), "one ground-truth pose");
        std::fs::write(dir.join("depth.txt"), "100.0 depth/a.png\n").expect("writing depth.txt");
        assert!(matches!(TumDataset::open(&dir, None), Err(Error::Dataset { .. })), "no pairs");
        std::fs::remove_file(dir.join("rgb.txt")).expect("removing rgb.txt");
        assert!(matches!(TumDataset::open(&dir, None), Err(Error::Io { path, .. }) if path == dir.join("rgb.txt")), "missing rgb.txt");
        assert!(matches!(TumDataset::open(scratch.path().join("nope"), None), Err(Error::Io { .. })), "missing directory");
    }
}
