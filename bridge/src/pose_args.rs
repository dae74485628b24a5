// SPDX-License-Identifier: MIT
//! `--poses` / `--robot-poses` / `--robot-pose-form`: camera poses given on the command line,
//! shared by `reconstruct` (fuse at them) and `simulate` (render at them).

use std::path::PathBuf;

use anyhow::Context as _;
use webfusion_core::io::robot_poses::{RobotPose, RobotPoseForm, read_robot_poses};
use webfusion_core::io::trajectory::{TimedPose, read_tum_trajectory};

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
