// SPDX-License-Identifier: MIT
//! Where frames come from: the [`FrameSource`] trait and [`open_source`], which picks the
//! implementation for a path (a TUM RGB-D directory or a `.wfr` recording).

use std::path::Path;

pub use crate::io::trajectory::TimedPose;
use crate::io::tum::TumDataset;
use crate::recording::{RECORDING_MAGIC, RecordingReader};
use crate::{Error, Result, RgbdCalibration, RgbdFrame};

/// The noise of a source's depth images: what tracking weights its residuals by and how wide
/// fusion's truncation band grows with depth (the noise model is the sensor's, so a source
/// that knows its sensor says it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DepthNoise {
    /// A Kinect v1's (structured light): σ_z(z) = 0.0012 + 0.0019 (z − 0.4)² m (Nguyen, Izadi
    /// and Lovell 2012). Every source that does not say otherwise: real Kinect logs.
    #[default]
    KinectV1,
    /// Exact depth, up to the images' quantisation (`simulate` without `--noise`): every
    /// measurement is as good as any other, so residuals are not weighted by depth and the
    /// band stays μ.
    None,
}

impl DepthNoise {
    /// The name calibration files use: `kinect` or `none`.
    pub fn name(self) -> &'static str {
        match self {
            Self::KinectV1 => "kinect",
            Self::None => "none",
        }
    }

    /// The model named `name` ([`Self::name`]).
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::KinectV1, Self::None].into_iter().find(|n| n.name() == name)
    }
}

/// A finite, random-access sequence of RGB-D frames with one calibration.
pub trait FrameSource: Send {
    /// Human-readable name (a directory or file name).
    fn name(&self) -> String;

    /// Calibration of every frame.
    fn calibration(&self) -> RgbdCalibration;

    /// The noise of its depth images: a Kinect v1's unless the source knows better (a
    /// simulated log's calibration file).
    fn depth_noise(&self) -> DepthNoise {
        DepthNoise::KinectV1
    }

    /// Number of frames; valid indices are `0..frame_count()`.
    fn frame_count(&self) -> usize;

    /// Reads and decodes frame `index`; its images have the calibration's size.
    fn read_frame(&mut self, index: usize) -> Result<RgbdFrame>;

    /// Ground-truth camera poses (`world_from_camera`), if the source has them.
    fn ground_truth(&self) -> Option<&[TimedPose]>;

    /// Depth timestamp of frame `index`, nanoseconds: by reading the frame, unless the source
    /// knows it without decoding (a TUM directory's list).
    fn frame_timestamp_ns(&mut self, index: usize) -> Result<i64> {
        Ok(self.read_frame(index)?.depth_timestamp_ns)
    }

    /// Frames the device produced but this source never handed out, so far (a live camera's
    /// gaps in its own frame numbers); files drop nothing.
    fn frames_dropped_by_source(&self) -> u64 {
        0
    }
}

/// A live camera: an endless stream of frames, read in order, with one calibration.
///
/// Unlike a [`FrameSource`] it cannot seek and has no frame count; frames that nobody reads
/// in time are the driver's to drop.
pub trait LiveSource: Send {
    /// Human-readable name (the device's vendor and model, or its URI).
    fn name(&self) -> String;

    /// Calibration of every frame.
    fn calibration(&self) -> RgbdCalibration;

    /// Blocks until the device delivers its next frame. Frames are numbered from 0 in the
    /// order read; an error means the device stopped (unplugged, timed out).
    fn next_frame(&mut self) -> Result<RgbdFrame>;

    /// Frames the device numbered but this source never handed out, so far: the gaps in the
    /// device's own frame numbers (the reader fell behind and the driver dropped them).
    fn frames_dropped(&self) -> u64;
}

/// Opens `path` as a frame source: a directory is read as a TUM RGB-D sequence, a file
/// starting with the recording magic as a `.wfr` recording.
///
/// `calibration_override` replaces the calibration of the source; for a recording it must
/// have the recorded image size.
pub fn open_source(path: &Path, calibration_override: Option<RgbdCalibration>) -> Result<Box<dyn FrameSource>> {
    let metadata = std::fs::metadata(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    if metadata.is_dir() {
        return Ok(Box::new(TumDataset::open(path, calibration_override)?));
    }
    if !is_recording(path)? {
        return Err(Error::Dataset {
            path: path.to_owned(),
            message: "neither a TUM RGB-D directory nor a webfusion recording (.wfr)".to_owned(),
        });
    }
    Ok(Box::new(open_recording(path, calibration_override)?))
}

/// Whether the file at `path` starts with the recording magic (reads only those bytes).
pub fn is_recording(path: &Path) -> Result<bool> {
    let mut magic = [0_u8; RECORDING_MAGIC.len()];
    let magic_len = std::fs::File::open(path)
        .and_then(|mut file| read_up_to(&mut file, &mut magic))
        .map_err(|source| Error::Io { path: path.to_owned(), source })?;
    Ok(magic[..magic_len] == RECORDING_MAGIC[..])
}

/// Opens a `.wfr` recording, with `calibration_override` (same image size) replacing its own.
/// A recording that does not open strictly (its writer was killed, its index is damaged) is
/// recovered by scanning ([`RecordingReader::open_recovering`]); what was kept is in
/// [`RecordingReader::recovery`], for the caller to report.
pub fn open_recording(path: &Path, calibration_override: Option<RgbdCalibration>) -> Result<RecordingReader> {
    let mut recording = RecordingReader::open_recovering(path)?;
    if let Some(calibration) = calibration_override {
        recording.override_calibration(calibration)?;
    }
    Ok(recording)
}

/// Fills `buffer` as far as the reader allows; returns the number of bytes read.
fn read_up_to(reader: &mut impl std::io::Read, buffer: &mut [u8]) -> std::io::Result<usize> {
    let mut filled = 0;
    while filled < buffer.len() {
        match reader.read(&mut buffer[filled..]) {
            Ok(0) => break,
            Ok(n) => filled += n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(filled)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::test_util::{SAMPLE_RECORDING, ScratchDir, sample_as_tum};

    #[test]
    fn opens_a_tum_directory_and_a_recording() {
        let (_scratch, dir) = sample_as_tum(0..3);
        let source = open_source(&dir, None).expect("opening the TUM directory");
        assert_eq!(source.frame_count(), 3, "frames");
        assert!(source.ground_truth().is_some(), "ground truth");
        let recording = open_source(Path::new(SAMPLE_RECORDING), None).expect("opening the sample recording");
        assert_eq!(recording.frame_count(), 100, "frames");
        assert_eq!(recording.calibration(), source.calibration(), "both fr1");
    }

    #[test]
    fn rejects_other_files() {
        let scratch = ScratchDir::new("source");
        let path = scratch.path().join("notes.txt");
        std::fs::write(&path, "hello").expect("writing");
        assert!(matches!(open_source(&path, None), Err(Error::Dataset { .. })), "text file");
        let empty = scratch.path().join("empty.wfr");
        std::fs::write(&empty, "").expect("writing");
        assert!(matches!(open_source(&empty, None), Err(Error::Dataset { .. })), "empty file");
        assert!(matches!(open_source(&scratch.path().join("missing"), None), Err(Error::Io { .. })), "missing path");
    }
}
