// SPDX-License-Identifier: MIT
//! `.wfr` ("webfusion recording"): a single file of RGB-D frames for replay and tests, with
//! random access and every byte covered by a CRC.
//!
//! Depth is stored losslessly with [RVL](crate::codec::rvl) (by default followed by DEFLATE),
//! colour as JPEG or PNG. A fixed
//! header holds the calibration; an index at the end gives each frame's offset, and a fixed
//! footer in the last 32 bytes points to the index, so a reader seeks straight to any frame.
//! A recording whose writer did not finish has no footer: [`RecordingReader::open`] (strict)
//! rejects it; [`RecordingReader::open_recovering`] (what the commands use) scans it instead
//! and keeps every complete record whose CRC matches, resynchronising on the record magic past
//! a damaged one (`webfusion repair` writes a finished copy).
//!
//! # Byte layout, version 3
//!
//! Integers are little-endian, floats IEEE 754 little-endian, CRCs CRC-32/ISO-HDLC (the
//! zlib/PNG CRC). Reserved bytes are written as zero and rejected if not zero.
//!
//! ```text
//! file = header, frame record × n, ground-truth block (optional), index, footer
//!
//! header, 64 bytes at offset 0
//!    0   8  magic                 89 57 46 52 0D 0A 1A 0A  ("\x89WFR\r\n\x1a\n")
//!    8   2  version u16           3 (files of versions 1 and 2 still read)
//!   10   2  reserved
//!   12   4  width_px u32          1..=8192
//!   16   4  height_px u32         1..=8192
//!   20  16  fx_px, fy_px, cx_px, cy_px f32
//!   36   4  depth_units_per_metre f32
//!   40   1  depth codec u8        1 = RVL, 2 = RVL + DEFLATE
//!   41   1  colour codec u8       1 = JPEG, 2 = PNG
//!   42   1  depth noise u8        0 = a Kinect v1's (a real sensor), 1 = exact (synthetic);
//!                                 reserved (0) before version 3
//!   43   1  reserved
//!   44   4  frame count n u32     (written as 0 until the writer finishes)
//!   48  12  reserved
//!   60   4  CRC of bytes 0..60
//!
//! frame record, 36 + D + C bytes; records follow each other from offset 64 (or from the end
//! of a ground-truth block there)
//!    0   4  magic "WFRF"
//!    4   4  frame index u32       position in the recording, from 0
//!    8   8  depth timestamp i64   nanoseconds
//!   16   8  colour timestamp i64  nanoseconds
//!   24   4  depth payload length D u32
//!   28   4  colour payload length C u32
//!   32   4  CRC of bytes 0..32 followed by the D + C payload bytes
//!   36   D  depth payload         (depth codec, width × height values)
//! 36+D   C  colour payload        (colour codec, width × height RGB8)
//!
//! ground-truth block, 12 + 64 g bytes (optional): right after the header when the writer
//! knows the trajectory before the first frame (version 2: it then survives a crash), else right
//! after the last record
//!    0   4  magic "WFRG"
//!    4   4  pose count g u32
//!    8 64g  poses: timestamp i64 ns, tx ty tz f64 metres, qx qy qz qw f64 (world_from_camera)
//! 8+64g  4  CRC of bytes 0..8+64g
//!
//! index, 12 + 8 n bytes, right after the records (and a trailing ground truth)
//!    0   4  magic "WFRI"
//!    4   4  frame count n u32
//!    8  8n  file offset of each frame record, u64, increasing
//!  8+8n  4  CRC of bytes 0..8+8n
//!
//! footer, the last 48 bytes (version 2)
//!    0   8  index offset u64
//!    8   8  ground-truth block offset u64, 0 if there is none
//!   16   4  frame count n u32
//!   20   4  frames dropped by the source u32 (a live camera's gaps in its frame numbers)
//!   24   8  take duration u64, nanoseconds of wall clock from the start of the take to its
//!           last frame written; 0 when the file is not a timed take (a conversion in memory)
//!   32   8  reserved
//!   40   4  CRC of bytes 0..40
//!   44   4  magic "WFRE"
//!
//! footer, the last 32 bytes (version 1, still read): bytes 0..20 as above, 4 reserved bytes,
//! the CRC of bytes 0..24, the magic
//! ```
//!
//! A reader checks the header, footer, index and ground truth when it opens a file, and a
//! frame record's bounds and CRC when it reads that frame. Every length is checked against
//! the file before anything is allocated for it.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::{DQuat, DVec3};

use crate::codec::{ColorCodec, DEFAULT_JPEG_QUALITY, DepthCodec};
use crate::io::trajectory::TimedPose;
use crate::source::{DepthNoise, FrameSource};
use crate::{ColorImage, DepthImage, Error, PinholeIntrinsics, Result, RgbdCalibration, RgbdFrame, Se3};

/// First 8 bytes of every recording. The high first byte and CR LF / EOF bytes detect text-mode
/// and 7-bit transfers, as in PNG.
pub const RECORDING_MAGIC: [u8; 8] = *b"\x89WFR\r\n\x1a\n";
/// Format version this build writes and the newest it reads.
pub const RECORDING_VERSION: u16 = 3;
/// File name extension of recordings (without the dot).
pub const RECORDING_EXTENSION: &str = "wfr";
/// Largest image width or height a recording may declare, in pixels. It bounds what decoding
/// one frame can allocate.
pub const MAX_IMAGE_SIDE_PX: u32 = 8192;

const HEADER_LEN: usize = 64;
const RECORD_HEADER_LEN: usize = 36;
const FOOTER_LEN: usize = 48;
/// Footer length of version 1 files.
const FOOTER_LEN_V1: usize = 32;
const BLOCK_HEAD_LEN: usize = 8;
const CRC_LEN: usize = 4;
const POSE_LEN: usize = 64;
const INDEX_ENTRY_LEN: usize = 8;
const RECORD_MAGIC: [u8; 4] = *b"WFRF";
const GROUND_TRUTH_MAGIC: [u8; 4] = *b"WFRG";
const INDEX_MAGIC: [u8; 4] = *b"WFRI";
const FOOTER_MAGIC: [u8; 4] = *b"WFRE";
/// Name used in errors for recordings that are not files.
const MEMORY_NAME: &str = "<memory>";

/// How a [`RecordingWriter`] encodes frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordingOptions {
    /// Depth codec (lossless either way).
    pub depth_codec: DepthCodec,
    /// Colour codec.
    pub color_codec: ColorCodec,
    /// JPEG quality 1..=100 when `color_codec` is JPEG.
    pub jpeg_quality: u8,
    /// The noise of the depth written (a replay tracks and fuses by it).
    pub depth_noise: DepthNoise,
}

impl Default for RecordingOptions {
    fn default() -> Self {
        Self { depth_codec: DepthCodec::RvlDeflate, color_codec: ColorCodec::Jpeg, jpeg_quality: DEFAULT_JPEG_QUALITY, depth_noise: DepthNoise::KinectV1 }
    }
}

/// What a finished recording holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordingSummary {
    /// Frames written.
    pub frame_count: usize,
    /// Ground-truth poses written.
    pub ground_truth_pose_count: usize,
    /// Size of the whole file, in bytes.
    pub total_bytes: u64,
    /// Sum of the compressed depth payloads, in bytes.
    pub depth_payload_bytes: u64,
    /// Sum of the compressed colour payloads, in bytes.
    pub color_payload_bytes: u64,
    /// How the take went, when the writer was told ([`RecordingWriter::set_take_stats`]).
    pub take: Option<TakeStats>,
}

/// How a take went, stored in the footer: what the recorder saw while writing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TakeStats {
    /// Wall-clock nanoseconds from the start of the take to its last frame written.
    pub duration_ns: u64,
    /// Frames the source produced but never delivered (a live camera's gaps in its frame
    /// numbers, when the recorder fell behind or the device skipped).
    pub frames_dropped_by_source: u32,
}

impl TakeStats {
    /// Frames written per second of the take; `None` for a zero duration.
    pub fn frames_per_second(&self, frame_count: usize) -> Option<f64> {
        (self.duration_ns > 0).then(|| frame_count as f64 / (self.duration_ns as f64 * 1e-9))
    }
}

/// Writes a `.wfr` recording frame by frame. Call [`RecordingWriter::finish`]: without it
/// the file has no index and readers reject it.
#[derive(Debug)]
pub struct RecordingWriter<W: Write + Seek = BufWriter<File>> {
    sink: W,
    path: PathBuf,
    calibration: RgbdCalibration,
    options: RecordingOptions,
    /// Offsets of the frame records, from the start of the recording.
    record_offsets: Vec<u64>,
    /// Position of the start of the recording in `sink`.
    base: u64,
    /// Bytes written so far, from the start of the recording.
    position: u64,
    /// Ground truth to write after the records, when it came after the first frame.
    ground_truth: Option<Vec<TimedPose>>,
    /// Offset and pose count of the ground-truth block written right after the header.
    leading_ground_truth: Option<(u64, usize)>,
    take: Option<TakeStats>,
    depth_payload_bytes: u64,
    color_payload_bytes: u64,
    /// Payload bytes (depth, colour) of each record, to give them back if a record is dropped.
    record_payloads: Vec<(u64, u64)>,
    /// End of the last complete record (or of the header), from the start of the recording.
    committed: u64,
    failed: bool,
}

