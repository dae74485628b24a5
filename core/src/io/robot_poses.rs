// SPDX-License-Identifier: MIT
//! Seed 000's robot poses: the sensor pose a robot reports for each capture, in the thesis's
//! conventions (`../shared/seeds/000-digest.md`, §5.1, Eqs. 5.1-5.4 and the errata).
//!
//! - World: right-handed, X right, Y forward (the robot's), Z up, origin at the first capture;
//!   positions in **centimetres**, angles in radians, counter-clockwise positive.
//! - Sensor pose (6 degrees of freedom): T = Trans(x, y, z) · Rz(α) · Ry(β) · Rx(γ), with α the
//!   head's turn (positive left), β its roll, γ its tilt (positive up). The thesis prints element
//!   (2,3) of the product as −cos α sin γ + sin α sin β **sin** γ; the product is
//!   −cos α sin γ + sin α sin β **cos** γ (erratum), which building it from the factors gives.
//! - Sensor axes (Eq. 5.3): a camera point (x_c right, y_c down, z_c forward, the pinhole frame
//!   webfusion uses) is (x_c, z_c, −y_c) in the sensor frame (X right, Y forward, Z up) before T.
//! - Planar form (a wheeled robot with a pan-tilt head at a fixed height, footnote 1 of Ch. 5):
//!   base x, y (cm), heading θ about Z, head pan (about Z) and tilt (about X): the sensor pose
//!   (x, y, 0, θ + pan, 0, tilt). The offset between the tilt axis and the sensor (the thesis's
//!   suspect for measurement 9) is not modelled, as in the thesis.
//!
//! Files hold one pose per line (`#` comments): `x y z α β γ` (6dof) or `x y θ pan tilt`
//! (planar), one per frame in frame order, or each with a leading timestamp in seconds.

use std::path::Path;

use glam::{DMat3, DQuat, DVec3};

use super::{data_fields, parse_timestamp_ns};
use crate::{Error, Result, Se3};

/// Which of 000's pose forms a file holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RobotPoseForm {
    /// `x y z α β γ`: the sensor's 6-degree-of-freedom pose.
    SixDof,
    /// `x y θ pan tilt`: a planar base and a pan-tilt head.
    Planar,
}

impl std::str::FromStr for RobotPoseForm {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "6dof" => Ok(Self::SixDof),
            "planar" => Ok(Self::Planar),
            other => Err(Error::InvalidConfig(format!("unknown robot pose form `{other}`: expected 6dof or planar"))),
        }
    }
}

impl RobotPoseForm {
    fn fields(self) -> usize {
        match self {
            Self::SixDof => 6,
            Self::Planar => 5,
        }
    }
}

/// One reported pose: its time (when the file has a timestamp column) and the camera-to-world
/// pose it gives (pinhole camera axes, world in metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RobotPose {
    /// Nanoseconds, when the file has a timestamp column.
    pub timestamp_ns: Option<i64>,
    /// Camera (x right, y down, z forward) to the thesis's world (X right, Y forward, Z up), metres.
    pub world_from_camera: Se3,
}

/// The camera pose of 000's sensor pose `(x, y, z)` cm, `(α, β, γ)` rad (see the module doc).
pub fn sensor_pose_6dof(x_cm: f64, y_cm: f64, z_cm: f64, alpha: f64, beta: f64, gamma: f64) -> Se3 {
    let rotation = DMat3::from_rotation_z(alpha) * DMat3::from_rotation_y(beta) * DMat3::from_rotation_x(gamma);
    // Eq. 5.3: camera (x, y, z) -> sensor (x, z, -y); its columns are the images of the camera axes.
    let sensor_from_camera = DMat3::from_cols(DVec3::X, -DVec3::Z, DVec3::Y);
    Se3::new(DQuat::from_mat3(&(rotation * sensor_from_camera)).normalize(), DVec3::new(x_cm, y_cm, z_cm) / 100.0)
}

/// The camera pose of the planar form: base `(x, y)` cm and heading `theta`, head `pan` and
/// `tilt` (rad).
pub fn sensor_pose_planar(x_cm: f64, y_cm: f64, theta: f64, pan: f64, tilt: f64) -> Se3 {
    sensor_pose_6dof(x_cm, y_cm, 0.0, theta + pan, 0.0, tilt)
}

/// Reads a robot pose file of `form` (see [`parse_robot_poses`]).
pub fn read_robot_poses(path: &Path, form: RobotPoseForm) -> Result<Vec<RobotPose>> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io { path: path.to_owned(), source })?;
    parse_robot_poses(&text, path, form)
}

