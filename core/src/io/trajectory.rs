// SPDX-License-Identifier: MIT
//! TUM trajectory files: one pose per line, `timestamp tx ty tz qx qy qz qw`.
//!
//! The pose maps camera coordinates to world coordinates (`world_from_camera`), translation in
//! metres, rotation as a unit quaternion with the scalar last. `#` lines are comments. This is
//! the format of the benchmark's `groundtruth.txt` and of the trajectories its tools evaluate.

use std::fmt::Write as _;
use std::path::Path;

use glam::{DQuat, DVec3};

use super::{data_fields, format_timestamp_s, parse_timestamp_ns};
use crate::{Error, Result, Se3};

/// A camera pose at a point in time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedPose {
    /// Time of the pose, nanoseconds (same clock as the frames' timestamps).
    pub timestamp_ns: i64,
    /// Camera-to-world transform.
    pub world_from_camera: Se3,
}

/// A quaternion norm below this is treated as no rotation at all (malformed input).
const MIN_QUATERNION_NORM: f64 = 1e-6;

/// A quaternion whose norm is within this of 1 is taken as normalised already.
const UNIT_QUATERNION_TOLERANCE: f64 = 8.0 * f64::EPSILON;

/// Reads a TUM trajectory file.
pub fn read_tum_trajectory(path: &Path) -> Result<Vec<TimedPose>> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    parse_tum_trajectory(&text, path)
}

/// Parses the text of a TUM trajectory file; `path` only names the file in errors.
///
/// Quaternions are normalised (unless unit to rounding already); a line with the wrong number of fields, a non-finite number or
/// a zero quaternion is an [`Error::Parse`].
pub fn parse_tum_trajectory(text: &str, path: &Path) -> Result<Vec<TimedPose>> {
    let mut poses = Vec::new();
    for (line_ix, line) in text.lines().enumerate() {
        let Some(fields) = data_fields(line) else { continue };
        let parse_error = |message: String| Error::Parse { path: path.to_owned(), line: line_ix + 1, message };
        if fields.len() != 8 {
            return Err(parse_error(format!("expected 8 fields `timestamp tx ty tz qx qy qz qw`, found {}", fields.len())));
        }
        let timestamp_ns = parse_timestamp_ns(fields[0])
            .ok_or_else(|| parse_error(format!("invalid timestamp {:?}: expected decimal seconds", fields[0])))?;
        let mut values = [0.0_f64; 7];
        for (value, field) in values.iter_mut().zip(&fields[1..]) {
            *value = field.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| parse_error(format!("invalid number {field:?}")))?;
        }
        let [tx, ty, tz, qx, qy, qz, qw] = values;
        let quaternion = DQuat::from_xyzw(qx, qy, qz, qw);
        let norm = quaternion.length();
        if norm < MIN_QUATERNION_NORM {
            return Err(parse_error("quaternion has zero length".to_owned()));
        }
        // Leave quaternions that are unit to rounding untouched, so written poses read back bit for bit.
        let rotation = if (norm - 1.0).abs() <= UNIT_QUATERNION_TOLERANCE { quaternion } else { quaternion / norm };
        poses.push(TimedPose { timestamp_ns, world_from_camera: Se3 { rotation, translation_m: DVec3::new(tx, ty, tz) } });
    }
    Ok(poses)
}

/// Header line of [`format_tum_trajectory`] (newline included).
pub const TUM_TRAJECTORY_HEADER: &str = "# timestamp tx ty tz qx qy qz qw\n";

/// Renders poses in the TUM trajectory format, with a `#` header line.
///
/// Timestamps keep their exact nanosecond value ([`super::format_timestamp_s`]); numbers use
/// Rust's shortest representation that parses back to the same `f64`, so the text round-trips.
pub fn format_tum_trajectory(poses: &[TimedPose]) -> String {
    let mut text = String::with_capacity(32 + poses.len() * 96);
    text.push_str(TUM_TRAJECTORY_HEADER);
    for pose in poses {
        push_tum_line(&mut text, pose);
    }
    text
}

/// Appends one pose's line of [`format_tum_trajectory`] to `text` (for text that grows a
/// pose at a time).
pub fn push_tum_line(text: &mut String, pose: &TimedPose) {
    let t = pose.world_from_camera.translation_m;
    let q = pose.world_from_camera.rotation;
    // Writing to a String cannot fail.
    writeln!(text, "{} {} {} {} {} {} {} {}", format_timestamp_s(pose.timestamp_ns), t.x, t.y, t.z, q.x, q.y, q.z, q.w).ok();
}