impl RecordingWriter<BufWriter<File>> {
    /// Creates (or truncates) the file at `path` and writes the header.
    pub fn create(path: impl AsRef<Path>, calibration: RgbdCalibration, options: RecordingOptions) -> Result<Self> {
        let path = path.as_ref();
        validate_calibration(&calibration).map_err(Error::InvalidConfig)?;
        validate_options(&options)?;
        let file = File::create(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
        Self::with_path(BufWriter::new(file), path.to_owned(), calibration, options)
    }

    /// Flushes everything written so far and syncs it to disk (`sync_data`): a crash or power
    /// loss after this loses none of those frames (a reader recovers them by scanning).
    pub fn sync(&mut self) -> Result<()> {
        self.check_not_failed()?;
        let result = self.sink.flush().and_then(|()| self.sink.get_ref().sync_data());
        result.map_err(|source| {
            self.failed = true;
            Error::Io { path: self.path.clone(), source }
        })
    }

    /// Finishes a recording whose last write failed (a full disk, a file-size limit): cuts the
    /// file back to its last complete record and writes the trailer there; where even that
    /// does not fit, drops a trailing ground truth (one written before the first frame stays),
    /// then records from the end, until it does. Returns
    /// what the finished file holds.
    pub fn finish_keeping_what_fits(mut self) -> Result<RecordingSummary> {
        let io_error = |path: &Path, source| Error::Io { path: path.to_owned(), source };
        loop {
            // A fresh buffer over the same file (the old one's pending bytes are dropped with
            // it), cut back to the last complete record.
            let file = self.sink.get_ref().try_clone().map_err(|e| io_error(&self.path, e))?;
            drop(std::mem::replace(&mut self.sink, BufWriter::new(file)));
            let end = self.base + self.committed;
            self.sink.get_ref().set_len(end).map_err(|e| io_error(&self.path, e))?;
            self.sink.seek(SeekFrom::Start(end)).map_err(|e| io_error(&self.path, e))?;
            self.position = self.committed;
            self.failed = false;
            let error = match self.write_trailer().and_then(|summary| self.sync().map(|()| summary)) {
                Ok(summary) => return Ok(summary),
                Err(e) => e,
            };
            if self.ground_truth.take().is_some() {
                continue;
            }
            match (self.record_offsets.pop(), self.record_payloads.pop()) {
                (Some(offset), Some((depth, color))) => {
                    self.committed = offset;
                    self.depth_payload_bytes -= depth;
                    self.color_payload_bytes -= color;
                }
                _ => return Err(error),
            }
        }
    }
}

impl<W: Write + Seek> RecordingWriter<W> {
    /// Writes a recording into `sink` (e.g. a `Cursor<Vec<u8>>`), starting at its current position.
    pub fn new(sink: W, calibration: RgbdCalibration, options: RecordingOptions) -> Result<Self> {
        Self::with_path(sink, PathBuf::from(MEMORY_NAME), calibration, options)
    }

    fn with_path(mut sink: W, path: PathBuf, calibration: RgbdCalibration, options: RecordingOptions) -> Result<Self> {
        validate_calibration(&calibration).map_err(Error::InvalidConfig)?;
        validate_options(&options)?;
        let base = sink.stream_position().map_err(|source| Error::Io { path: path.clone(), source })?;
        let mut writer = Self {
            sink,
            path,
            calibration,
            options,
            record_offsets: Vec::new(),
            base,
            position: 0,
            ground_truth: None,
            leading_ground_truth: None,
            take: None,
            depth_payload_bytes: 0,
            color_payload_bytes: 0,
            record_payloads: Vec::new(),
            committed: 0,
            failed: false,
        };
        let header = encode_header(&calibration, options.depth_codec, options.color_codec, options.depth_noise, 0);
        writer.write_all(&header)?;
        writer.committed = writer.position;
        Ok(writer)
    }

    /// Encodes and appends one frame. Its images must have the calibration's size; its
    /// `index` is replaced by its position in the recording.
    pub fn write_frame(&mut self, frame: &RgbdFrame) -> Result<()> {
        self.check_not_failed()?;
        let intrinsics = &self.calibration.intrinsics;
        for (what, width_px, height_px) in
            [("depth image", frame.depth.width_px, frame.depth.height_px), ("colour image", frame.color.width_px, frame.color.height_px)]
        {
            if (width_px, height_px) != (intrinsics.width_px, intrinsics.height_px) {
                return Err(Error::FrameSize {
                    what,
                    got_width: width_px,
                    got_height: height_px,
                    want_width: intrinsics.width_px,
                    want_height: intrinsics.height_px,
                });
            }
        }
        let depth_payload = self.options.depth_codec.encode(&frame.depth);
        let color_payload = self.options.color_codec.encode(&frame.color, self.options.jpeg_quality)?;
        self.write_record(frame.depth_timestamp_ns, frame.color_timestamp_ns, &depth_payload, &color_payload)
    }

    /// Appends a frame already encoded with this writer's codecs (from a recording with the
    /// same codecs, e.g. when repairing one), bytes unchanged; its index becomes its position.
    pub fn write_encoded_frame(&mut self, frame: &EncodedFrame) -> Result<()> {
        self.check_not_failed()?;
        self.write_record(frame.depth_timestamp_ns, frame.color_timestamp_ns, &frame.depth_payload, &frame.color_payload)
    }

    fn write_record(&mut self, depth_timestamp_ns: i64, color_timestamp_ns: i64, depth_payload: &[u8], color_payload: &[u8]) -> Result<()> {
        let frame_index = u32::try_from(self.record_offsets.len())
            .ok()
            .filter(|&ix| ix < u32::MAX)
            .ok_or_else(|| Error::InvalidConfig(format!("a recording holds at most {} frames", u32::MAX)))?;
        let too_long =
            |what: &str, len: usize| Error::InvalidConfig(format!("{what} payload of {len} bytes exceeds the 4 GiB record limit"));
        let depth_len = u32::try_from(depth_payload.len()).map_err(|_| too_long("depth", depth_payload.len()))?;
        let color_len = u32::try_from(color_payload.len()).map_err(|_| too_long("colour", color_payload.len()))?;

        let mut header = [0_u8; RECORD_HEADER_LEN];
        header[0..4].copy_from_slice(&RECORD_MAGIC);
        header[4..8].copy_from_slice(&frame_index.to_le_bytes());
        header[8..16].copy_from_slice(&depth_timestamp_ns.to_le_bytes());
        header[16..24].copy_from_slice(&color_timestamp_ns.to_le_bytes());
        header[24..28].copy_from_slice(&depth_len.to_le_bytes());
        header[28..32].copy_from_slice(&color_len.to_le_bytes());
        let crc = record_crc(&header, &[depth_payload, color_payload]);
        header[32..36].copy_from_slice(&crc.to_le_bytes());

        let offset = self.position;
        self.write_all(&header)?;
        self.write_all(depth_payload)?;
        self.write_all(color_payload)?;
        self.record_offsets.push(offset);
        self.record_payloads.push((u64::from(depth_len), u64::from(color_len)));
        self.depth_payload_bytes += u64::from(depth_len);
        self.color_payload_bytes += u64::from(color_len);
        self.committed = self.position;
        Ok(())
    }

    /// Sets the ground-truth trajectory stored with the recording. Before the first frame it
    /// is written at once, right after the header, so a take that never finishes still holds it
    /// (a scan recovers it); later it is kept for the trailer (replacing any set before). A
    /// trajectory already written at the start cannot be replaced.
    pub fn set_ground_truth(&mut self, poses: &[TimedPose]) -> Result<()> {
        self.check_not_failed()?;
        if self.leading_ground_truth.is_some() {
            return Err(Error::InvalidConfig("the ground truth was written before the first frame and cannot be replaced".to_owned()));
        }
        if !self.record_offsets.is_empty() {
            self.ground_truth = Some(poses.to_vec());
            return Ok(());
        }
        let block = encode_ground_truth(poses)?;
        let offset = self.position;
        self.write_all(&block)?;
        self.committed = self.position;
        self.leading_ground_truth = Some((offset, poses.len()));
        Ok(())
    }

    /// Sets how the take went (its duration, the frames its source dropped), for the footer.
    pub fn set_take_stats(&mut self, take: TakeStats) {
        self.take = Some(take);
    }

    /// Frames written so far.
    pub fn frame_count(&self) -> usize {
        self.record_offsets.len()
    }

    /// Bytes written so far.
    pub fn bytes_written(&self) -> u64 {
        self.position
    }

    /// Writes ground truth, index and footer, completes the header and flushes.
    pub fn finish(self) -> Result<RecordingSummary> {
        self.finish_into_inner().map(|(_, summary)| summary)
    }

    /// Like [`RecordingWriter::finish`], and gives back the sink (e.g. the bytes of a `Cursor`).
    pub fn finish_into_inner(mut self) -> Result<(W, RecordingSummary)> {
        self.check_not_failed()?;
        let summary = self.write_trailer()?;
        Ok((self.sink, summary))
    }

    /// Writes ground truth, index and footer after the records, completes the header and
    /// flushes.
    fn write_trailer(&mut self) -> Result<RecordingSummary> {
        // `write_frame` keeps the count below `u32::MAX`.
        let frame_count = u32::try_from(self.record_offsets.len()).unwrap_or(u32::MAX);

        let (ground_truth_offset, ground_truth_pose_count) = match (&self.leading_ground_truth, self.ground_truth.clone()) {
            (Some((offset, count)), _) => (*offset, *count),
            (None, Some(poses)) => {
                let block = encode_ground_truth(&poses)?;
                let offset = self.position;
                self.write_all(&block)?;
                (offset, poses.len())
            }
            (None, None) => (0, 0),
        };

        let index_offset = self.position;
        let mut index = Vec::with_capacity(BLOCK_HEAD_LEN + self.record_offsets.len() * INDEX_ENTRY_LEN + CRC_LEN);
        index.extend_from_slice(&INDEX_MAGIC);
        index.extend_from_slice(&frame_count.to_le_bytes());
        for offset in &self.record_offsets {
            index.extend_from_slice(&offset.to_le_bytes());
        }
        let crc = crc32fast::hash(&index);
        index.extend_from_slice(&crc.to_le_bytes());
        self.write_all(&index)?;

        let mut footer = [0_u8; FOOTER_LEN];
        footer[0..8].copy_from_slice(&index_offset.to_le_bytes());
        footer[8..16].copy_from_slice(&ground_truth_offset.to_le_bytes());
        footer[16..20].copy_from_slice(&frame_count.to_le_bytes());
        let take = self.take.unwrap_or(TakeStats { duration_ns: 0, frames_dropped_by_source: 0 });
        footer[20..24].copy_from_slice(&take.frames_dropped_by_source.to_le_bytes());
        footer[24..32].copy_from_slice(&take.duration_ns.to_le_bytes());
        let crc = crc32fast::hash(&footer[..40]);
        footer[40..44].copy_from_slice(&crc.to_le_bytes());
        footer[44..48].copy_from_slice(&FOOTER_MAGIC);
        self.write_all(&footer)?;

        // Complete the header now that the frame count is known.
        let header = encode_header(&self.calibration, self.options.depth_codec, self.options.color_codec, self.options.depth_noise, frame_count);
        let io_error = |path: &Path, source| Error::Io { path: path.to_owned(), source };
        self.sink.seek(SeekFrom::Start(self.base)).map_err(|e| io_error(&self.path, e))?;
        self.sink.write_all(&header).map_err(|e| io_error(&self.path, e))?;
        self.sink.seek(SeekFrom::Start(self.base + self.position)).map_err(|e| io_error(&self.path, e))?;
        self.sink.flush().map_err(|e| io_error(&self.path, e))?;

        let summary = RecordingSummary {
            frame_count: self.record_offsets.len(),
            ground_truth_pose_count,
            total_bytes: self.position,
            depth_payload_bytes: self.depth_payload_bytes,
            color_payload_bytes: self.color_payload_bytes,
            take: self.take,
        };
        Ok(summary)
    }

