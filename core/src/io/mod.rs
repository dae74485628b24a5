// SPDX-License-Identifier: MIT
//! Readers and writers of dataset files: TUM RGB-D directories and TUM trajectory files.
//!
//! Timestamps in these files are decimal seconds (`1305031229.528784`). They are parsed
//! digit by digit into integer nanoseconds, never through `f64`, so a timestamp written back
//! is the one that was read.

pub mod robot_poses;
pub mod trajectory;
pub mod tum;

pub use trajectory::{TUM_TRAJECTORY_HEADER, TimedPose, format_tum_trajectory, parse_tum_trajectory, push_tum_line, read_tum_trajectory, write_tum_trajectory};
pub use tum::{CALIBRATION_FILE, DEFAULT_MAX_TIME_DIFFERENCE_NS, TumDataset, TumFrameFiles, TumOptions, WrittenCalibration, format_calibration_file, read_calibration_file};

/// Nanoseconds per second.
const NS_PER_S: i64 = 1_000_000_000;

/// Parses decimal seconds (`1305031229.528784`, `-0.5`, `12`) into integer nanoseconds.
///
/// Accepts an optional sign, digits, and an optional `.` with up to 9 fractional digits (more
/// are accepted only if the extra digits are zeros). Returns `None` for anything else (exponents,
/// `inf`, empty strings, sub-nanosecond precision) and on `i64` overflow.
pub fn parse_timestamp_ns(text: &str) -> Option<i64> {
    let (negative, unsigned) = match text.as_bytes().first()? {
        b'-' => (true, &text[1..]),
        b'+' => (false, &text[1..]),
        _ => (false, text),
    };
    let (int_part, frac_part) = match unsigned.split_once('.') {
        Some((i, f)) => (i, f),
        None => (unsigned, ""),
    };
    if int_part.is_empty() && frac_part.is_empty() {
        return None;
    }
    if !int_part.bytes().all(|b| b.is_ascii_digit()) || !frac_part.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    let mut seconds: i64 = 0;
    for digit in int_part.bytes() {
        seconds = seconds.checked_mul(10)?.checked_add(i64::from(digit - b'0'))?;
    }
    let (frac_ns_digits, sub_ns_digits) = frac_part.split_at(frac_part.len().min(9));
    if sub_ns_digits.bytes().any(|b| b != b'0') {
        return None;
    }
    let mut frac_ns: i64 = 0;
    for digit in frac_ns_digits.bytes() {
        frac_ns = frac_ns * 10 + i64::from(digit - b'0');
    }
    for _ in frac_ns_digits.len()..9 {
        frac_ns *= 10;
    }
    let magnitude = seconds.checked_mul(NS_PER_S)?.checked_add(frac_ns)?;
    Some(if negative { -magnitude } else { magnitude })
}

/// Formats integer nanoseconds as decimal seconds with at least 6 fractional digits
/// (`1305031229528784000` → `1305031229.528784`); further digits appear only when non-zero, so
/// [`parse_timestamp_ns`] gives back exactly `timestamp_ns`.
pub fn format_timestamp_s(timestamp_ns: i64) -> String {
    let magnitude = timestamp_ns.unsigned_abs();
    let seconds = magnitude / NS_PER_S.unsigned_abs();
    let frac_ns = magnitude % NS_PER_S.unsigned_abs();
    let mut frac = format!("{frac_ns:09}");
    while frac.len() > 6 && frac.ends_with('0') {
        frac.pop();
    }
    let sign = if timestamp_ns < 0 { "-" } else { "" };
    format!("{sign}{seconds}.{frac}")
}

/// Splits a data line of a TUM text file into fields: separators are spaces, tabs and commas
/// (as in the benchmark's `associate.py`). Returns `None` for blank lines and `#` comments.
fn data_fields(line: &str) -> Option<Vec<&str>> {
    let trimmed = line.trim();
    if trimmed.is_empty() || trimmed.starts_with('#') {
        return None;
    }
    Some(trimmed.split(|c: char| c.is_whitespace() || c == ',').filter(|f| !f.is_empty()).collect())
}

#[cfg(test)]
pub(crate) mod test_util {
    //! Scratch directories for tests that write files.

    use std::path::{Path, PathBuf};
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A fresh directory under the system temp dir, removed on drop.
    pub(crate) struct ScratchDir {
        path: PathBuf,
    }

    impl ScratchDir {
        /// Creates `<tmp>/webfusion-test-<pid>-<n>-<name>`.
        pub(crate) fn new(name: &str) -> Self {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let path = std::env::temp_dir().join(format!("webfusion-test-{}-{n}-{name}", std::process::id()));
            if path.exists() {
                std::fs::remove_dir_all(&path).expect("removing a stale scratch dir");
            }
            std::fs::create_dir_all(&path).expect("creating a scratch dir");
            Self { path }
        }

        /// The directory.
        pub(crate) fn path(&self) -> &Path {
            &self.path
        }
    }

    impl Drop for ScratchDir {
        fn drop(&mut self) {
            std::fs::remove_dir_all(&self.path).ok();
        }
    }