/// Writes poses to a TUM trajectory file (see [`format_tum_trajectory`]).
pub fn write_tum_trajectory(path: &Path, poses: &[TimedPose]) -> Result<()> {
    std::fs::write(path, format_tum_trajectory(poses)).map_err(|source| Error::Io { path: path.to_owned(), source })
}

/// Largest distance in time between a frame and the nearest given pose for the frame to get a
/// pose: 20 ms, the TUM benchmark's association limit (`associate.py`).
pub const MAX_POSE_GAP_NS: i64 = 20_000_000;

/// Given poses, sorted by time, to look up a frame's pose by its timestamp (mapping from known
/// poses: `reconstruct --poses`).
#[derive(Clone, Debug, PartialEq)]
pub struct PoseTimeline {
    poses: Vec<TimedPose>,
}

impl PoseTimeline {
    /// The poses in time order. An empty list, or two poses with the same timestamp (which
    /// would make the lookup ambiguous), is an [`Error::InvalidConfig`] naming it.
    pub fn new(mut poses: Vec<TimedPose>) -> Result<Self> {
        if poses.is_empty() {
            return Err(Error::InvalidConfig("the given trajectory holds no pose".into()));
        }
        poses.sort_by_key(|p| p.timestamp_ns);
        if let Some(w) = poses.windows(2).find(|w| w[0].timestamp_ns == w[1].timestamp_ns) {
            return Err(Error::InvalidConfig(format!("the given trajectory has two poses at {}", format_timestamp_s(w[0].timestamp_ns))));
        }
        Ok(Self { poses })
    }

    /// The poses, in time order.
    pub fn poses(&self) -> &[TimedPose] {
        &self.poses
    }