    fn write_all(&mut self, bytes: &[u8]) -> Result<()> {
        if let Err(source) = self.sink.write_all(bytes) {
            self.failed = true;
            return Err(Error::Io { path: self.path.clone(), source });
        }
        self.position += bytes.len() as u64;
        Ok(())
    }

    fn check_not_failed(&self) -> Result<()> {
        if self.failed {
            return Err(Error::Recording {
                path: self.path.clone(),
                message: "an earlier write failed; the recording is incomplete".to_owned(),
            });
        }
        Ok(())
    }
}

/// A ground-truth block: magic, pose count, poses, CRC.
fn encode_ground_truth(poses: &[TimedPose]) -> Result<Vec<u8>> {
    let pose_count =
        u32::try_from(poses.len()).map_err(|_| Error::InvalidConfig(format!("a recording holds at most {} ground-truth poses", u32::MAX)))?;
    let mut block = Vec::with_capacity(BLOCK_HEAD_LEN + poses.len() * POSE_LEN + CRC_LEN);
    block.extend_from_slice(&GROUND_TRUTH_MAGIC);
    block.extend_from_slice(&pose_count.to_le_bytes());
    for pose in poses {
        let t = pose.world_from_camera.translation_m;
        let q = pose.world_from_camera.rotation;
        block.extend_from_slice(&pose.timestamp_ns.to_le_bytes());
        for value in [t.x, t.y, t.z, q.x, q.y, q.z, q.w] {
            block.extend_from_slice(&value.to_le_bytes());
        }
    }
    let crc = crc32fast::hash(&block);
    block.extend_from_slice(&crc.to_le_bytes());
    Ok(block)
}

fn validate_options(options: &RecordingOptions) -> Result<()> {
    if options.color_codec == ColorCodec::Jpeg && !(1..=100).contains(&options.jpeg_quality) {
        return Err(Error::InvalidConfig(format!("JPEG quality must be 1..=100, got {}", options.jpeg_quality)));
    }
    Ok(())
}

/// Checks what a recording header can hold; returns what is wrong.
fn validate_calibration(calibration: &RgbdCalibration) -> std::result::Result<(), String> {
    let k = &calibration.intrinsics;
    for (name, side_px) in [("width", k.width_px), ("height", k.height_px)] {
        if !(1..=MAX_IMAGE_SIDE_PX).contains(&side_px) {
            return Err(format!("image {name} {side_px} px is outside 1..={MAX_IMAGE_SIDE_PX}"));
        }
    }
    let positive = [("fx_px", k.fx_px), ("fy_px", k.fy_px), ("depth_units_per_metre", calibration.depth_units_per_metre)];
    for (name, value) in positive {
        if !(value.is_finite() && value > 0.0) {
            return Err(format!("{name} must be finite and positive, got {value}"));
        }
    }
    for (name, value) in [("cx_px", k.cx_px), ("cy_px", k.cy_px)] {
        if !value.is_finite() {
            return Err(format!("{name} must be finite, got {value}"));
        }
    }
    Ok(())
}

fn encode_header(calibration: &RgbdCalibration, depth_codec: DepthCodec, color_codec: ColorCodec, depth_noise: DepthNoise, frame_count: u32) -> [u8; HEADER_LEN] {
    let k = &calibration.intrinsics;
    let mut header = [0_u8; HEADER_LEN];
    header[0..8].copy_from_slice(&RECORDING_MAGIC);
    header[8..10].copy_from_slice(&RECORDING_VERSION.to_le_bytes());
    header[12..16].copy_from_slice(&k.width_px.to_le_bytes());
    header[16..20].copy_from_slice(&k.height_px.to_le_bytes());
    for (i, value) in [k.fx_px, k.fy_px, k.cx_px, k.cy_px, calibration.depth_units_per_metre].into_iter().enumerate() {
        header[20 + 4 * i..24 + 4 * i].copy_from_slice(&value.to_le_bytes());
    }
    header[40] = depth_codec.id();
    header[41] = color_codec.id();
    header[42] = depth_noise_id(depth_noise);
    header[44..48].copy_from_slice(&frame_count.to_le_bytes());
    let crc = crc32fast::hash(&header[..60]);
    header[60..64].copy_from_slice(&crc.to_le_bytes());
    header
}

/// The header's depth-noise byte (version 3).
fn depth_noise_id(noise: DepthNoise) -> u8 {
    match noise {
        DepthNoise::KinectV1 => 0,
        DepthNoise::None => 1,
    }
}

fn depth_noise_of_id(id: u8) -> Option<DepthNoise> {
    match id {
        0 => Some(DepthNoise::KinectV1),
        1 => Some(DepthNoise::None),
        _ => None,
    }
}

fn u16_at(bytes: &[u8], offset: usize) -> u16 {
    u16::from_le_bytes([bytes[offset], bytes[offset + 1]])
}

fn u32_at(bytes: &[u8], offset: usize) -> u32 {
    u32::from_le_bytes([bytes[offset], bytes[offset + 1], bytes[offset + 2], bytes[offset + 3]])
}

fn u64_at(bytes: &[u8], offset: usize) -> u64 {
    let mut le = [0_u8; 8];
    le.copy_from_slice(&bytes[offset..offset + 8]);
    u64::from_le_bytes(le)
}

/// A length that must fit in memory on this platform.
fn to_usize(len: u64) -> std::result::Result<usize, String> {
    usize::try_from(len).map_err(|_| format!("{len} bytes do not fit in memory on this platform"))
}

fn f32_at(bytes: &[u8], offset: usize) -> f32 {
    f32::from_bits(u32_at(bytes, offset))
}

fn f64_at(bytes: &[u8], offset: usize) -> f64 {
    f64::from_bits(u64_at(bytes, offset))
}

/// The bytes of a recording: a file read on demand, or a buffer.
#[derive(Debug)]
enum Storage {
    File { file: File, len: u64 },
    Memory(Vec<u8>),
}

impl Storage {
    fn len(&self) -> u64 {
        match self {
            Self::File { len, .. } => *len,
            Self::Memory(bytes) => bytes.len() as u64,
        }
    }

    /// Reads `len` bytes at `offset`; the caller has checked that they lie inside the storage.
    fn read_at(&mut self, offset: u64, len: usize) -> std::io::Result<Vec<u8>> {
        let out_of_bounds = || std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "read past the end of the recording");
        let end = offset.checked_add(len as u64).filter(|&end| end <= self.len()).ok_or_else(out_of_bounds)?;
        match self {
            Self::File { file, .. } => {
                let mut buffer = vec![0; len];
                file.seek(SeekFrom::Start(offset))?;
                file.read_exact(&mut buffer)?;
                Ok(buffer)
            }
            Self::Memory(bytes) => Ok(bytes[offset as usize..end as usize].to_vec()),
        }
    }
}

/// A frame as stored: timestamps and the compressed, CRC-checked payloads.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodedFrame {
    /// Position in the recording, from 0.
    pub index: u64,
    /// Depth capture time, nanoseconds.
    pub depth_timestamp_ns: i64,
    /// Colour capture time, nanoseconds.
    pub color_timestamp_ns: i64,
    /// Depth image in the recording's depth codec.
    pub depth_payload: Vec<u8>,
    /// Colour image in the recording's colour codec (a complete JPEG or PNG file).
    pub color_payload: Vec<u8>,
}

/// Reads a `.wfr` recording with random access to its frames.
#[derive(Debug)]
pub struct RecordingReader {
    storage: Storage,
    path: PathBuf,
    calibration: RgbdCalibration,
    depth_codec: DepthCodec,
    color_codec: ColorCodec,
    depth_noise: DepthNoise,
    records: Vec<RecordSpan>,
    ground_truth: Option<Vec<TimedPose>>,
    take: Option<TakeStats>,
    recovery: Option<RecoveryReport>,
}

/// Where one frame record lies: its header at `offset`, its payload up to `end`, and the
/// index it was written with (its position, unless records before it were lost).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct RecordSpan {
    offset: u64,
    end: u64,
    stored_index: u32,
}

/// What [`RecordingReader::open_recovering`] kept of a recording that did not open strictly
/// (no footer: the writer was killed; or a damaged index, footer or record).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RecoveryReport {
    /// Why the strict open failed.
    pub reason: String,
    /// Complete records whose CRC matched, in file order: the recovered frames.
    pub frames_kept: usize,
    /// Damaged records skipped (a CRC mismatch or impossible lengths, then a resynchronisation
    /// on the next record magic), counted from the gaps in the kept records' indices.
    pub records_dropped: usize,
    /// Bytes after the last complete record that hold no complete record (an unfinished tail).
    pub tail_bytes_dropped: u64,
    /// Whether a complete ground-truth block was found.
    pub ground_truth_recovered: bool,
}

impl std::fmt::Display for RecoveryReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "recovered {} frames by scanning ({}); {} damaged records dropped, {} bytes of unfinished tail dropped, ground truth {}",
            self.frames_kept,
            self.reason,
            self.records_dropped,
            self.tail_bytes_dropped,
            if self.ground_truth_recovered { "recovered" } else { "not found" }
        )
    }
}

impl RecordingReader {
    /// Opens a recording file and checks its header, footer, index and ground truth (the strict
    /// path: any damage is an error). Frames are read from the file on demand.
    pub fn open(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_storage(Self::file_storage(path)?, path.to_owned(), false)
    }

