// SPDX-License-Identifier: MIT
//! Map files (`.wfm`): a fused map saved for later (seed 000: build a room's map once, then
//! simulate the sensor in it or fuse more into it). They follow the project's file policy
//! (ARCHITECTURE.md, "Recording format"): what a reader needs first, self-checking records,
//! readable without the footer, written to `<path>.partial`, synced and renamed when finished.
//!
//! ```text
//! header (96 bytes, little-endian)
//!    0  magic  "WFMAP\r\n\x1a"
//!    8  version u32 (3; 1, 2 still read)  12  header bytes u32 (96)
//!   16  kind u32 (0 dense, 1 sparse)   20  flags u32 (bit 0: colour)
//!   24  block edge, voxels u32 (8)     28  voxel size, m f32     32  truncation, m f32
//!   36  max weight u32                 40  box dims, voxels [u32; 3]
//!   52  origin (the box's voxel (0,0,0) corner) in the world, m [f32; 3]
//!   64  frame u32 (0: the first camera of a tracked run, 1: the given poses' frame)
//!   68  creation-parameters bytes u32 (a JSON object after the header)
//!   72  up, a unit vector in the map's frame [f32; 3] (version 2; all 0: not known)
//!   84  noise band, σ of the Kinect model f32 (version 3; TsdfConfig::noise_band_sigmas)
//!   88  reserved u32 (0)               92  CRC-32 of bytes 0..92
//! (version 1 had reserved [u32; 5] at 72: read as "up not known"; versions 1 and 2 had
//! reserved words at 84: read as a noise band of 0, μ at every depth, as they were fused)
//! creation parameters: JSON, then its CRC-32 (u32)
//! block record, one per block, in key order (z, then y, then x):
//!    0  magic "WFBK"   4  block coordinates [u32; 3]
//!   16  voxel words [u32; 512] (snorm16 TSDF | weight << 16), then colour words (with colour)
//!   ..  CRC-32 of bytes 4.. of the record
//! footer (24 bytes): magic "WFMEND\0\0", block count u64, CRC-32 of the count, 0 u32
//! ```
//!
//! A damaged or truncated file still yields its intact blocks ([`read_map_file_recovering`],
//! with a [`MapDamage`] report); [`read_map_file`] refuses it with the problem named. A header
//! that fails its check is always an error: without it nothing can be placed.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use glam::DVec3;

use crate::Se3;
use crate::cpu::shared::{BLOCK_VOXELS, block_key};
use crate::map::{MapBlock, MapKind};
use crate::{Error, PinholeIntrinsics, Result};

const MAGIC: &[u8; 8] = b"WFMAP\r\n\x1a";
const BLOCK_MAGIC: &[u8; 4] = b"WFBK";
const FOOTER_MAGIC: &[u8; 8] = b"WFMEND\0\0";
/// The version this code writes (it reads this one, version 2, which fused with μ at every
/// depth, and version 1, which also had no up direction).
pub const MAP_FILE_VERSION: u32 = 3;
const HEADER_BYTES: usize = 96;
const FOOTER_BYTES: usize = 24;
/// Largest creation-parameters block a reader accepts.
const MAX_META_BYTES: u32 = 1 << 20;

/// Which frame a map's coordinates are in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MapFrame {
    /// The first camera of a tracked run.
    FirstCamera,
    /// The frame of the poses it was fused at (`reconstruct --poses`).
    GivenPoses,
}