    /// The pose at `t_ns`: interpolated between the two poses around it (linearly in
    /// translation, spherically in rotation), or the first or last pose at the ends, provided
    /// the nearest pose lies within `max_gap_ns`; `None` otherwise (the frame has no pose).
    pub fn pose_at(&self, t_ns: i64, max_gap_ns: i64) -> Option<Se3> {
        let after = self.poses.partition_point(|p| p.timestamp_ns < t_ns);
        let before = after.checked_sub(1).map(|i| &self.poses[i]);
        let next = self.poses.get(after);
        let nearest_gap = [before.map(|p| t_ns - p.timestamp_ns), next.map(|p| p.timestamp_ns - t_ns)].into_iter().flatten().min()?;
        if nearest_gap > max_gap_ns {
            return None;
        }
        Some(match (before, next) {
            (_, Some(b)) if b.timestamp_ns == t_ns => b.world_from_camera,
            (Some(a), Some(b)) => {
                let s = (t_ns - a.timestamp_ns) as f64 / (b.timestamp_ns - a.timestamp_ns) as f64;
                let (pa, pb) = (a.world_from_camera, b.world_from_camera);
                Se3 { rotation: pa.rotation.slerp(pb.rotation, s).normalize(), translation_m: pa.translation_m.lerp(pb.translation_m, s) }
            }
            (Some(a), None) => a.world_from_camera,
            (None, Some(b)) => b.world_from_camera,
            (None, None) => return None,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timeline_interpolates_between_poses_and_refuses_frames_without_one() {
        let p = |t_ms: i64, x: f64, yaw_deg: f64| TimedPose { timestamp_ns: t_ms * 1_000_000, world_from_camera: Se3::new(DQuat::from_rotation_z(yaw_deg.to_radians()), DVec3::new(x, 0.0, 0.0)) };
        // Out of order on purpose: the timeline sorts.
        let timeline = PoseTimeline::new(vec![p(100, 1.0, 10.0), p(0, 0.0, 0.0), p(1000, 5.0, 0.0)]).expect("timeline");
        // 15 % of the way from 0 to 100 ms: x 0.15, yaw 1.5°, exactly.
        let q = timeline.pose_at(15_000_000, MAX_POSE_GAP_NS).expect("a pose");
        assert!((q.translation_m.x - 0.15).abs() < 1e-12 && (q.rotation_angle_rad().to_degrees() - 1.5).abs() < 1e-9, "{q:?}");
        // On a pose: that pose.
        assert_eq!(timeline.pose_at(100_000_000, 0), Some(p(100, 1.0, 10.0).world_from_camera));
        // 50 ms from both neighbours: no pose within 20 ms.
        assert_eq!(timeline.pose_at(50_000_000, MAX_POSE_GAP_NS), None);
        // 15 ms after the last pose: the last pose; 25 ms before the first: none.
        assert_eq!(timeline.pose_at(1_015_000_000, MAX_POSE_GAP_NS), Some(p(1000, 5.0, 0.0).world_from_camera));
        assert_eq!(timeline.pose_at(-25_000_000, MAX_POSE_GAP_NS), None);
        // 10 ms after a pose whose next one is 900 ms away: interpolated along that long gap.
        let r = timeline.pose_at(110_000_000, MAX_POSE_GAP_NS).expect("a pose");
        assert!((r.translation_m.x - (1.0 + 4.0 * 10.0 / 900.0)).abs() < 1e-12);
        // Bad timelines are refused by name.
        assert!(PoseTimeline::new(Vec::new()).is_err());
        assert!(PoseTimeline::new(vec![p(5, 0.0, 0.0), p(5, 1.0, 0.0)]).is_err_and(|e| e.to_string().contains("two poses")));
    }
    use crate::io::test_util::{ScratchDir, shared_tum_fr1_rpy_dir};

    fn sample_poses() -> Vec<TimedPose> {
        vec![
            TimedPose { timestamp_ns: 1_305_031_229_528_784_000, world_from_camera: Se3::IDENTITY },
            TimedPose {
                timestamp_ns: 1_305_031_229_564_442_123,
                world_from_camera: Se3::new(DQuat::from_xyzw(0.6853, 0.5405, -0.0074, -0.4881), DVec3::new(1.3047, 0.6853, 1.5750)),
            },
            TimedPose {
                timestamp_ns: -42,
                world_from_camera: Se3::new(DQuat::from_rotation_y(0.1234567890123), DVec3::new(-1e-9, 1e12, 0.1 + 0.2)),
            },
        ]
    }

    #[test]
    fn round_trips_through_text() {
        let poses = sample_poses();
        let text = format_tum_trajectory(&poses);
        let parsed = parse_tum_trajectory(&text, Path::new("mem.txt")).expect("parsing what we wrote");
        assert_eq!(parsed, poses, "text:\n{text}");
        assert!(text.lines().nth(1).expect("first pose line").starts_with("1305031229.528784 "), "text:\n{text}");
    }

    #[test]
    fn round_trips_through_a_file() {
        let dir = ScratchDir::new("trajectory");
        let path = dir.path().join("traj.txt");
        let poses = sample_poses();
        write_tum_trajectory(&path, &poses).expect("writing");
        assert_eq!(read_tum_trajectory(&path).expect("reading"), poses, "file round trip");
    }

    #[test]
    #[ignore = "optional: needs ../shared/data (scripts/test.sh --extras)"]
    fn reads_tum_ground_truth() {
        let path = shared_tum_fr1_rpy_dir().join("groundtruth.txt");
        let poses = read_tum_trajectory(&path).expect("reading groundtruth.txt");
        assert_eq!(poses.len(), 430, "pose lines in groundtruth.txt");
        assert_eq!(poses[0].timestamp_ns, 1_305_031_229_033_100_000, "first timestamp");
        let t = poses[0].world_from_camera.translation_m;
        assert_eq!((t.x, t.y, t.z), (1.3047, 0.6853, 1.5750), "first translation");
        let q = poses[0].world_from_camera.rotation;
        let q_file = DQuat::from_xyzw(0.6853, 0.5405, -0.0074, -0.4881).normalize();
        assert!(q.abs_diff_eq(q_file, 1e-12), "first rotation {q:?}");
    }

    #[test]
    fn reports_malformed_lines_with_line_numbers() {
        let cases = [
            ("# header\n1.0 0 0 0 0 0 0\n", 2, "expected 8 fields"),
            ("\n\n1.0 0 0 0 0 0 0 1 9\n", 3, "expected 8 fields"),
            ("1.0 0 0 0 0 0 0 1\nx 0 0 0 0 0 0 1\n", 2, "invalid timestamp"),
            ("1.0 0 0 nan 0 0 0 1\n", 1, "invalid number"),
            ("1.0 0 0 0 0 0 0 abc\n", 1, "invalid number"),
            ("1.0 0 0 0 0 0 0 0\n", 1, "zero length"),
        ];
        for (text, want_line, want_message) in cases {
            match parse_tum_trajectory(text, Path::new("gt.txt")) {
                Err(Error::Parse { path, line, message }) => {
                    assert_eq!(path, Path::new("gt.txt"), "path in error for {text:?}");
                    assert_eq!(line, want_line, "line in error for {text:?}");
                    assert!(message.contains(want_message), "message {message:?} for {text:?}");
                }
                other => panic!("expected a parse error for {text:?}, got {other:?}"),
            }
        }
    }

    #[test]
    fn missing_file_is_an_io_error_naming_it() {
        let err = read_tum_trajectory(Path::new("/nonexistent/traj.txt")).expect_err("reading a missing file");
        assert!(matches!(&err, Error::Io { path, .. } if path == Path::new("/nonexistent/traj.txt")), "{err:?}");
    }
}