    /// Opens a recording as [`Self::open`] does; if that fails past the header (the writer was
    /// killed before its footer, or the footer, index, ground truth or a record is damaged),
    /// recovers by scanning: every complete record whose CRC matches is kept, a damaged one is
    /// skipped up to the next record magic, the unfinished tail is dropped. What was kept is in
    /// [`Self::recovery`]. A bad header (wrong magic, version, calibration) is still an error.
    pub fn open_recovering(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::from_storage(Self::file_storage(path)?, path.to_owned(), true)
    }

    fn file_storage(path: &Path) -> Result<Storage> {
        let io_error = |source| Error::Io { path: path.to_owned(), source };
        let file = File::open(path).map_err(io_error)?;
        let len = file.metadata().map_err(io_error)?.len();
        Ok(Storage::File { file, len })
    }

    /// Reads a recording held in memory (as fetched by the browser), strictly.
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Self> {
        Self::from_storage(Storage::Memory(bytes), PathBuf::from(MEMORY_NAME), false)
    }

    /// Reads a recording held in memory, recovering as [`Self::open_recovering`] does.
    pub fn from_bytes_recovering(bytes: Vec<u8>) -> Result<Self> {
        Self::from_storage(Storage::Memory(bytes), PathBuf::from(MEMORY_NAME), true)
    }

    /// What scanning recovered, if the recording did not open strictly.
    pub fn recovery(&self) -> Option<&RecoveryReport> {
        self.recovery.as_ref()
    }

    fn from_storage(mut storage: Storage, path: PathBuf, recover: bool) -> Result<Self> {
        let error = |message: String| Error::Recording { path: path.clone(), message };
        let file_len = storage.len();
        let read = |storage: &mut Storage, offset: u64, len: usize| -> Result<Vec<u8>> {
            storage.read_at(offset, len).map_err(|source| Error::Io { path: path.clone(), source })
        };

        // Header.
        let magic = read(&mut storage, 0, file_len.min(RECORDING_MAGIC.len() as u64) as usize)?;
        if magic[..] != RECORDING_MAGIC[..magic.len()] {
            return Err(error("not a webfusion recording (wrong magic bytes)".to_owned()));
        }
        if file_len < HEADER_LEN as u64 {
            return Err(error(format!("truncated: {file_len} bytes, shorter than the {HEADER_LEN}-byte header")));
        }
        let header = read(&mut storage, 0, HEADER_LEN)?;
        let version = u16_at(&header, 8);
        if version > RECORDING_VERSION {
            return Err(error(format!("recording version {version} is newer than this build supports ({RECORDING_VERSION})")));
        }
        if version == 0 {
            return Err(error("invalid recording version 0".to_owned()));
        }
        check_crc(&header, 60, "header").map_err(&error)?;
        if header[10..12] != [0; 2] || header[43] != 0 || (version < 3 && header[42] != 0) || header[48..60] != [0; 12] {
            return Err(error("reserved header bytes are not zero".to_owned()));
        }
        let depth_noise = depth_noise_of_id(header[42]).ok_or_else(|| error(format!("unknown depth noise id {}", header[42])))?;
        let calibration = RgbdCalibration {
            intrinsics: PinholeIntrinsics {
                fx_px: f32_at(&header, 20),
                fy_px: f32_at(&header, 24),
                cx_px: f32_at(&header, 28),
                cy_px: f32_at(&header, 32),
                width_px: u32_at(&header, 12),
                height_px: u32_at(&header, 16),
            },
            depth_units_per_metre: f32_at(&header, 36),
        };
        validate_calibration(&calibration).map_err(|m| error(format!("invalid calibration: {m}")))?;
        let depth_codec = DepthCodec::from_id(header[40]).ok_or_else(|| error(format!("unknown depth codec id {}", header[40])))?;
        let color_codec = ColorCodec::from_id(header[41]).ok_or_else(|| error(format!("unknown colour codec id {}", header[41])))?;
        let header_frame_count = u32_at(&header, 44);
        let (records, ground_truth, take, recovery) = match read_indexed(&mut storage, &path, header_frame_count, version) {
            Ok(indexed) => (indexed.records, indexed.ground_truth, indexed.take, None),
            Err(e) if recover => {
                let reason = match &e {
                    Error::Recording { message, .. } => message.clone(),
                    other => other.to_string(),
                };
                let scan = scan_records(&mut storage).map_err(|source| Error::Io { path: path.clone(), source })?;
                let report = RecoveryReport {
                    reason,
                    frames_kept: scan.records.len(),
                    records_dropped: scan.records_dropped,
                    tail_bytes_dropped: scan.tail_bytes_dropped,
                    ground_truth_recovered: scan.ground_truth.is_some(),
                };
                (scan.records, scan.ground_truth, None, Some(report))
            }
            Err(e) => return Err(e),
        };
        Ok(Self { storage, path, calibration, depth_codec, color_codec, depth_noise, records, ground_truth, take, recovery })
    }

    /// How the take went, from the footer of a finished version-2 file with a timed take;
    /// `None` for older files, untimed ones and recovered ones (the footer is what was lost).
    pub fn take_stats(&self) -> Option<TakeStats> {
        self.take
    }

    /// The file (or `<memory>`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Codec of the depth payloads.
    pub fn depth_codec(&self) -> DepthCodec {
        self.depth_codec
    }

    /// Codec of the colour payloads.
    pub fn color_codec(&self) -> ColorCodec {
        self.color_codec
    }

    /// Size of the recording in bytes.
    pub fn len_bytes(&self) -> u64 {
        self.storage.len()
    }

    /// Replaces the recorded calibration, e.g. to correct intrinsics; the image size must
    /// stay the recorded one.
    pub fn override_calibration(&mut self, calibration: RgbdCalibration) -> Result<()> {
        let (want, got) = (&self.calibration.intrinsics, &calibration.intrinsics);
        if (got.width_px, got.height_px) != (want.width_px, want.height_px) {
            return Err(Error::InvalidConfig(format!(
                "calibration override is for {}x{} px but {} has {}x{} px frames",
                got.width_px,
                got.height_px,
                self.path.display(),
                want.width_px,
                want.height_px
            )));
        }
        validate_calibration(&calibration).map_err(Error::InvalidConfig)?;
        self.calibration = calibration;
        Ok(())
    }

    /// Reads frame `index` without decoding its images; the record's bounds and CRC are checked.
    pub fn read_encoded_frame(&mut self, index: usize) -> Result<EncodedFrame> {
        let path = self.path.clone();
        let error = |message: String| Error::Recording { path: path.clone(), message };
        let corrupt = |message: String| Error::CorruptFrame { path: path.clone(), index, message };
        let io_error = |source| Error::Io { path: path.clone(), source };
        let Some(&RecordSpan { offset, end: record_end, stored_index: expected_index }) = self.records.get(index) else {
            return Err(error(format!("frame {index} does not exist ({} frames)", self.records.len())));
        };
        let header = self.storage.read_at(offset, RECORD_HEADER_LEN).map_err(io_error)?;
        if header[0..4] != RECORD_MAGIC {
            return Err(corrupt(format!("no frame record at offset {offset}")));
        }
        let (depth_len, color_len) = (u64::from(u32_at(&header, 24)), u64::from(u32_at(&header, 28)));
        let payload_len = depth_len + color_len;
        let room = record_end - offset - RECORD_HEADER_LEN as u64;
        if payload_len != room {
            return Err(corrupt(format!("record claims {payload_len} payload bytes but has room for {room}")));
        }
        let payload = self.storage.read_at(offset + RECORD_HEADER_LEN as u64, to_usize(payload_len).map_err(&error)?).map_err(io_error)?;
        let (stored, computed) = (u32_at(&header, 32), record_crc(&header, &[&payload]));
        if stored != computed {
            return Err(corrupt(format!("CRC mismatch (stored {stored:08x}, computed {computed:08x}); the record is corrupt")));
        }
        let stored_index = u32_at(&header, 4);
        if stored_index != expected_index {
            return Err(corrupt(format!("record says it is frame {stored_index}")));
        }
        let mut depth_payload = payload;
        let color_payload = depth_payload.split_off(depth_len as usize);
        Ok(EncodedFrame {
            index: index as u64,
            depth_timestamp_ns: u64_at(&header, 8) as i64,
            color_timestamp_ns: u64_at(&header, 16) as i64,
            depth_payload,
            color_payload,
        })
    }

    /// Decodes the images of an encoded frame of this recording.
    pub fn decode_frame(&self, encoded: &EncodedFrame) -> Result<RgbdFrame> {
        let (width_px, height_px) = (self.calibration.intrinsics.width_px, self.calibration.intrinsics.height_px);
        let in_frame = |e: Error| Error::CorruptFrame { path: self.path.clone(), index: encoded.index as usize, message: e.to_string() };
        let depth: DepthImage = self.depth_codec.decode(&encoded.depth_payload, width_px, height_px).map_err(in_frame)?;
        let color: ColorImage = self.color_codec.decode(&encoded.color_payload, width_px, height_px).map_err(in_frame)?;
        Ok(RgbdFrame {
            index: encoded.index,
            depth_timestamp_ns: encoded.depth_timestamp_ns,
            color_timestamp_ns: encoded.color_timestamp_ns,
            depth,
            color,
        })
    }
}

/// What the strict path read past the header.
struct Indexed {
    records: Vec<RecordSpan>,
    ground_truth: Option<Vec<TimedPose>>,
    take: Option<TakeStats>,
}

