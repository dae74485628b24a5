// SPDX-License-Identifier: MIT
//! The page's status: one typed struct, serialised once per update into `window.webfusion`,
//! and the bounded statistics it is built from (O(1) work per frame).

use std::collections::VecDeque;

use serde::Serialize;

/// Frames the stage medians and the fps figure look back over.
pub(crate) const STATS_WINDOW: usize = 32;

/// The last [`STATS_WINDOW`] samples of a quantity and their median.
#[derive(Clone, Debug, Default)]
pub(crate) struct Window {
    samples: VecDeque<f64>,
}

impl Window {
    pub(crate) fn push(&mut self, sample: f64) {
        if self.samples.len() == STATS_WINDOW {
            self.samples.pop_front();
        }
        self.samples.push_back(sample);
    }

    /// Median of the window (the upper one of an even count), `None` when empty.
    pub(crate) fn median(&self) -> Option<f64> {
        let mut sorted: Vec<f64> = self.samples.iter().copied().collect();
        sorted.sort_by(f64::total_cmp);
        sorted.get(sorted.len() / 2).copied()
    }

    pub(crate) fn clear(&mut self) {
        self.samples.clear();
    }
}

/// Median stage times over the last frames, milliseconds (GPU timestamps where the browser
/// gives them, else 0 for the GPU stages).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub(crate) struct StageMedians {
    pub(crate) decode: f64,
    pub(crate) preprocess: f64,
    /// The feature pass recorded into the frame (detection, description, matching,
    /// estimation; 0 with features off).
    pub(crate) features: f64,
    pub(crate) track: f64,
    pub(crate) integrate: f64,
    pub(crate) raycast: f64,
    /// Encoding the views' colour maps and copies (the GPU does the rest).
    pub(crate) views: f64,
}

/// A window of each stage's times, one sample per frame.
#[derive(Clone, Debug, Default)]
pub(crate) struct StageWindows {
    pub(crate) decode: Window,
    pub(crate) preprocess: Window,
    pub(crate) features: Window,
    pub(crate) track: Window,
    pub(crate) integrate: Window,
    pub(crate) raycast: Window,
    pub(crate) views: Window,
}

impl StageWindows {
    fn all_mut(&mut self) -> [&mut Window; 7] {
        [&mut self.decode, &mut self.preprocess, &mut self.features, &mut self.track, &mut self.integrate, &mut self.raycast, &mut self.views]
    }

    /// Adds one frame's stage times (milliseconds, in [`StageMedians`]' fields).
    pub(crate) fn push(&mut self, frame: &StageMedians) {
        let StageMedians { decode, preprocess, features, track, integrate, raycast, views } = *frame;
        for (window, sample) in self.all_mut().into_iter().zip([decode, preprocess, features, track, integrate, raycast, views]) {
            window.push(sample);
        }
    }

    /// Each stage's median (0 before the first frame).
    pub(crate) fn medians(&self) -> StageMedians {
        let m = |w: &Window| w.median().unwrap_or(0.0);
        StageMedians {
            decode: m(&self.decode),
            preprocess: m(&self.preprocess),
            features: m(&self.features),
            track: m(&self.track),
            integrate: m(&self.integrate),
            raycast: m(&self.raycast),
            views: m(&self.views),
        }
    }

    pub(crate) fn clear(&mut self) {
        self.all_mut().into_iter().for_each(Window::clear);
    }
}

/// The volume the pipeline fuses into.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub(crate) struct VolumeStatus {
    /// dense or sparse.
    pub(crate) kind: &'static str,
    /// The dense box's voxels per axis, or the sparse map's addressable box.
    pub(crate) dims_voxels: [u32; 3],
    /// Blocks of 8³ voxels in a sparse map's pool (0 for a dense box).
    pub(crate) pool_blocks: u32,
    /// Of those, blocks in use (as of the last report).
    pub(crate) blocks_used: u32,
    /// Blocks swapped out to host (wasm) memory.
    pub(crate) blocks_on_host: u32,
    /// Bytes they take there.
    pub(crate) host_bytes: u64,
    /// The swapping regions' margins in force, percent of the full ones (below 100 while the
    /// map's surroundings do not fit the pool; 0 without swapping).
    pub(crate) swap_margin_percent: u32,
    /// A sparse map ran out of pool blocks or hash slots: surfaces seen since were not fused.
    pub(crate) full: bool,
    pub(crate) voxel_size_m: f32,
    pub(crate) truncation_m: f32,
    pub(crate) memory_bytes: u64,
}

/// How often the page touched the GPU per fused frame (steady state).
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub(crate) struct HostPerFrame {
    pub(crate) submits: f64,
    pub(crate) host_waits: f64,
    pub(crate) readbacks: f64,
}

/// Everything the page reports, as `window.webfusion.status`: the shell's fields and the
/// running mode's section, flattened into one object.
#[derive(Clone, Debug, Serialize)]
pub(crate) struct Status {
    /// running, paused, ended, connecting, reconnecting, disconnected or error.
    pub(crate) state: &'static str,
    /// The link: disconnected, connecting, connected or retrying.
    pub(crate) link: &'static str,
    /// The last error, or why a setting was ignored ("" if none).
    pub(crate) message: String,
    pub(crate) source: Option<String>,
    pub(crate) frames_total: Option<u64>,
    pub(crate) adapter: String,
    /// Frames dropped (real-time delivery) here and at the bridge.
    pub(crate) frames_dropped: u64,
    /// Damaged frames of the source the bridge skipped (`serve --skip-corrupt`).
    pub(crate) frames_skipped: u64,
    pub(crate) reconnects: u32,
    /// Pipelines rebuilt after the GPU device was lost.
    pub(crate) device_rebuilds: u32,
    /// Connecting to the first fused frame, milliseconds.
    pub(crate) time_to_first_frame_ms: Option<f64>,
    /// Pipelines compiled by the first fused frame, of all the kernels.
    pub(crate) first_frame_kernels: Option<[usize; 2]>,
    /// When the milestones up to the first fused frame happened, milliseconds after the page
    /// started.
    pub(crate) startup_ms: std::collections::BTreeMap<String, f64>,
    #[serde(flatten)]
    pub(crate) fusion: crate::fusion_mode::FusionStatus,
    /// The virtual sensor (seed 000) and the saved map open in the page.
    pub(crate) sensor: crate::sim::SensorStatus,
}

#[cfg(test)]
mod tests {
    use wasm_bindgen_test::wasm_bindgen_test;

    use super::*;

    #[wasm_bindgen_test]
    fn the_window_keeps_the_last_samples_and_their_median() {
        let mut w = Window::default();
        assert_eq!(w.median(), None, "empty");
        for i in 0..100 {
            w.push(f64::from(i));
        }
        // The last 32 samples are 68..=99: the upper median is 84.
        assert_eq!(w.median(), Some(84.0), "median of the window");
        w.clear();
        w.push(3.0);
        assert_eq!(w.median(), Some(3.0), "after clear");
    }
}