/// What a map file says about its map.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFileHeader {
    /// Dense box or sparse blocks.
    pub kind: MapKind,
    /// Whether blocks carry colour words.
    pub color: bool,
    /// Voxel edge, metres.
    pub voxel_size_m: f32,
    /// Truncation distance μ, metres.
    pub truncation_m: f32,
    /// Standard deviations of the Kinect model a sample's truncation band spans where wider
    /// than μ (`TsdfConfig::noise_band_sigmas`; 0: μ at every depth, and every map of
    /// versions 1 and 2): how the stored TSDF values are scaled, so fusing more keeps it.
    pub noise_band_sigmas: f32,
    /// Cap of the integration weight.
    pub max_weight: u32,
    /// Voxels along x, y, z of the map's box (a sparse map's addressable range).
    pub dims_voxels: [u32; 3],
    /// World position of the box's voxel (0, 0, 0) corner, metres.
    pub origin_in_world: [f32; 3],
    /// The frame the map is in.
    pub frame: MapFrame,
    /// The world's up direction in the map's frame, a unit vector, where the maker knew it
    /// (`reconstruct`: the mean of the fused cameras' up axes, −y of each camera: a handheld
    /// or robot-mounted Kinect is held roughly level); a viewer orbits about it.
    pub up_in_map: Option<[f32; 3]>,
    /// How it was made (source, frames, settings): the text of a JSON object (UTF-8).
    pub creation: String,
}

impl MapFileHeader {
    /// The header of a map fused with `tsdf` whose box's voxel (0, 0, 0) corner lies at
    /// `origin_in_world` of `frame`.
    pub fn for_map(tsdf: &crate::tsdf::TsdfConfig, origin_in_world: [f32; 3], frame: MapFrame, up_in_map: Option<[f32; 3]>, creation: String) -> Self {
        Self {
            kind: tsdf.kind,
            color: tsdf.color,
            voxel_size_m: tsdf.voxel_size_m,
            truncation_m: tsdf.truncation_m,
            noise_band_sigmas: tsdf.noise_band_sigmas,
            max_weight: tsdf.max_weight,
            dims_voxels: tsdf.box_dims_voxels(),
            origin_in_world,
            frame,
            up_in_map,
            creation,
        }
    }

    /// The camera the map was fused from, as its creation parameters name it (`camera`:
    /// fx_px, fy_px, cx_px, cy_px, width_px, height_px; written by `reconstruct --save-map`),
    /// when it is there and valid: a virtual sensor renders what that camera would see unless
    /// told otherwise. Maps saved before it was recorded have none.
    pub fn fused_camera(&self) -> Option<PinholeIntrinsics> {
        let creation: serde_json::Value = serde_json::from_str(&self.creation).ok()?;
        let c = &creation["camera"];
        let f = |key: &str| c[key].as_f64().map(|v| v as f32).filter(|v| v.is_finite());
        let size = |key: &str| c[key].as_u64().and_then(|v| u32::try_from(v).ok()).filter(|v| (1..=crate::recording::MAX_IMAGE_SIDE_PX).contains(v));
        let k = PinholeIntrinsics { fx_px: f("fx_px")?, fy_px: f("fy_px")?, cx_px: f("cx_px")?, cy_px: f("cy_px")?, width_px: size("width_px")?, height_px: size("height_px")? };
        (k.fx_px > 0.0 && k.fy_px > 0.0).then_some(k)
    }
}

/// What a recovering read found wrong.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MapDamage {
    /// Damaged block records skipped (their bytes failed the check).
    pub damaged_blocks: usize,
    /// The file ends without its footer (a truncated or unfinished file).
    pub truncated: bool,
    /// Blocks the footer counts that were not read.
    pub missing_blocks: u64,
}

impl std::fmt::Display for MapDamage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} damaged block record(s) skipped", self.damaged_blocks)?;
        if self.truncated {
            write!(f, ", the file is truncated (no footer)")?;
        }
        if self.missing_blocks > 0 {
            write!(f, ", {} block(s) the footer counts are missing", self.missing_blocks)?;
        }
        Ok(())
    }
}

/// A map file's contents.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFile {
    /// Its header.
    pub header: MapFileHeader,
    /// Its intact blocks, in key order.
    pub blocks: Vec<MapBlock>,
    /// What a recovering read skipped (`None`: the file is intact).
    pub damage: Option<MapDamage>,
}