/// The strict path past the header: footer, index and ground truth, all checked; the records'
/// spans from the index.
fn read_indexed(storage: &mut Storage, path: &Path, header_frame_count: u32, version: u16) -> Result<Indexed> {
    let error = |message: String| Error::Recording { path: path.to_owned(), message };
    let file_len = storage.len();
    let read = |storage: &mut Storage, offset: u64, len: usize| -> Result<Vec<u8>> {
    storage.read_at(offset, len).map_err(|source| Error::Io { path: path.to_owned(), source })
    };
    let footer_len = if version >= 2 { FOOTER_LEN } else { FOOTER_LEN_V1 };
    let min_len = (HEADER_LEN + BLOCK_HEAD_LEN + CRC_LEN + footer_len) as u64;
    if file_len < min_len {
        return Err(error(format!("truncated: {file_len} bytes, but a finished recording has at least {min_len}")));
    }

    // Footer.
    let footer = read(storage, file_len - footer_len as u64, footer_len)?;
    if footer[footer_len - 4..] != FOOTER_MAGIC {
        return Err(error("truncated or unfinished: no footer at the end of the file".to_owned()));
    }
    check_crc(&footer, footer_len - 8, "footer").map_err(&error)?;
    let reserved = if version >= 2 { &footer[32..40] } else { &footer[20..24] };
    if reserved.iter().any(|&b| b != 0) {
        return Err(error("reserved footer bytes are not zero".to_owned()));
    }
    let take = (version >= 2 && u64_at(&footer, 24) > 0)
        .then(|| TakeStats { duration_ns: u64_at(&footer, 24), frames_dropped_by_source: u32_at(&footer, 20) });
    let index_offset = u64_at(&footer, 0);
    let ground_truth_offset = u64_at(&footer, 8);
    let frame_count = u32_at(&footer, 16);
    if frame_count != header_frame_count {
        return Err(error(format!("header says {header_frame_count} frames but footer says {frame_count}")));
    }

    // Index: exactly between its offset and the footer.
    let index_len = BLOCK_HEAD_LEN as u64 + u64::from(frame_count) * INDEX_ENTRY_LEN as u64 + CRC_LEN as u64;
    let index_end = index_offset.checked_add(index_len);
    if index_offset < HEADER_LEN as u64 || index_end != Some(file_len - footer_len as u64) {
        return Err(error(format!(
            "index of {frame_count} frames at offset {index_offset} does not end at the footer (file is {file_len} bytes)"
        )));
    }
    let index = read(storage, index_offset, to_usize(index_len).map_err(&error)?)?;
    if index[0..4] != INDEX_MAGIC {
        return Err(error(format!("no index at offset {index_offset}")));
    }
    check_crc(&index, index.len() - CRC_LEN, "index").map_err(&error)?;
    if u32_at(&index, 4) != frame_count {
        return Err(error(format!("index holds {} frames but footer says {frame_count}", u32_at(&index, 4))));
    }

    // Ground truth: right after the header (version 2), the records after it; or exactly
    // between its offset and the index.
    let (records_start, records_end, ground_truth) = if ground_truth_offset == 0 {
        (HEADER_LEN as u64, index_offset, None)
    } else if version >= 2 && ground_truth_offset == HEADER_LEN as u64 {
        let head = read(storage, ground_truth_offset, BLOCK_HEAD_LEN)?;
        let block_len = ground_truth_block_len(u32_at(&head, 4));
        if ground_truth_offset + block_len > index_offset {
            return Err(error(format!("ground truth of {} poses at offset {ground_truth_offset} runs into the index", u32_at(&head, 4))));
        }
        let block = read(storage, ground_truth_offset, to_usize(block_len).map_err(&error)?)?;
        (ground_truth_offset + block_len, index_offset, Some(decode_ground_truth(&block).map_err(&error)?))
    } else {
        if ground_truth_offset < HEADER_LEN as u64 || ground_truth_offset > index_offset - (BLOCK_HEAD_LEN + CRC_LEN) as u64 {
            return Err(error(format!("ground truth offset {ground_truth_offset} lies outside the records")));
        }
        let block_len = index_offset - ground_truth_offset;
        let block = read(storage, ground_truth_offset, to_usize(block_len).map_err(&error)?)?;
        (HEADER_LEN as u64, ground_truth_offset, Some(decode_ground_truth(&block).map_err(&error)?))
    };

    let record_offsets: Vec<u64> = (0..frame_count as usize).map(|i| u64_at(&index, BLOCK_HEAD_LEN + i * INDEX_ENTRY_LEN)).collect();
    let mut expected_min = records_start;
    for (i, &offset) in record_offsets.iter().enumerate() {
        let first_ok = i != 0 || offset == records_start;
        if !first_ok || offset < expected_min || offset.saturating_add(RECORD_HEADER_LEN as u64) > records_end {
            return Err(error(format!("index entry {i} (offset {offset}) is out of order or outside the records")));
        }
        expected_min = offset + RECORD_HEADER_LEN as u64;
    }
    if record_offsets.is_empty() && records_end != records_start {
        return Err(error(format!("no frames, but {} bytes between header and index", records_end.saturating_sub(records_start))));
    }

    let records = record_offsets
    .iter()
    .enumerate()
    .map(|(i, &offset)| RecordSpan { offset, end: record_offsets.get(i + 1).copied().unwrap_or(records_end), stored_index: i as u32 })
    .collect();
    Ok(Indexed { records, ground_truth, take })
}

/// What scanning a recording's records found.
struct Scan {
    records: Vec<RecordSpan>,
    ground_truth: Option<Vec<TimedPose>>,
    records_dropped: usize,
    tail_bytes_dropped: u64,
}

/// Scans the records from the end of the header: keeps every complete record whose CRC
/// matches; past a damaged one (CRC mismatch, lengths beyond the file) it resynchronises on the
/// next record magic; a complete, CRC-checked ground-truth block is taken; the index (or
/// nothing complete) ends the scan.
fn scan_records(storage: &mut Storage) -> std::io::Result<Scan> {
    let len = storage.len();
    let mut scan = Scan { records: Vec::new(), ground_truth: None, records_dropped: 0, tail_bytes_dropped: 0 };
    let mut at = HEADER_LEN as u64;
    // Where the bytes not yet accounted for began (a damaged record or garbage).
    let mut damaged_since: Option<u64> = None;
    while at + 4 <= len {
        let magic = storage.read_at(at, 4)?;
        let next = if magic == RECORD_MAGIC { complete_record(storage, at)? } else { None };
        if let Some(span) = next {
            damaged_since = None;
            // Records are written with their position as index: a gap counts the lost ones.
            let expected = scan.records.last().map_or(0, |r| r.stored_index.saturating_add(1));
            scan.records_dropped += span.stored_index.saturating_sub(expected) as usize;
            scan.records.push(span);
            at = span.end;
            continue;
        }
        if magic == GROUND_TRUTH_MAGIC
            && let Some((poses, end)) = complete_ground_truth(storage, at)?
        {
            damaged_since = None;
            scan.ground_truth = Some(poses);
            at = end;
            continue;
        }
        if magic == INDEX_MAGIC && damaged_since.is_none() {
            // The index and footer follow the records: nothing more to recover.
            return Ok(scan);
        }
        // Damage or an unfinished record: look for the next magic.
        damaged_since.get_or_insert(at);
        match find_magic(storage, at + 1)? {
            Some(found) => at = found,
            None => break,
        }
    }
    if let Some(from) = damaged_since {
        scan.tail_bytes_dropped = len - from;
    } else if at < len {
        scan.tail_bytes_dropped = len - at;
    }
    Ok(scan)
}

/// The record at `at` if it is complete and its CRC matches.
fn complete_record(storage: &mut Storage, at: u64) -> std::io::Result<Option<RecordSpan>> {
    let len = storage.len();
    if at + RECORD_HEADER_LEN as u64 > len {
        return Ok(None);
    }
    let header = storage.read_at(at, RECORD_HEADER_LEN)?;
    let payload_len = u64::from(u32_at(&header, 24)) + u64::from(u32_at(&header, 28));
    let end = at + RECORD_HEADER_LEN as u64 + payload_len;
    if end > len {
        return Ok(None);
    }
    let Ok(payload_len) = usize::try_from(payload_len) else { return Ok(None) };
    let payload = storage.read_at(at + RECORD_HEADER_LEN as u64, payload_len)?;
    Ok((record_crc(&header, &[&payload]) == u32_at(&header, 32)).then_some(RecordSpan { offset: at, end, stored_index: u32_at(&header, 4) }))
}

/// Bytes of a ground-truth block of `pose_count` poses: head, poses, CRC.
fn ground_truth_block_len(pose_count: u32) -> u64 {
    (BLOCK_HEAD_LEN + CRC_LEN) as u64 + u64::from(pose_count) * POSE_LEN as u64
}

/// The ground-truth block at `at` and its end, if it is complete and its CRC matches.
fn complete_ground_truth(storage: &mut Storage, at: u64) -> std::io::Result<Option<(Vec<TimedPose>, u64)>> {
    let len = storage.len();
    if at + BLOCK_HEAD_LEN as u64 > len {
        return Ok(None);
    }
    let head = storage.read_at(at, BLOCK_HEAD_LEN)?;
    let block_len = ground_truth_block_len(u32_at(&head, 4));
    if at + block_len > len {
        return Ok(None);
    }
    let Ok(block_len) = usize::try_from(block_len) else { return Ok(None) };
    let block = storage.read_at(at, block_len)?;
    Ok(decode_ground_truth(&block).ok().map(|poses| (poses, at + block_len as u64)))
}

/// Offset of the first record, ground-truth or index magic at or after `from`, read in 1 MiB
/// chunks (so a multi-gigabyte take is never held in memory).
fn find_magic(storage: &mut Storage, from: u64) -> std::io::Result<Option<u64>> {
    const CHUNK: u64 = 1 << 20;
    let len = storage.len();
    let mut start = from;
    while start + 4 <= len {
        let n = (len - start).min(CHUNK + 3);
        let bytes = storage.read_at(start, n as usize)?;
        if let Some(i) = bytes.windows(4).position(|w| w == RECORD_MAGIC || w == GROUND_TRUTH_MAGIC || w == INDEX_MAGIC) {
            return Ok(Some(start + i as u64));
        }
        start += CHUNK;
    }
    Ok(None)
}

impl FrameSource for RecordingReader {
    fn name(&self) -> String {
        self.path.file_name().map_or_else(|| self.path.display().to_string(), |n| n.to_string_lossy().into_owned())
    }

    fn calibration(&self) -> RgbdCalibration {
        self.calibration
    }

    /// What the header says (version 3; older files: a Kinect v1's).
    fn depth_noise(&self) -> DepthNoise {
        self.depth_noise
    }

    fn frame_count(&self) -> usize {
        self.records.len()
    }

    fn read_frame(&mut self, index: usize) -> Result<RgbdFrame> {
        let encoded = self.read_encoded_frame(index)?;
        self.decode_frame(&encoded)
    }

    fn ground_truth(&self) -> Option<&[TimedPose]> {
        self.ground_truth.as_deref()
    }
}

/// The CRC of a frame record: over its header's first 32 bytes, then the payload bytes.
fn record_crc(header: &[u8], payloads: &[&[u8]]) -> u32 {
    let mut crc = crc32fast::Hasher::new();
    crc.update(&header[..32]);
    for payload in payloads {
        crc.update(payload);
    }
    crc.finalize()
}

