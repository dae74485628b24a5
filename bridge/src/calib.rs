// SPDX-License-Identifier: MIT
//! Calibration flags shared by every command that reads a log.

use anyhow::Context as _;
use webfusion_core::camera::TUM_DEPTH_UNITS_PER_METRE;
use webfusion_core::{PinholeIntrinsics, RgbdCalibration};

/// `--intrinsics`, `--depth-scale` and `--image-size` overrides. Without `--intrinsics` the
/// source's own calibration is used (a recording's, or the published TUM values recognised
/// from a directory name); if it has none the command stops and asks for `--intrinsics`.
#[derive(clap::Args, Clone, Debug, Default)]
pub(crate) struct CalibrationArgs {
    /// Override the intrinsics: `fx,fy,cx,cy` in pixels, optionally followed by `width,height`
    /// (as `record` takes them; or give the size with --image-size).
    #[arg(long, value_name = "FX,FY,CX,CY[,W,H]")]
    pub(crate) intrinsics: Option<String>,
    /// Raw depth units per metre (5000 for TUM, 1000 for OpenNI millimetres).
    #[arg(long, value_name = "UNITS_PER_METRE")]
    pub(crate) depth_scale: Option<f32>,
    /// Image size for `--intrinsics`, `WxH` (default 640x480).
    #[arg(long, value_name = "WxH")]
    pub(crate) image_size: Option<String>,
}

/// `--image-size WxH`: whole pixels, 16 to 4096 each way.
pub(crate) fn parse_image_size(s: &str) -> anyhow::Result<(u32, u32)> {
    let (w, h) = s.split_once('x').with_context(|| format!("--image-size {s:?}: expected WxH"))?;
    let (w, h): (u32, u32) = (w.parse().with_context(|| format!("--image-size width {w:?}"))?, h.parse().with_context(|| format!("--image-size height {h:?}"))?);
    anyhow::ensure!((16..=4096).contains(&w) && (16..=4096).contains(&h), "--image-size {s}: 16..=4096 pixels each way");
    Ok((w, h))
}

impl CalibrationArgs {
    /// The override, or `None` to use the source's calibration.
    pub(crate) fn resolve(&self) -> anyhow::Result<Option<RgbdCalibration>> {
        let Some(spec) = &self.intrinsics else {
            anyhow::ensure!(self.depth_scale.is_none() && self.image_size.is_none(), "--depth-scale and --image-size need --intrinsics");
            return Ok(None);
        };
        let v: Vec<f32> = spec
            .split(',')
            .map(|s| s.trim().parse::<f32>().with_context(|| format!("--intrinsics {spec:?}: {s:?} is not a number")))
            .collect::<anyhow::Result<_>>()?;
        anyhow::ensure!((v.len() == 4 || v.len() == 6) && v.iter().all(|x| x.is_finite()), "--intrinsics {spec:?}: expected four numbers fx,fy,cx,cy (or six, with width,height)");
        anyhow::ensure!(v[0] > 0.0 && v[1] > 0.0, "--intrinsics {spec:?}: focal lengths must be positive");
        let (width_px, height_px) = match (&self.image_size, v.get(4..6)) {
            (Some(_), Some(_)) => anyhow::bail!("--intrinsics {spec:?} gives the image size, so --image-size is one too many"),
            (None, Some(&[w, h])) => {
                anyhow::ensure!(w >= 1.0 && h >= 1.0 && w.fract() == 0.0 && h.fract() == 0.0, "--intrinsics {spec:?}: width and height must be whole pixels");
                (w as u32, h as u32)
            }
            (None, _) => (640, 480),
            (Some(s), _) => parse_image_size(s)?,
        };
        let depth_units_per_metre = self.depth_scale.unwrap_or(TUM_DEPTH_UNITS_PER_METRE);
        anyhow::ensure!(depth_units_per_metre > 0.0 && depth_units_per_metre.is_finite(), "--depth-scale must be a positive number");
        Ok(Some(RgbdCalibration {
            intrinsics: PinholeIntrinsics { fx_px: v[0], fy_px: v[1], cx_px: v[2], cy_px: v[3], width_px, height_px },
            depth_units_per_metre,
        }))
    }
}