/// The world's up direction from the cameras that saw it: the normalised mean of their up axes
/// (−y of each camera, in the world). A handheld or robot-mounted Kinect is held roughly level,
/// so the mean points up even when single frames roll or pitch; `None` when there is no camera
/// or they disagree so much that the mean is shorter than a third (no direction to trust).
/// `prior` adds an up already known (a loaded map's) with the weight of `prior_cameras` cameras.
pub fn mean_camera_up<'a>(world_from_cameras: impl IntoIterator<Item = &'a Se3>, prior: Option<([f32; 3], usize)>) -> Option<[f32; 3]> {
    let (mut sum, mut n) = prior.map_or((DVec3::ZERO, 0usize), |(up, count)| (DVec3::from(up.map(f64::from)) * count as f64, count));
    for pose in world_from_cameras {
        sum -= pose.rotation * DVec3::Y;
        n += 1;
    }
    let mean = sum / n.max(1) as f64;
    (n > 0 && mean.length() > 1.0 / 3.0).then(|| mean.normalize().as_vec3().to_array())
}

fn record_bytes(color: bool) -> usize {
    16 + 4 * BLOCK_VOXELS as usize * if color { 2 } else { 1 } + 4
}

/// Writes `blocks` (any order; written in key order) under `header` to `path`, through
/// `<path>.partial` (synced, then renamed), so a crash never leaves a half-written map under the
/// final name. A block whose word counts do not match the header is an error.
pub fn write_map_file(path: &Path, header: &MapFileHeader, blocks: &[MapBlock]) -> Result<()> {
    let io = |source: std::io::Error| Error::Io { path: path.to_owned(), source };
    let n = BLOCK_VOXELS as usize;
    if let Some(b) = blocks.iter().find(|b| b.voxels.len() != n || (header.color && b.colors.len() != n)) {
        return Err(Error::MapFile { path: path.to_owned(), message: format!("block {:?} has {} voxel and {} colour words, not {n}", b.coords, b.voxels.len(), b.colors.len()) });
    }
    let mut order: Vec<&MapBlock> = blocks.iter().collect();
    order.sort_by_key(|b| block_key(b.coords));
    let partial = PathBuf::from(format!("{}.partial", path.display()));
    let file = std::fs::File::create(&partial).map_err(|source| Error::Io { path: partial.clone(), source })?;
    let mut out = std::io::BufWriter::new(file);
    let meta = header.creation.as_bytes();
    let mut h = Vec::with_capacity(HEADER_BYTES);
    h.extend_from_slice(MAGIC);
    for w in [MAP_FILE_VERSION, HEADER_BYTES as u32, u32::from(header.kind == MapKind::Sparse), u32::from(header.color), 8] {
        h.extend_from_slice(&w.to_le_bytes());
    }
    h.extend_from_slice(&header.voxel_size_m.to_le_bytes());
    h.extend_from_slice(&header.truncation_m.to_le_bytes());
    h.extend_from_slice(&header.max_weight.to_le_bytes());
    for d in header.dims_voxels {
        h.extend_from_slice(&d.to_le_bytes());
    }
    for o in header.origin_in_world {
        h.extend_from_slice(&o.to_le_bytes());
    }
    h.extend_from_slice(&u32::from(header.frame == MapFrame::GivenPoses).to_le_bytes());
    h.extend_from_slice(&(meta.len() as u32).to_le_bytes());
    for u in header.up_in_map.unwrap_or([0.0; 3]) {
        h.extend_from_slice(&u.to_le_bytes());
    }
    h.extend_from_slice(&header.noise_band_sigmas.to_le_bytes());
    h.extend_from_slice(&[0u8; 4]);
    let crc = crc32fast::hash(&h);
    h.extend_from_slice(&crc.to_le_bytes());
    debug_assert_eq!(h.len(), HEADER_BYTES, "the header layout in the module doc");
    out.write_all(&h).map_err(io)?;
    out.write_all(meta).map_err(io)?;
    out.write_all(&crc32fast::hash(meta).to_le_bytes()).map_err(io)?;
    let mut record = Vec::with_capacity(record_bytes(header.color));
    for b in &order {
        record.clear();
        record.extend_from_slice(BLOCK_MAGIC);
        for c in b.coords {
            record.extend_from_slice(&c.to_le_bytes());
        }
        record.extend_from_slice(bytemuck::cast_slice(&b.voxels));
        if header.color {
            record.extend_from_slice(bytemuck::cast_slice(&b.colors));
        }
        let crc = crc32fast::hash(&record[4..]);
        record.extend_from_slice(&crc.to_le_bytes());
        out.write_all(&record).map_err(io)?;
    }
    let count = order.len() as u64;
    out.write_all(FOOTER_MAGIC).map_err(io)?;
    out.write_all(&count.to_le_bytes()).map_err(io)?;
    out.write_all(&crc32fast::hash(&count.to_le_bytes()).to_le_bytes()).map_err(io)?;
    out.write_all(&0u32.to_le_bytes()).map_err(io)?;
    let file = out.into_inner().map_err(|e| io(e.into_error()))?;
    file.sync_all().map_err(io)?;
    std::fs::rename(&partial, path).map_err(io)
}