/// Checks the little-endian CRC stored at `crc_offset` against the CRC of the bytes before it.
fn check_crc(bytes: &[u8], crc_offset: usize, what: &str) -> std::result::Result<(), String> {
    let (stored, computed) = (u32_at(bytes, crc_offset), crc32fast::hash(&bytes[..crc_offset]));
    if stored != computed {
        return Err(format!("{what} CRC mismatch (stored {stored:08x}, computed {computed:08x}); the file is corrupt"));
    }
    Ok(())
}

fn decode_ground_truth(block: &[u8]) -> std::result::Result<Vec<TimedPose>, String> {
    if block[0..4] != GROUND_TRUTH_MAGIC {
        return Err("no ground-truth block at its offset".to_owned());
    }
    let pose_count = u32_at(block, 4) as usize;
    let want_len = pose_count.checked_mul(POSE_LEN).and_then(|n| n.checked_add(BLOCK_HEAD_LEN + CRC_LEN));
    if want_len != Some(block.len()) {
        return Err(format!("ground-truth block of {} bytes cannot hold {pose_count} poses", block.len()));
    }
    check_crc(block, block.len() - CRC_LEN, "ground truth")?;
    let mut poses = Vec::with_capacity(pose_count);
    for i in 0..pose_count {
        let at = BLOCK_HEAD_LEN + i * POSE_LEN;
        let v = |k: usize| f64_at(block, at + 8 + 8 * k);
        poses.push(TimedPose {
            timestamp_ns: u64_at(block, at) as i64,
            world_from_camera: Se3 { rotation: DQuat::from_xyzw(v(3), v(4), v(5), v(6)), translation_m: DVec3::new(v(0), v(1), v(2)) },
        });
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use super::*;
    use crate::io::test_util::{ScratchDir, shared_tum_fr1_rpy_dir};
    use crate::io::tum::TumDataset;
    use crate::source::open_source;

    /// The sample recording shipped in `data/sample`.
    const SAMPLE_PATH: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");

    fn small_calibration() -> RgbdCalibration {
        RgbdCalibration {
            intrinsics: PinholeIntrinsics { fx_px: 20.5, fy_px: 21.0, cx_px: 7.5, cy_px: 5.25, width_px: 16, height_px: 12 },
            depth_units_per_metre: 1000.0,
        }
    }

    /// Smooth colour (JPEG-friendly) and depth with holes, different per frame.
    fn synthetic_frame(index: u64) -> RgbdFrame {
        let k = small_calibration().intrinsics;
        let mut units = Vec::new();
        let mut rgb8 = Vec::new();
        for y in 0..k.height_px {
            for x in 0..k.width_px {
                let hole = (x + y + index as u32).is_multiple_of(7);
                units.push(if hole { 0 } else { 800 + (x * 13 + y * 29) as u16 + index as u16 * 3 });
                rgb8.extend_from_slice(&[(x * 12) as u8, (y * 16) as u8, (100 + index * 10) as u8]);
            }
        }
        RgbdFrame {
            index: 1000 + index,
            depth_timestamp_ns: 1_305_031_229_528_784_000 + index as i64 * 33_333_333,
            color_timestamp_ns: -5 + index as i64,
            depth: DepthImage::new(k.width_px, k.height_px, units).expect("depth size"),
            color: ColorImage::new(k.width_px, k.height_px, rgb8).expect("colour size"),
        }
    }

    fn sample_ground_truth() -> Vec<TimedPose> {
        (0..5)
            .map(|i| TimedPose {
                timestamp_ns: 1_305_031_229_000_000_000 + i * 10_000_000,
                world_from_camera: Se3::new(DQuat::from_rotation_z(0.1 * i as f64), DVec3::new(1.0, -2.0, 0.5 * i as f64)),
            })
            .collect()
    }

    fn record_to_bytes(options: RecordingOptions, frames: &[RgbdFrame], ground_truth: Option<&[TimedPose]>) -> Vec<u8> {
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), options).expect("creating the writer");
        for frame in frames {
            writer.write_frame(frame).expect("writing a frame");
        }
        if let Some(poses) = ground_truth {
            writer.set_ground_truth(poses).expect("ground truth after the frames");
        }
        let (cursor, summary) = writer.finish_into_inner().expect("finishing");
        assert_eq!(summary.frame_count, frames.len(), "summary frame count");
        assert_eq!(summary.total_bytes, cursor.get_ref().len() as u64, "summary size");
        cursor.into_inner()
    }

    fn png_options() -> RecordingOptions {
        RecordingOptions { depth_codec: DepthCodec::Rvl, color_codec: ColorCodec::Png, ..RecordingOptions::default() }
    }

    /// Three PNG frames with ground truth.
    fn small_recording() -> Vec<u8> {
        let frames: Vec<RgbdFrame> = (0..3).map(synthetic_frame).collect();
        record_to_bytes(png_options(), &frames, Some(&sample_ground_truth()))
    }

    /// The message of the [`Error::Recording`] that `result` must be.
    fn recording_error<T: std::fmt::Debug>(result: Result<T>) -> String {
        match result {
            Err(Error::Recording { message, .. }) => message,
            Err(Error::CorruptFrame { index, message, .. }) => format!("frame {index}: {message}"),
            other => panic!("expected a recording error, got {other:?}"),
        }
    }

    /// Opens and decodes every frame; the first error, if any.
    fn read_everything(bytes: Vec<u8>) -> Result<()> {
        let mut reader = RecordingReader::from_bytes(bytes)?;
        for i in 0..reader.frame_count() {
            reader.read_frame(i)?;
        }
        Ok(())
    }

    fn with_header_crc(mut bytes: Vec<u8>) -> Vec<u8> {
        let crc = crc32fast::hash(&bytes[..60]);
        bytes[60..64].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    #[test]
    fn png_round_trip_is_exact() {
        let frames: Vec<RgbdFrame> = (0..3).map(synthetic_frame).collect();
        let ground_truth = sample_ground_truth();
        let bytes = record_to_bytes(png_options(), &frames, Some(&ground_truth));
        assert_eq!(bytes[..8], RECORDING_MAGIC, "magic");
        let mut reader = RecordingReader::from_bytes(bytes).expect("opening");
        assert_eq!(reader.calibration(), small_calibration(), "calibration");
        assert_eq!((reader.depth_codec(), reader.color_codec()), (DepthCodec::Rvl, ColorCodec::Png), "codecs");
        assert_eq!(reader.frame_count(), 3, "frames");
        assert_eq!(reader.ground_truth(), Some(&ground_truth[..]), "ground truth");
        assert_eq!(reader.name(), "<memory>", "name");
        // Random access, backwards.
        for (i, want) in frames.iter().enumerate().rev() {
            let frame = reader.read_frame(i).expect("reading a frame");
            assert_eq!(frame.index, i as u64, "index is the position in the recording");
            assert_eq!(frame.depth_timestamp_ns, want.depth_timestamp_ns, "depth timestamp {i}");
            assert_eq!(frame.color_timestamp_ns, want.color_timestamp_ns, "colour timestamp {i}");
            assert_eq!(frame.depth, want.depth, "depth {i}");
            assert_eq!(frame.color, want.color, "colour {i}");
        }
        assert!(recording_error(reader.read_frame(3)).contains("frame 3 does not exist"), "out of range");
    }

    #[test]
    fn jpeg_round_trip_keeps_depth_exact_and_colour_close() {
        let frames: Vec<RgbdFrame> = (0..2).map(synthetic_frame).collect();
        let bytes = record_to_bytes(RecordingOptions::default(), &frames, None);
        let mut reader = RecordingReader::from_bytes(bytes).expect("opening");
        assert_eq!((reader.depth_codec(), reader.color_codec()), (DepthCodec::RvlDeflate, ColorCodec::Jpeg), "default codecs");
        assert!(reader.ground_truth().is_none(), "no ground truth");
        for (i, want) in frames.iter().enumerate() {
            let frame = reader.read_frame(i).expect("reading");
            assert_eq!(frame.depth, want.depth, "depth {i} is lossless");
            let error: u64 = frame.color.rgb8.iter().zip(&want.color.rgb8).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum();
            let mean = error as f64 / want.color.rgb8.len() as f64;
            assert!(mean < 3.0, "frame {i}: mean colour error {mean}");
        }
    }

    #[test]
    fn empty_recordings_round_trip() {
        let reader = RecordingReader::from_bytes(record_to_bytes(png_options(), &[], None)).expect("no frames");
        assert_eq!((reader.frame_count(), reader.ground_truth()), (0, None), "empty");
        let poses = sample_ground_truth();
        let reader = RecordingReader::from_bytes(record_to_bytes(png_options(), &[], Some(&poses))).expect("ground truth only");
        assert_eq!((reader.frame_count(), reader.ground_truth()), (0, Some(&poses[..])), "ground truth only");
        let reader = RecordingReader::from_bytes(record_to_bytes(png_options(), &[], Some(&[]))).expect("empty ground truth");
        assert_eq!(reader.ground_truth(), Some(&[][..]), "empty ground truth is kept");
    }

    #[test]
    fn file_round_trip_and_open_source() {
        let scratch = ScratchDir::new("recording-file");
        let path = scratch.path().join("small.wfr");
        let mut writer = RecordingWriter::create(&path, small_calibration(), RecordingOptions::default()).expect("creating");
        for i in 0..4 {
            writer.write_frame(&synthetic_frame(i)).expect("writing");
        }
        writer.set_ground_truth(&sample_ground_truth()).expect("ground truth");
        assert_eq!(writer.frame_count(), 4, "frames so far");
        let summary = writer.finish().expect("finishing");
        assert_eq!(summary.total_bytes, std::fs::metadata(&path).expect("metadata").len(), "size on disk");
        assert_eq!(summary.ground_truth_pose_count, 5, "poses");
        assert!(summary.depth_payload_bytes > 0 && summary.color_payload_bytes > 0, "{summary:?}");

        let mut reader = RecordingReader::open(&path).expect("opening");
        assert_eq!(reader.name(), "small.wfr", "name");
        assert_eq!(reader.read_frame(2).expect("reading").depth, synthetic_frame(2).depth, "depth via file");

        let mut source = open_source(&path, None).expect("open_source on a .wfr");
        assert_eq!((source.frame_count(), source.calibration()), (4, small_calibration()), "source");
        assert_eq!(source.read_frame(3).expect("reading").depth, synthetic_frame(3).depth, "depth via source");

        let mut corrected = small_calibration();
        corrected.intrinsics.fx_px = 30.0;
        let source = open_source(&path, Some(corrected)).expect("override with the same size");
        assert_eq!(source.calibration(), corrected, "override applied");
        corrected.intrinsics.width_px = 32;
        assert!(matches!(open_source(&path, Some(corrected)), Err(Error::InvalidConfig(_))), "override with another size");
    }

    #[test]
    fn every_truncation_is_rejected() {
        let bytes = small_recording();
        for len in 0..bytes.len() {
            assert!(RecordingReader::from_bytes(bytes[..len].to_vec()).is_err(), "truncation to {len} of {} bytes", bytes.len());
        }
        let message = recording_error(RecordingReader::from_bytes(bytes[..bytes.len() - 1].to_vec()));
        assert!(message.contains("no footer"), "{message}");
    }

    #[test]
    fn every_single_byte_corruption_is_detected() {
        let bytes = small_recording();
        assert!(read_everything(bytes.clone()).is_ok(), "the intact recording reads");
        for position in 0..bytes.len() {
            for flip in [0x01_u8, 0xFF] {
                let mut corrupt = bytes.clone();
                corrupt[position] ^= flip;
                assert!(read_everything(corrupt).is_err(), "byte {position} ^ {flip:#04x} went unnoticed");
            }
        }
    }

    #[test]
    fn corrupt_frames_are_named() {
        let bytes = small_recording();
        let reader = RecordingReader::from_bytes(bytes.clone()).expect("opening");
        let frame1_offset = reader.records[1].offset as usize;
        let mut corrupt = bytes.clone();
        corrupt[frame1_offset + RECORD_HEADER_LEN + 5] ^= 0x10;
        let mut reader = RecordingReader::from_bytes(corrupt).expect("corrupt payloads are found when read");
        reader.read_frame(0).expect("frame 0 is intact");
        reader.read_frame(2).expect("frame 2 is intact");
        let message = recording_error(reader.read_frame(1));
        assert!(message.contains("frame 1: CRC mismatch"), "{message}");

        // A payload length larger than the file: rejected before anything is read or allocated.
        let mut huge = bytes;
        huge[frame1_offset + 24..frame1_offset + 28].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut reader = RecordingReader::from_bytes(huge).expect("opening");
        let message = recording_error(reader.read_frame(1));
        assert!(message.contains("frame 1: record claims"), "{message}");
    }

    #[test]
    fn rejects_bad_headers_with_clear_messages() {
        let bytes = small_recording();

        let mut newer = bytes.clone();
        newer[8..10].copy_from_slice(&4_u16.to_le_bytes());
        let message = recording_error(RecordingReader::from_bytes(newer.clone()));
        assert_eq!(message, "recording version 4 is newer than this build supports (3)", "without a fixed CRC");
        let message = recording_error(RecordingReader::from_bytes(with_header_crc(newer)));
        assert_eq!(message, "recording version 4 is newer than this build supports (3)", "with a fixed CRC");

        let mut reserved = bytes.clone();
        reserved[50] = 1;
        assert!(recording_error(RecordingReader::from_bytes(with_header_crc(reserved))).contains("reserved header bytes"), "reserved");

        let mut wrong_magic = bytes.clone();
        wrong_magic[1] = b'X';
        assert!(recording_error(RecordingReader::from_bytes(wrong_magic)).contains("wrong magic"), "magic");

        let mut header_flip = bytes.clone();
        header_flip[20] ^= 1;
        assert!(recording_error(RecordingReader::from_bytes(header_flip)).contains("header CRC mismatch"), "header CRC");

        let mut unknown_codec = bytes.clone();
        unknown_codec[41] = 9;
        assert!(
            recording_error(RecordingReader::from_bytes(with_header_crc(unknown_codec))).contains("unknown colour codec id 9"),
            "codec"
        );

        let mut huge_image = bytes.clone();
        huge_image[12..16].copy_from_slice(&u32::MAX.to_le_bytes());
        assert!(recording_error(RecordingReader::from_bytes(with_header_crc(huge_image))).contains("invalid calibration"), "size");

        let mut footer_index = bytes.clone();
        let at = footer_index.len() - FOOTER_LEN;
        footer_index[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        let crc = crc32fast::hash(&footer_index[at..at + 40]);
        footer_index[at + 40..at + 44].copy_from_slice(&crc.to_le_bytes());
        assert!(recording_error(RecordingReader::from_bytes(footer_index)).contains("does not end at the footer"), "index offset");

        let mut footer_reserved = bytes.clone();
        footer_reserved[at + 35] = 1;
        let crc = crc32fast::hash(&footer_reserved[at..at + 40]);
        footer_reserved[at + 40..at + 44].copy_from_slice(&crc.to_le_bytes());
        assert!(recording_error(RecordingReader::from_bytes(footer_reserved)).contains("reserved footer bytes"), "footer reserved");

        assert!(recording_error(RecordingReader::from_bytes(Vec::new())).contains("truncated"), "empty");
        assert!(recording_error(RecordingReader::from_bytes(RECORDING_MAGIC.to_vec())).contains("truncated"), "magic only");
    }

    #[test]
    fn unfinished_recordings_are_rejected() {
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), png_options()).expect("creating");
        writer.write_frame(&synthetic_frame(0)).expect("writing");
        let partial = writer.sink.get_ref().clone();
        assert!(recording_error(RecordingReader::from_bytes(partial)).contains("no footer"), "unfinished");
    }

    #[test]
    fn writer_rejects_bad_input() {
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), png_options()).expect("creating");
        let mut frame = synthetic_frame(0);
        frame.color = ColorImage::new(8, 12, vec![0; 8 * 12 * 3]).expect("size");
        assert!(matches!(writer.write_frame(&frame), Err(Error::FrameSize { what: "colour image", got_width: 8, .. })), "colour size");
        assert_eq!(writer.frame_count(), 0, "nothing written");

        let bad_quality = RecordingOptions { color_codec: ColorCodec::Jpeg, jpeg_quality: 0, ..RecordingOptions::default() };
        assert!(
            matches!(RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), bad_quality), Err(Error::InvalidConfig(_))),
            "quality"
        );
        let mut bad_calibration = small_calibration();
        bad_calibration.depth_units_per_metre = 0.0;
        assert!(
            matches!(RecordingWriter::new(Cursor::new(Vec::new()), bad_calibration, png_options()), Err(Error::InvalidConfig(_))),
            "units"
        );
        bad_calibration = small_calibration();
        bad_calibration.intrinsics.width_px = MAX_IMAGE_SIDE_PX + 1;
        assert!(
            matches!(RecordingWriter::new(Cursor::new(Vec::new()), bad_calibration, png_options()), Err(Error::InvalidConfig(_))),
            "width"
        );
    }

    /// Frames 0..n of the synthetic sequence, written; and where each record ends.
    fn recording_with_record_ends(n: u64, ground_truth: bool) -> (Vec<u8>, Vec<usize>) {
        let frames: Vec<RgbdFrame> = (0..n).map(synthetic_frame).collect();
        let bytes = record_to_bytes(png_options(), &frames, ground_truth.then(sample_ground_truth).as_deref());
        let reader = RecordingReader::from_bytes(bytes.clone()).expect("a finished recording opens");
        let ends = reader.records.iter().map(|r| r.end as usize).collect();
        (bytes, ends)
    }

    #[test]
    fn a_cut_at_every_byte_recovers_the_complete_records_before_it() {
        let (bytes, ends) = recording_with_record_ends(4, true);
        let mut strict = RecordingReader::from_bytes(bytes.clone()).expect("strict");
        let originals: Vec<EncodedFrame> = (0..4).map(|i| strict.read_encoded_frame(i).expect("frame")).collect();
        for cut in HEADER_LEN..bytes.len() {
            let mut reader = RecordingReader::from_bytes_recovering(bytes[..cut].to_vec()).unwrap_or_else(|e| panic!("cut at {cut}: {e}"));
            let want = ends.iter().filter(|&&end| end <= cut).count();
            let report = reader.recovery().cloned().unwrap_or_else(|| panic!("cut at {cut}: a cut file cannot open strictly"));
            assert_eq!((reader.frame_count(), report.frames_kept, report.records_dropped), (want, want, 0), "cut at {cut}: {report}");
            for (i, original) in originals.iter().enumerate().take(want) {
                assert_eq!(&reader.read_encoded_frame(i).expect("a kept frame reads"), original, "cut at {cut}: frame {i} bit-identical");
            }
            // The ground-truth block follows the last record: whole, or not at all.
            let gt_end = ends[3] + BLOCK_HEAD_LEN + sample_ground_truth().len() * POSE_LEN + CRC_LEN;
            assert_eq!(report.ground_truth_recovered, cut >= gt_end, "cut at {cut}: ground truth");
            if report.ground_truth_recovered {
                assert_eq!(reader.ground_truth(), Some(&sample_ground_truth()[..]), "cut at {cut}: poses exact");
            }
        }
        // Shorter than the header: nothing to recover, a clear error.
        let short = RecordingReader::from_bytes_recovering(bytes[..HEADER_LEN - 1].to_vec());
        assert!(matches!(&short, Err(Error::Recording { message, .. }) if message.contains("header")), "{:?}", short.err());
        // An intact file opens strictly, with no recovery to report.
        assert!(RecordingReader::from_bytes_recovering(bytes).expect("intact").recovery().is_none(), "intact file");
    }

    #[test]
    fn scanning_skips_damaged_records_and_counts_them() {
        let (bytes, ends) = recording_with_record_ends(6, false);
        let mut strict = RecordingReader::from_bytes(bytes.clone()).expect("strict");
        let originals: Vec<EncodedFrame> = (0..6).map(|i| strict.read_encoded_frame(i).expect("frame")).collect();
        // An unfinished take (no index or footer) with frames 1 and 2 damaged: a flipped
        // payload byte and a flipped length field.
        let mut damaged = bytes[..ends[5]].to_vec();
        damaged[ends[0] + RECORD_HEADER_LEN + 5] ^= 0x40;
        damaged[ends[1] + 24] ^= 0x01;
        let mut reader = RecordingReader::from_bytes_recovering(damaged).expect("recovers");
        let report = reader.recovery().cloned().expect("scanned");
        assert_eq!((report.frames_kept, report.records_dropped, report.tail_bytes_dropped), (4, 2, 0), "{report}");
        assert!(report.reason.contains("no footer"), "why the strict open failed: {}", report.reason);
        for (i, want) in [0, 3, 4, 5].iter().enumerate() {
            let got = reader.read_encoded_frame(i).expect("kept frame");
            assert_eq!((got.depth_payload.clone(), got.color_payload.clone()), (originals[*want].depth_payload.clone(), originals[*want].color_payload.clone()), "frame {i} is original {want}");
            assert_eq!(got.index, i as u64, "renumbered in order");
        }
        // Garbage after the last record is an unfinished tail, not a dropped record.
        let mut tail = bytes[..ends[5]].to_vec();
        tail.extend_from_slice(&RECORD_MAGIC);
        tail.extend_from_slice(&[7; 20]);
        let report = RecordingReader::from_bytes_recovering(tail).expect("recovers").recovery().cloned().expect("scanned");
        assert_eq!((report.frames_kept, report.records_dropped, report.tail_bytes_dropped), (6, 0, 24), "{report}");
        // A damaged index in a finished file: scanning still finds every frame.
        let mut bad_index = bytes.clone();
        let index_at = bad_index.len() - FOOTER_LEN - 4;
        bad_index[index_at] ^= 0xff;
        assert!(RecordingReader::from_bytes(bad_index.clone()).is_err(), "strict rejects the index");
        let report = RecordingReader::from_bytes_recovering(bad_index).expect("recovers").recovery().cloned().expect("scanned");
        assert_eq!((report.frames_kept, report.records_dropped), (6, 0), "{report}");
    }

    #[test]
    fn encoded_frames_pass_through_a_writer_unchanged() {
        let (bytes, _) = recording_with_record_ends(3, true);
        let mut reader = RecordingReader::from_bytes(bytes.clone()).expect("open");
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), reader.calibration(), png_options()).expect("writer");
        for i in 0..3 {
            writer.write_encoded_frame(&reader.read_encoded_frame(i).expect("frame")).expect("write");
        }
        writer.set_ground_truth(reader.ground_truth().expect("gt")).expect("gt after the frames");
        let (cursor, _) = writer.finish_into_inner().expect("finish");
        assert_eq!(cursor.into_inner(), bytes, "the same bytes as the original");
    }

    #[test]
    fn ground_truth_set_before_the_first_frame_survives_a_cut_anywhere_after_it() {
        let frames: Vec<RgbdFrame> = (0..3).map(synthetic_frame).collect();
        let poses = sample_ground_truth();
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), png_options()).expect("writer");
        writer.set_ground_truth(&poses).expect("written at once");
        let gt_end = HEADER_LEN + BLOCK_HEAD_LEN + poses.len() * POSE_LEN + CRC_LEN;
        assert_eq!(writer.bytes_written(), gt_end as u64, "the block follows the header");
        for frame in &frames {
            writer.write_frame(frame).expect("frame");
        }
        let refused = writer.set_ground_truth(&poses[..2]);
        assert!(matches!(&refused, Err(Error::InvalidConfig(m)) if m.contains("cannot be replaced")), "{refused:?}");
        writer.set_take_stats(TakeStats { duration_ns: 1_500_000_000, frames_dropped_by_source: 7 });
        let (cursor, summary) = writer.finish_into_inner().expect("finish");
        assert_eq!((summary.ground_truth_pose_count, summary.frame_count), (poses.len(), 3), "{summary:?}");
        let bytes = cursor.into_inner();

        let mut reader = RecordingReader::from_bytes(bytes.clone()).expect("strict open");
        assert_eq!(reader.ground_truth(), Some(&poses[..]), "poses exact");
        assert_eq!(reader.read_frame(2).expect("frame").depth, frames[2].depth, "records after the block");
        let take = reader.take_stats().expect("a timed take");
        assert_eq!((take.duration_ns, take.frames_dropped_by_source), (1_500_000_000, 7), "take stats");
        assert_eq!(take.frames_per_second(3), Some(2.0), "3 frames in 1.5 s");
        // A take killed at any byte after the block keeps the ground truth; before it, not.
        for cut in HEADER_LEN..bytes.len() - 1 {
            let reader = RecordingReader::from_bytes_recovering(bytes[..cut].to_vec()).unwrap_or_else(|e| panic!("cut at {cut}: {e}"));
            assert_eq!(reader.ground_truth().is_some(), cut >= gt_end, "cut at {cut}");
            assert!(reader.take_stats().is_none(), "cut at {cut}: the footer with the take stats is gone");
        }
        // A zero-frame take with ground truth only.
        let mut writer = RecordingWriter::new(Cursor::new(Vec::new()), small_calibration(), png_options()).expect("writer");
        writer.set_ground_truth(&poses).expect("written at once");
        let (cursor, _) = writer.finish_into_inner().expect("finish");
        let reader = RecordingReader::from_bytes(cursor.into_inner()).expect("strict open");
        assert_eq!((reader.frame_count(), reader.ground_truth().map(<[_]>::len)), (0, Some(poses.len())), "empty take");
        assert!(reader.take_stats().is_none(), "an untimed file");
    }

    /// Version 3's header byte 42 says the depth's noise; a version-2 file (that byte reserved,
    /// so 0) reads as a Kinect's, and an unknown id, or a non-zero byte in a version-2 header,
    /// is named.
    #[test]
    fn the_depth_noise_round_trips_and_older_files_read_as_a_kinects() {
        let frames: Vec<RgbdFrame> = (0..2).map(synthetic_frame).collect();
        for noise in [DepthNoise::KinectV1, DepthNoise::None] {
            let bytes = record_to_bytes(RecordingOptions { depth_noise: noise, ..png_options() }, &frames, None);
            assert_eq!(u16_at(&bytes, 8), 3);
            let reader = RecordingReader::from_bytes(bytes).expect("opening");
            assert_eq!(reader.depth_noise(), noise);
        }
        let exact = record_to_bytes(RecordingOptions { depth_noise: DepthNoise::None, ..png_options() }, &frames, None);
        let mut v2 = record_to_bytes(png_options(), &frames, None);
        v2[8..10].copy_from_slice(&2_u16.to_le_bytes());
        let reader = RecordingReader::from_bytes(with_header_crc(v2.clone())).expect("a version-2 file");
        assert_eq!(reader.depth_noise(), DepthNoise::KinectV1);
        v2[42] = 1;
        assert!(recording_error(RecordingReader::from_bytes(with_header_crc(v2))).contains("reserved header bytes"), "byte 42 of a version-2 header");
        let mut unknown = exact;
        unknown[42] = 7;
        assert_eq!(recording_error(RecordingReader::from_bytes(with_header_crc(unknown))), "unknown depth noise id 7");
    }

    #[test]
    fn version_1_files_still_read() {
        let mut reader = RecordingReader::open(SAMPLE_PATH).expect("the bundled sample opens");
        let header = std::fs::read(SAMPLE_PATH).expect("sample bytes");
        assert_eq!(u16_at(&header, 8), 1, "the bundled sample is a version 1 file");
        assert!(reader.recovery().is_none() && reader.take_stats().is_none(), "strict, no take stats");
        assert_eq!(reader.frame_count(), 100, "frames");
        assert!(reader.ground_truth().is_some_and(|gt| !gt.is_empty()), "ground truth");
        reader.read_frame(99).expect("the last frame reads");
    }

    #[test]
    fn garbage_never_panics() {
        let bytes = small_recording();
        let mut state = 0x2545_F491_4F6C_DD1D_u64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..300 {
            let mut corrupt = bytes.clone();
            for _ in 0..1 + next() % 16 {
                let ix = (next() % corrupt.len() as u64) as usize;
                corrupt[ix] = next() as u8;
            }
            read_everything(corrupt.clone()).ok();
            // Recovery reads whatever it kept, and every kept frame reads.
            let cut = (next() % corrupt.len() as u64) as usize;
            if let Ok(mut reader) = RecordingReader::from_bytes_recovering(corrupt[..cut].to_vec()) {
                for i in 0..reader.frame_count() {
                    reader.read_encoded_frame(i).expect("a frame recovery kept reads");
                }
            }
        }
        for len in [0, 7, 8, 63, 64, 100, 1000] {
            let mut garbage: Vec<u8> = (0..len).map(|_| next() as u8).collect();
            if len >= 8 {
                garbage[..8].copy_from_slice(&RECORDING_MAGIC);
            }
            assert!(read_everything(garbage).is_err(), "{len} bytes of garbage");
        }
    }

    #[test]
    #[ignore = "optional: needs ../shared/data (scripts/test.sh --extras)"]
    fn sample_recording_matches_the_tum_pngs() {
        let mut recording = RecordingReader::open(SAMPLE_PATH).expect("opening data/sample/fr1_rpy.wfr");
        let mut tum = TumDataset::open(shared_tum_fr1_rpy_dir(), None).expect("opening the TUM excerpt");
        assert_eq!(recording.frame_count(), 100, "frames");
        assert_eq!(recording.calibration(), tum.calibration(), "calibration");
        assert_eq!(recording.ground_truth(), tum.ground_truth(), "ground truth passes through exactly");
        for index in [0, 1, 50, 99] {
            let from_recording = recording.read_frame(index).expect("reading the recording");
            let from_tum = tum.read_frame(index).expect("reading the PNGs");
            assert_eq!(from_recording.depth, from_tum.depth, "frame {index}: depth bit for bit");
            assert_eq!(from_recording.depth_timestamp_ns, from_tum.depth_timestamp_ns, "frame {index}: depth timestamp");
            assert_eq!(from_recording.color_timestamp_ns, from_tum.color_timestamp_ns, "frame {index}: colour timestamp");
            let error: u64 = from_recording.color.rgb8.iter().zip(&from_tum.color.rgb8).map(|(&a, &b)| u64::from(a.abs_diff(b))).sum();
            let mean = error as f64 / from_tum.color.rgb8.len() as f64;
            assert!(mean < 4.0, "frame {index}: mean JPEG colour error {mean}");
        }
    }
}
