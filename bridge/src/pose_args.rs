// SPDX-License-Identifier: MIT
//! `--poses` / `--robot-poses` / `--robot-pose-form`: camera poses given on the command line,
//! shared by `reconstruct` (fuse at them), `simulate` (render at them) and `planes` (build the
//! world model at them).

use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::Se3;
use webfusion_core::io::robot_poses::{RobotPose, RobotPoseForm, read_robot_poses};
use webfusion_core::io::trajectory::{MAX_POSE_GAP_NS, PoseTimeline, TimedPose, read_tum_trajectory};

#[derive(clap::Args, Clone, Debug)]
pub(crate) struct PoseFileArgs {
    /// Camera-to-world poses, a TUM trajectory file (`timestamp tx ty tz qx qy qz qw`).
    /// `reconstruct` fuses each frame at the pose at its depth timestamp instead of tracking
    /// (interpolated between the two nearest poses when the nearest is within 20 ms; frames
    /// without one are skipped and counted; the map and outputs are in the poses' frame);
    /// `simulate` renders one frame per pose, at its timestamp.
    #[arg(long, conflicts_with = "robot_poses")]
    pub(crate) poses: Option<PathBuf>,
    /// Like `--poses`, with seed 000's robot poses: x y z (cm) α β γ (rad; world X right, Y
    /// forward, Z up; T = Trans·Rz(α)·Ry(β)·Rx(γ)) per line, or the planar form (see
    /// `--robot-pose-form`); one per frame in frame order (1/30 s apart for `simulate`), or each
    /// with a leading timestamp (seconds, then associated as `--poses` is).
    #[arg(long)]
    pub(crate) robot_poses: Option<PathBuf>,
    /// The form of `--robot-poses`: `6dof` (x y z α β γ) or `planar` (x y θ pan tilt: a base
    /// heading and a pan-tilt head at a fixed height).
    #[arg(long, default_value = "6dof")]
    pub(crate) robot_pose_form: RobotPoseForm,
}

impl PoseFileArgs {
    /// The file of `--poses` or `--robot-poses`.
    pub(crate) fn file(&self) -> Option<&PathBuf> {
        self.poses.as_ref().or(self.robot_poses.as_ref())
    }

    /// `--poses`, read.
    pub(crate) fn tum(&self) -> anyhow::Result<Option<Vec<TimedPose>>> {
        self.poses.as_ref().map(|path| read_tum_trajectory(path).with_context(|| format!("reading the given poses {}", path.display()))).transpose()
    }

    /// `--robot-poses`, read.
    pub(crate) fn robot(&self) -> anyhow::Result<Option<Vec<RobotPose>>> {
        self.robot_poses.as_ref().map(|path| read_robot_poses(path, self.robot_pose_form).with_context(|| format!("reading the robot poses {}", path.display()))).transpose()
    }
}

/// Poses given on the command line: by time (TUM `--poses`, or `--robot-poses` with
/// timestamps) or one per frame in frame order (`--robot-poses` without).
pub(crate) enum GivenPoses {
    Timeline(PoseTimeline),
    FrameOrder(Vec<Se3>),
}

impl GivenPoses {
    /// The pose of the `position`-th frame of the run (at depth time `t_ns`).
    pub(crate) fn pose_for(&self, position: usize, t_ns: i64) -> Option<Se3> {
        match self {
            Self::Timeline(t) => t.pose_at(t_ns, MAX_POSE_GAP_NS),
            Self::FrameOrder(poses) => poses.get(position).copied(),
        }
    }

    /// The first given pose.
    pub(crate) fn first(&self) -> Option<Se3> {
        match self {
            Self::Timeline(t) => t.poses().first().map(|p| p.world_from_camera),
            Self::FrameOrder(poses) => poses.first().copied(),
        }
    }
}

impl PoseFileArgs {
    /// The given poses of `--poses` or `--robot-poses`, read and checked (`None` without
    /// either).
    pub(crate) fn read(&self) -> anyhow::Result<Option<GivenPoses>> {
        if let Some(poses) = self.tum()? {
            return Ok(Some(GivenPoses::Timeline(PoseTimeline::new(poses).with_context(|| format!("the given poses {}", self.file().map(|p| p.display().to_string()).unwrap_or_default()))?)));
        }
        let Some(path) = &self.robot_poses else { return Ok(None) };
        let poses = self.robot()?.unwrap_or_default();
        if poses.iter().all(|p| p.timestamp_ns.is_some()) {
            let timed = poses.iter().map(|p| TimedPose { timestamp_ns: p.timestamp_ns.unwrap_or_default(), world_from_camera: p.world_from_camera }).collect();
            return Ok(Some(GivenPoses::Timeline(PoseTimeline::new(timed).with_context(|| format!("the robot poses {}", path.display()))?)));
        }
        Ok(Some(GivenPoses::FrameOrder(poses.iter().map(|p| p.world_from_camera).collect())))
    }
}