/// Parses a robot pose file: every line the form's fields, or a timestamp and them (all lines
/// alike). A line with another field count, a mix of both layouts, a non-finite number or a bad
/// timestamp is an [`Error::Parse`] naming the line; `path` only names the file in errors.
pub fn parse_robot_poses(text: &str, path: &Path, form: RobotPoseForm) -> Result<Vec<RobotPose>> {
    let n = form.fields();
    let mut poses = Vec::new();
    let mut timed: Option<bool> = None;
    for (line_ix, line) in text.lines().enumerate() {
        let Some(fields) = data_fields(line) else { continue };
        let error = |message: String| Error::Parse { path: path.to_owned(), line: line_ix + 1, message };
        let has_time = match fields.len() {
            k if k == n => false,
            k if k == n + 1 => true,
            k => return Err(error(format!("expected {n} fields ({}) or a timestamp and them, found {k}", if form == RobotPoseForm::SixDof { "x y z α β γ" } else { "x y θ pan tilt" }))),
        };
        if *timed.get_or_insert(has_time) != has_time {
            return Err(error("every line needs the same layout: with a timestamp or without".into()));
        }
        let timestamp_ns = if has_time { Some(parse_timestamp_ns(fields[0]).ok_or_else(|| error(format!("invalid timestamp {:?}: expected decimal seconds", fields[0])))?) } else { None };
        let values: Vec<f64> = fields[usize::from(has_time)..].iter().map(|f| f.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| error(format!("invalid number {f:?}")))).collect::<Result<_>>()?;
        let world_from_camera = match form {
            RobotPoseForm::SixDof => sensor_pose_6dof(values[0], values[1], values[2], values[3], values[4], values[5]),
            RobotPoseForm::Planar => sensor_pose_planar(values[0], values[1], values[2], values[3], values[4]),
        };
        poses.push(RobotPose { timestamp_ns, world_from_camera });
    }
    if poses.is_empty() {
        return Err(Error::Parse { path: path.to_owned(), line: 0, message: "no pose in the file".into() });
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DVec3, b: DVec3) -> bool {
        (a - b).length() < 1e-12
    }

    #[test]
    fn the_thesis_conventions_hold_on_hand_computed_poses() {
        let forward = DVec3::Z; // the camera's optical axis (pinhole frame)
        let down = DVec3::Y;
        // The first capture: looking along +Y, the camera's down is -Z, at the origin.
        let p = sensor_pose_6dof(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        assert!(close(p.rotation * forward, DVec3::Y) && close(p.rotation * down, -DVec3::Z) && close(p.rotation * DVec3::X, DVec3::X));
        // Table 6.1, measurement 2: α = 1 rad, head turned left: forward (−sin 1, cos 1, 0).
        let p = sensor_pose_6dof(0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
        assert!(close(p.rotation * forward, DVec3::new(-1f64.sin(), 1f64.cos(), 0.0)));
        // Measurement 4: γ = −0.5, looking down: forward (0, cos 0.5, −sin 0.5).
        let p = sensor_pose_6dof(0.0, 0.0, 0.0, 0.0, 0.0, -0.5);
        assert!(close(p.rotation * forward, DVec3::new(0.0, 0.5f64.cos(), -0.5f64.sin())));
        // Measurement 7: 1 m forward (y = 100 cm): the camera centre at (0, 1, 0) m.
        let p = sensor_pose_6dof(0.0, 100.0, 0.0, 0.0, 0.0, 0.0);
        assert!(close(p.translation_m, DVec3::new(0.0, 1.0, 0.0)));
        // β = +0.3, right ear to the right shoulder: the top of the head (the camera's up, −y)
        // goes right (+X).
        let p = sensor_pose_6dof(0.0, 0.0, 0.0, 0.0, 0.3, 0.0);
        assert!(close(p.rotation * -down, DVec3::new(0.3f64.sin(), 0.0, 0.3f64.cos())));
        // The erratum: element (2,3) of Rz Ry Rx is −cos α sin γ + sin α sin β cos γ. In the
        // sensor frame (before Eq. 5.3's axis change) the matrix's (row 2, column 3) is the Y
        // component of the image of the sensor's Z axis, which is the camera's −y.
        let (a, b, g) = (0.7f64, -0.4f64, 0.9f64);
        let p = sensor_pose_6dof(0.0, 0.0, 0.0, a, b, g);
        let r23 = (p.rotation * -DVec3::Y).y;
        assert!((r23 - (-a.cos() * g.sin() + a.sin() * b.sin() * g.cos())).abs() < 1e-12, "the corrected (2,3) element");
        assert!((r23 - (-a.cos() * g.sin() + a.sin() * b.sin() * g.sin())).abs() > 1e-3, "negative control: the printed typo differs");
        // Planar: heading 0.5 and pan 0.25 turn like α = 0.75; tilt like γ; z stays 0.
        let q = sensor_pose_planar(30.0, -20.0, 0.5, 0.25, -0.1);
        let r = sensor_pose_6dof(30.0, -20.0, 0.0, 0.75, 0.0, -0.1);
        assert!(close(q.translation_m, r.translation_m) && q.rotation.angle_between(r.rotation) < 1e-12);
    }

    #[test]
    fn pose_files_parse_in_either_layout_and_bad_lines_are_named() {
        let path = Path::new("poses.txt");
        let plain = parse_robot_poses("# x y z a b g\n0 0 0 0 0 0\n0 100 0 1 0 -0.5\n", path, RobotPoseForm::SixDof).expect("plain");
        assert_eq!(plain.len(), 2);
        assert!(plain.iter().all(|p| p.timestamp_ns.is_none()));
        assert!(close(plain[1].world_from_camera.translation_m, DVec3::new(0.0, 1.0, 0.0)));
        let timed = parse_robot_poses("1.5 10 20 0.1 0.2 0.05\n1.6 11 20 0.1 0.2 0.05\n", path, RobotPoseForm::Planar).expect("timed");
        assert_eq!(timed[1].timestamp_ns, Some(1_600_000_000));
        let err = |text: &str, form| parse_robot_poses(text, path, form).expect_err("an error").to_string();
        assert!(err("0 0 0 0 0\n", RobotPoseForm::SixDof).contains("poses.txt:1") && err("0 0 0 0 0\n", RobotPoseForm::SixDof).contains("found 5"));
        assert!(err("0 0 0 0 0 0\n1.0 0 0 0 0 0 0\n", RobotPoseForm::SixDof).contains("same layout"));
        assert!(err("0 0 0 nan 0 0\n", RobotPoseForm::SixDof).contains("invalid number"));
        assert!(err("# nothing\n", RobotPoseForm::Planar).contains("no pose"));
    }
}