    /// The bundled sample recording (TUM `freiburg1_rpy`, frames 0-99, with ground truth):
    /// what tests read real Kinect frames from.
    pub(crate) const SAMPLE_RECORDING: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../data/sample/fr1_rpy.wfr");

    /// The original TUM excerpt the sample was made from, for the optional checks against the
    /// benchmark's own files (`#[ignore]`d; `scripts/test.sh --extras` runs them):
    /// `$WEBFUSION_SHARED_DATA/tum_fr1_rpy_0-99`, by default `../shared/data` beside the
    /// repository.
    pub(crate) fn shared_tum_fr1_rpy_dir() -> PathBuf {
        let data = std::env::var_os("WEBFUSION_SHARED_DATA")
            .map_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data"), PathBuf::from);
        let dir = data.join("tum_fr1_rpy_0-99");
        assert!(dir.join("depth.txt").is_file(), "this optional check needs the shared TUM excerpt at {} (set WEBFUSION_SHARED_DATA)", dir.display());
        dir
    }

    /// Frames `frames` of the sample recording written as a TUM directory named like the
    /// benchmark's (`rgbd_dataset_freiburg1_rpy`, so its calibration is found from the path)
    /// inside a fresh scratch directory; returns both (the directory lives as long as the
    /// scratch).
    pub(crate) fn sample_as_tum(frames: std::ops::Range<usize>) -> (ScratchDir, PathBuf) {
        let scratch = ScratchDir::new("sample-tum");
        let dir = scratch.path().join("rgbd_dataset_freiburg1_rpy");
        let mut sample = crate::recording::RecordingReader::open(SAMPLE_RECORDING).expect("opening data/sample/fr1_rpy.wfr");
        crate::io::tum::write_tum_dataset(&dir, &mut sample, frames).expect("writing the sample as a TUM directory");
        (scratch, dir)
    }

    /// Frame `index` of the sample recording.
    pub(crate) fn sample_frame(index: usize) -> crate::RgbdFrame {
        use crate::source::FrameSource as _;
        crate::recording::RecordingReader::open(SAMPLE_RECORDING).expect("opening data/sample/fr1_rpy.wfr").read_frame(index).expect("reading a sample frame")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_timestamps_exactly() {
        assert_eq!(parse_timestamp_ns("1305031229.528784"), Some(1_305_031_229_528_784_000));
        assert_eq!(parse_timestamp_ns("1305031229.0331"), Some(1_305_031_229_033_100_000));
        assert_eq!(parse_timestamp_ns("12"), Some(12_000_000_000));
        assert_eq!(parse_timestamp_ns("12."), Some(12_000_000_000));
        assert_eq!(parse_timestamp_ns(".5"), Some(500_000_000));
        assert_eq!(parse_timestamp_ns("-0.5"), Some(-500_000_000));
        assert_eq!(parse_timestamp_ns("+1.000000001"), Some(1_000_000_001));
        assert_eq!(parse_timestamp_ns("1.0000000010"), Some(1_000_000_001));
        assert_eq!(parse_timestamp_ns("9223372036.854775807"), Some(i64::MAX));
    }

    #[test]
    fn rejects_malformed_timestamps() {
        for bad in ["", "-", ".", "1.2.3", "1e9", "inf", "NaN", " 1", "1 ", "0x10", "1.0000000001", "9223372036.854775808", "--1", "1,5"] {
            assert_eq!(parse_timestamp_ns(bad), None, "{bad:?} should be rejected");
        }
    }

    #[test]
    fn formats_timestamps_with_at_least_six_decimals() {
        assert_eq!(format_timestamp_s(1_305_031_229_528_784_000), "1305031229.528784");
        assert_eq!(format_timestamp_s(1_305_031_229_033_100_000), "1305031229.033100");
        assert_eq!(format_timestamp_s(1_000_000_001), "1.000000001");
        assert_eq!(format_timestamp_s(1_000_000_010), "1.00000001");
        assert_eq!(format_timestamp_s(0), "0.000000");
        assert_eq!(format_timestamp_s(-1_500_000), "-0.001500");
        assert_eq!(format_timestamp_s(i64::MIN), "-9223372036.854775808");
    }

    #[test]
    fn timestamp_format_round_trips() {
        let mut state = 0x9E37_79B9_7F4A_7C15_u64;
        for _ in 0..10_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let t = state as i64;
            if t == i64::MIN {
                continue;
            }
            assert_eq!(parse_timestamp_ns(&format_timestamp_s(t)), Some(t), "round trip of {t}");
        }
        assert_eq!(parse_timestamp_ns(&format_timestamp_s(i64::MAX)), Some(i64::MAX), "round trip of i64::MAX");
    }

    #[test]
    fn splits_data_lines() {
        assert_eq!(data_fields("# comment"), None);
        assert_eq!(data_fields("   "), None);
        assert_eq!(data_fields("1.0 rgb/a.png"), Some(vec!["1.0", "rgb/a.png"]));
        assert_eq!(data_fields("1.0,\trgb/a.png\r"), Some(vec!["1.0", "rgb/a.png"]));
    }
}