/// Reads an intact map file; any damage is an [`Error::MapFile`] naming it.
pub fn read_map_file(path: &Path) -> Result<MapFile> {
    let file = read_map_file_recovering(path)?;
    match &file.damage {
        Some(d) => Err(Error::MapFile { path: path.to_owned(), message: format!("{d} (a recovering read keeps the {} intact blocks)", file.blocks.len()) }),
        None => Ok(file),
    }
}

/// Reads a map file, keeping every intact block of a damaged or truncated one (damaged records
/// are skipped by finding the next record's magic) and reporting what it skipped. A bad header
/// is an error.
pub fn read_map_file_recovering(path: &Path) -> Result<MapFile> {
    let bytes = std::fs::read(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    parse_map_file(&bytes, path)
}

/// As [`read_map_file_recovering`], for a map file's bytes already in memory (the browser's
/// file picker, a download); `name` names it in errors.
pub fn parse_map_bytes(bytes: &[u8], name: &str) -> Result<MapFile> {
    parse_map_file(bytes, Path::new(name))
}

fn parse_map_file(bytes: &[u8], path: &Path) -> Result<MapFile> {
    let bad = |message: String| Error::MapFile { path: path.to_owned(), message };
    if bytes.len() < HEADER_BYTES || &bytes[..8] != MAGIC {
        return Err(bad(if bytes.len() >= 8 && &bytes[..8] != MAGIC { "not a webfusion map file (bad magic)".into() } else { format!("{} bytes: shorter than the {HEADER_BYTES}-byte header", bytes.len()) }));
    }
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let f32_at = |at: usize| f32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes"));
    let version = u32_at(8);
    if !(1..=MAP_FILE_VERSION).contains(&version) {
        return Err(bad(format!("version {version}; this webfusion reads versions 1 to {MAP_FILE_VERSION}")));
    }
    if crc32fast::hash(&bytes[..92]) != u32_at(92) {
        return Err(bad("the header fails its CRC check".into()));
    }
    // Version 1 reserved the words from 72 on; version 2 keeps the up direction there, version 3
    // also the noise band at 84.
    let reserved_from = match version {
        1 => 72,
        2 => 84,
        _ => 88,
    };
    if u32_at(12) as usize != HEADER_BYTES || u32_at(24) != 8 || (reserved_from..92).step_by(4).any(|at| u32_at(at) != 0) {
        return Err(bad("the header's sizes or reserved words are not this version's".into()));
    }
    let up = [f32_at(72), f32_at(76), f32_at(80)];
    let up_in_map = if version == 1 || up == [0.0; 3] {
        None
    } else {
        let norm = up.iter().map(|u| f64::from(*u).powi(2)).sum::<f64>().sqrt();
        if !((norm - 1.0).abs() < 1e-3) {
            return Err(bad(format!("the up direction {up:?} is not a unit vector")));
        }
        Some(up)
    };
    let kind = match u32_at(16) {
        0 => MapKind::Dense,
        1 => MapKind::Sparse,
        k => return Err(bad(format!("unknown map kind {k}"))),
    };
    let flags = u32_at(20);
    if flags > 1 {
        return Err(bad(format!("unknown flags {flags:#x}")));
    }
    let frame = match u32_at(64) {
        0 => MapFrame::FirstCamera,
        1 => MapFrame::GivenPoses,
        f => return Err(bad(format!("unknown frame {f}"))),
    };
    let noise_band_sigmas = if version >= 3 { f32_at(84) } else { 0.0 };
    if !(noise_band_sigmas >= 0.0 && noise_band_sigmas.is_finite()) {
        return Err(bad(format!("noise band of {noise_band_sigmas} standard deviations")));
    }
    let (voxel_size_m, truncation_m) = (f32_at(28), f32_at(32));
    if !(voxel_size_m > 0.0 && voxel_size_m.is_finite() && truncation_m > 0.0 && truncation_m.is_finite()) {
        return Err(bad(format!("voxel size {voxel_size_m} m, truncation {truncation_m} m")));
    }
    let meta_len = u32_at(68);
    if meta_len > MAX_META_BYTES || HEADER_BYTES + meta_len as usize + 4 > bytes.len() {
        return Err(bad(format!("creation parameters of {meta_len} bytes do not fit the file")));
    }
    let meta = &bytes[HEADER_BYTES..HEADER_BYTES + meta_len as usize];
    if crc32fast::hash(meta) != u32_at(HEADER_BYTES + meta_len as usize) {
        return Err(bad("the creation parameters fail their CRC check".into()));
    }
    let creation = String::from_utf8(meta.to_vec()).map_err(|e| bad(format!("creation parameters are not UTF-8: {e}")))?;
    let header = MapFileHeader {
        kind,
        color: flags & 1 != 0,
        voxel_size_m,
        truncation_m,
        noise_band_sigmas,
        max_weight: u32_at(36),
        dims_voxels: [u32_at(40), u32_at(44), u32_at(48)],
        origin_in_world: [f32_at(52), f32_at(56), f32_at(60)],
        frame,
        up_in_map,
        creation,
    };
    let n_box = header.dims_voxels.map(|d| d.div_ceil(8));
    let n = BLOCK_VOXELS as usize;
    let record = record_bytes(header.color);
    let mut at = HEADER_BYTES + meta_len as usize + 4;
    let (mut blocks, mut damaged, mut footer_count) = (Vec::new(), 0usize, None);
    let mut seen = std::collections::HashSet::new();
    while at < bytes.len() {
        if bytes.len() - at >= FOOTER_BYTES && &bytes[at..at + 8] == FOOTER_MAGIC {
            let count = u64::from_le_bytes(bytes[at + 8..at + 16].try_into().expect("8 bytes"));
            if crc32fast::hash(&bytes[at + 8..at + 16]) == u32_at(at + 16) && at + FOOTER_BYTES == bytes.len() {
                footer_count = Some(count);
                break;
            }
        }
        if bytes.len() - at >= record && &bytes[at..at + 4] == BLOCK_MAGIC && crc32fast::hash(&bytes[at + 4..at + record - 4]) == u32_at(at + record - 4) {
            let coords = [u32_at(at + 4), u32_at(at + 8), u32_at(at + 12)];
            let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[at + 16..at + record - 4]);
            // A record that checks but names a block outside the box, or one already read, is
            // damage too (a file spliced from another map).
            if (0..3).all(|a| coords[a] < n_box[a]) && seen.insert(coords) {
                let colors = if header.color { words[n..].to_vec() } else { Vec::new() };
                blocks.push(MapBlock { coords, voxels: words[..n].to_vec(), colors });
            } else {
                damaged += 1;
            }
            at += record;
            continue;
        }
        // Damage: resynchronise on the next record or footer magic.
        damaged += 1;
        let next = (at + 1..bytes.len().saturating_sub(3)).find(|&i| &bytes[i..i + 4] == BLOCK_MAGIC || (bytes.len() - i >= 8 && &bytes[i..i + 8] == FOOTER_MAGIC));
        match next {
            Some(i) => at = i,
            None => break,
        }
    }
    blocks.sort_by_key(|b| block_key(b.coords));
    let truncated = footer_count.is_none();
    let missing = footer_count.map_or(0, |c| c.saturating_sub(blocks.len() as u64));
    // A truncated tail that is only a partial record is not counted as a damaged record.
    let damage = (damaged > 0 || truncated || missing > 0).then_some(MapDamage { damaged_blocks: damaged, truncated, missing_blocks: missing });
    Ok(MapFile { header, blocks, damage })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(color: bool) -> MapFileHeader {
        MapFileHeader { kind: MapKind::Sparse, color, voxel_size_m: 0.01, truncation_m: 0.04, noise_band_sigmas: 3.0, max_weight: 128, dims_voxels: [16384, 16384, 8184], origin_in_world: [-81.92, -81.92, -40.92], frame: MapFrame::GivenPoses, up_in_map: color.then_some([0.0, 0.6, 0.8]), creation: r#"{"source":"test","frames":3}"#.to_owned() }
    }

    /// The fusing camera comes back from the creation parameters; a map without one, or with
    /// a camera that could not be (zero size, negative focal length, text), has none.
    #[test]
    fn the_fused_camera_is_read_from_the_creation_parameters() {
        let with = |creation: &str| MapFileHeader { creation: creation.to_owned(), ..header(false) }.fused_camera();
        let k = with(r#"{"camera":{"fx_px":517.3,"fy_px":516.5,"cx_px":318.6,"cy_px":255.3,"width_px":640,"height_px":480,"depth_units_per_metre":5000}}"#);
        assert_eq!(k, Some(PinholeIntrinsics { fx_px: 517.3, fy_px: 516.5, cx_px: 318.6, cy_px: 255.3, width_px: 640, height_px: 480 }));
        assert_eq!(header(false).fused_camera(), None, "no camera recorded");
        for bad in [
            r#"{"camera":{"fx_px":-517.3,"fy_px":516.5,"cx_px":318.6,"cy_px":255.3,"width_px":640,"height_px":480}}"#,
            r#"{"camera":{"fx_px":517.3,"fy_px":516.5,"cx_px":318.6,"cy_px":255.3,"width_px":0,"height_px":480}}"#,
            r#"{"camera":{"fx_px":"517","fy_px":516.5,"cx_px":318.6,"cy_px":255.3,"width_px":640,"height_px":480}}"#,
            "not json",
        ] {
            assert_eq!(with(bad), None, "{bad}");
        }
    }

    fn blocks(color: bool) -> Vec<MapBlock> {
        (0..20u32)
            .map(|i| MapBlock { coords: [1000 + i % 5, 1000 + i / 5, 500 + i % 3], voxels: (0..512).map(|v| (v * 7919 + i) | 0x1_0000).collect(), colors: if color { (0..512).map(|v| v ^ (i << 8)).collect() } else { Vec::new() } })
            .collect()
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("webfusion-mapfile-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch");
        dir.join("map.wfm")
    }

    #[test]
    fn a_map_round_trips_exactly_in_key_order() {
        for color in [true, false] {
            let path = scratch(&format!("rt{color}"));
            let mut given = blocks(color);
            given.reverse();
            write_map_file(&path, &header(color), &given).expect("write");
            let file = read_map_file(&path).expect("read");
            assert_eq!(file.header, header(color));
            given.sort_by_key(|b| block_key(b.coords));
            assert_eq!(file.blocks, given, "the same blocks, in key order");
            assert!(file.damage.is_none());
            assert!(!PathBuf::from(format!("{}.partial", path.display())).exists(), "the partial file was renamed");
        }
    }

    /// The header's bytes with their CRC recomputed (an edit that only the content check sees).
    fn with_header_crc(mut bytes: Vec<u8>) -> Vec<u8> {
        let crc = crc32fast::hash(&bytes[..92]);
        bytes[92..96].copy_from_slice(&crc.to_le_bytes());
        bytes
    }

    #[test]
    fn a_version_1_file_reads_with_no_up_direction_and_keeps_its_reserved_words_checked() {
        let path = scratch("v1");
        write_map_file(&path, &header(true), &blocks(true)).expect("write");
        let mut v1 = std::fs::read(&path).expect("bytes");
        // What version 1 wrote: the version word 1 and zeros where versions 2 and 3 keep the up
        // and the noise band.
        v1[8] = 1;
        v1[72..88].fill(0);
        let file = parse_map_file(&with_header_crc(v1.clone()), &path).expect("version 1 reads");
        assert_eq!(file.header, MapFileHeader { up_in_map: None, noise_band_sigmas: 0.0, ..header(true) });
        assert_eq!(file.blocks.len(), 20);
        // Version 1's reserved words include 72..84: an up there is not version 1's.
        let mut v1_up = v1;
        v1_up[80..84].copy_from_slice(&1.0f32.to_le_bytes());
        assert!(parse_map_file(&with_header_crc(v1_up), &path).is_err_and(|e| e.to_string().contains("reserved")));
        // Negative control: the same up in a version 2 header is read.
        let mut v2 = std::fs::read(&path).expect("bytes");
        v2[8] = 2;
        v2[72..84].copy_from_slice(bytemuck::cast_slice(&[0.0f32, 0.0, 1.0]));
        v2[84..88].fill(0);
        let file = parse_map_file(&with_header_crc(v2.clone()), &path).expect("version 2");
        assert_eq!((file.header.up_in_map, file.header.noise_band_sigmas), (Some([0.0, 0.0, 1.0]), 0.0));
    }

    #[test]
    fn the_noise_band_is_read_from_version_3_and_is_0_before() {
        let path = scratch("noise");
        write_map_file(&path, &header(true), &blocks(true)).expect("write");
        let v3 = std::fs::read(&path).expect("bytes");
        assert_eq!(parse_map_file(&v3, &path).expect("version 3").header.noise_band_sigmas, 3.0);
        // Version 2 fused with μ at every depth and reserved the word: a band there is not
        // version 2's.
        let mut v2 = v3.clone();
        v2[8] = 2;
        assert!(parse_map_file(&with_header_crc(v2.clone()), &path).is_err_and(|e| e.to_string().contains("reserved")));
        v2[84..88].fill(0);
        assert_eq!(parse_map_file(&with_header_crc(v2), &path).expect("version 2").header.noise_band_sigmas, 0.0);
        // A negative or non-finite band is named.
        for bad in [-1.0f32, f32::NAN, f32::INFINITY] {
            let mut b = v3.clone();
            b[84..88].copy_from_slice(&bad.to_le_bytes());
            assert!(parse_map_file(&with_header_crc(b), &path).is_err_and(|e| e.to_string().contains("noise band")), "{bad}");
        }
        // The word after it stays reserved.
        let mut r = v3;
        r[88] = 1;
        assert!(parse_map_file(&with_header_crc(r), &path).is_err_and(|e| e.to_string().contains("reserved")));
    }

    #[test]
    fn the_up_direction_is_the_mean_of_the_cameras_up_axes() {
        use glam::DQuat;
        // Cameras of a Z-up world (TUM's mocap, seed 000's robot), level with z forward along
        // the floor: camera y (down) is world -z; two rolled ±30° average back to up.
        let level = DQuat::from_rotation_x(-std::f64::consts::FRAC_PI_2);
        let poses: Vec<Se3> = [-0.5, 0.5, 0.0].iter().map(|r: &f64| Se3 { rotation: level * DQuat::from_rotation_z(*r), translation_m: DVec3::ZERO }).collect();
        let up = mean_camera_up(&poses, None).expect("an up");
        assert!((DVec3::from(up.map(f64::from)) - DVec3::Z).length() < 1e-6, "{up:?}");
        // A camera's own frame (a tracked run's first camera): up is -y.
        assert_eq!(mean_camera_up([&Se3::IDENTITY], None), Some([0.0, -1.0, 0.0]));
        // No camera, or cameras that disagree (one upside down): no direction.
        assert_eq!(mean_camera_up([], None), None);
        let flipped = Se3 { rotation: DQuat::from_rotation_z(std::f64::consts::PI), translation_m: DVec3::ZERO };
        assert_eq!(mean_camera_up([&Se3::IDENTITY, &flipped], None), None);
        // A prior (a loaded map's up) counts as its cameras.
        let with_prior = mean_camera_up([&flipped], Some(([0.0, -1.0, 0.0], 3))).expect("an up");
        assert!((DVec3::from(with_prior.map(f64::from)) - DVec3::NEG_Y).length() < 1e-6, "{with_prior:?}");
    }

    #[test]
    fn damage_anywhere_keeps_the_intact_blocks_and_is_named() {
        let path = scratch("damage");
        let given = blocks(true);
        write_map_file(&path, &header(true), &given).expect("write");
        let bytes = std::fs::read(&path).expect("bytes");
        let first_record = HEADER_BYTES + header(true).creation.len() + 4;
        let record = record_bytes(true);
        // A flipped bit inside the third block: that block is lost, the other 19 kept.
        let mut flipped = bytes.clone();
        flipped[first_record + 2 * record + 100] ^= 0x10;
        let file = parse_map_file(&flipped, &path).expect("recovering read");
        assert_eq!(file.blocks.len(), 19);
        let d = file.damage.clone().expect("damage reported");
        assert_eq!((d.damaged_blocks, d.truncated, d.missing_blocks), (1, false, 1));
        assert!(file.blocks.iter().all(|b| given.contains(b)), "every kept block is intact");
        std::fs::write(&path, &flipped).expect("write");
        let err = read_map_file(&path).expect_err("the strict read refuses damage");
        assert!(err.to_string().contains("1 damaged block") && err.to_string().contains("19 intact"), "{err}");
        // Cut at every byte past the header: never a panic, the complete blocks before the cut
        // kept, the truncation named.
        for cut in (HEADER_BYTES..bytes.len()).step_by(97) {
            match parse_map_file(&bytes[..cut], &path) {
                Ok(f) => {
                    let complete = cut.saturating_sub(first_record) / record;
                    assert_eq!(f.blocks.len(), complete.min(20), "cut at {cut}");
                    assert!(f.damage.is_some_and(|d| d.truncated), "cut at {cut}: truncation reported");
                }
                Err(e) => assert!(cut < first_record, "cut at {cut}: only a cut header or parameters is an error ({e})"),
            }
        }
        // A bad header, a foreign file, a newer version: errors naming the problem.
        let mut bad = bytes.clone();
        bad[30] ^= 1;
        assert!(parse_map_file(&bad, &path).is_err_and(|e| e.to_string().contains("CRC")));
        assert!(parse_map_file(b"PLY\nformat binary_little_endian 1.0\n.........................................................................................", &path).is_err_and(|e| e.to_string().contains("magic")));
        let mut newer = bytes.clone();
        newer[8] = 4;
        assert!(parse_map_file(&with_header_crc(newer), &path).is_err_and(|e| e.to_string().contains("version 4")));
        // An up direction that is not a unit vector (a foreign writer's, or 0 in one word only).
        let mut skew = bytes.clone();
        skew[72..76].copy_from_slice(&2.0f32.to_le_bytes());
        assert!(parse_map_file(&with_header_crc(skew), &path).is_err_and(|e| e.to_string().contains("not a unit vector")));
        // Negative control: the intact bytes parse without damage.
        assert!(parse_map_file(&bytes, &path).expect("intact").damage.is_none());
    }
}
