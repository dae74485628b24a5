// SPDX-License-Identifier: MIT
//! The one error type of `webfusion-core`.

use std::path::PathBuf;

/// Everything that can go wrong in `webfusion-core`.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// No GPU adapter matched the request.
    #[error("no GPU adapter found for backends {backends}{}; natively install a Vulkan driver (e.g. Mesa lavapipe: apt-get install mesa-vulkan-drivers), in a browser enable WebGPU", wanted.as_ref().map(|w| format!(" with a name containing {w:?}")).unwrap_or_default())]
    NoAdapter {
        /// The backends that were searched.
        backends: String,
        /// The adapter-name filter, if any.
        wanted: Option<String>,
    },
    /// A view of a saved map reaches more of its blocks than the GPU pool holds, so it cannot
    /// be rendered whole.
    #[error("the view reaches {view_blocks} blocks of the map, more than the GPU pool's {pool_blocks}: render it with a shorter depth range (--max-depth) or narrower intrinsics, or on a device with larger storage bindings")]
    ViewExceedsPool {
        /// Blocks the view may read.
        view_blocks: usize,
        /// Blocks the pool holds.
        pool_blocks: usize,
    },
    /// The adapter offers less of a limit than the kernels need.
    #[error("GPU adapter {adapter:?} offers {name} = {available}, but webfusion needs at least {required}")]
    MissingLimit {
        /// Adapter name.
        adapter: String,
        /// `wgpu::Limits` field name.
        name: &'static str,
        /// What the kernels need.
        required: u64,
        /// What the adapter offers.
        available: u64,
    },
    /// The device could not be created.
    #[error("GPU device request failed: {0}")]
    RequestDevice(#[from] wgpu::RequestDeviceError),
    /// Reading a GPU buffer back failed.
    #[error("mapping GPU buffer {label:?} for reading failed: {message}")]
    BufferMap {
        /// Buffer label.
        label: String,
        /// What wgpu said.
        message: String,
    },
    /// Waiting for the GPU failed or timed out.
    #[error("waiting for the GPU failed: {0}")]
    Poll(String),
    /// The GPU device was lost (driver reset, GPU process crash, `destroy`); everything on it
    /// must be rebuilt.
    #[error("the GPU device was lost ({reason}); the pipeline must be rebuilt on a new device")]
    DeviceLost {
        /// What the driver or browser said.
        reason: String,
    },
    /// An image does not have the size the pipeline was built for.
    #[error("{what} is {got_width}x{got_height} px but the pipeline expects {want_width}x{want_height} px")]
    FrameSize {
        /// Which image.
        what: &'static str,
        /// Width received.
        got_width: u32,
        /// Height received.
        got_height: u32,
        /// Width expected.
        want_width: u32,
        /// Height expected.
        want_height: u32,
    },
    /// A configuration value is out of its valid range.
    #[error("invalid configuration: {0}")]
    InvalidConfig(String),
    /// A file could not be read or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// An image file could not be decoded or has the wrong pixel format.
    #[error("{}: cannot decode image: {message}", path.display())]
    ImageDecode {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A text file of a dataset (TUM lists, ground truth) is malformed.
    #[error("{}:{line}: {message}", path.display())]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// A dataset directory has no usable frames.
    #[error("{}: {message}", path.display())]
    Dataset {
        /// The dataset directory or file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The calibration of a source is unknown and was not given.
    #[error("no calibration for {source_name}: pass --intrinsics fx,fy,cx,cy (and --depth-scale units-per-metre if not 5000)")]
    UnknownCalibration {
        /// The source that lacks calibration.
        source_name: String,
    },
    /// One frame record of a recording is damaged (a CRC mismatch, impossible lengths, a
    /// payload that does not decode); the other frames may be fine (`--skip-corrupt`).
    #[error("recording {}: frame {index}: {message}", path.display())]
    CorruptFrame {
        /// The recording file (or `<memory>`).
        path: PathBuf,
        /// The frame's position in the recording.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// A recording file is corrupt, truncated or of an unsupported version.
    #[error("recording {}: {message}", path.display())]
    Recording {
        /// The recording file (or `<memory>`).
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A map file is corrupt, truncated, foreign or of an unsupported version.
    #[error("map file {}: {message}", path.display())]
    MapFile {
        /// The map file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A compressed depth or colour payload is malformed.
    #[error("cannot decode {codec} payload: {message}")]
    Codec {
        /// Codec name (`rvl`, `jpeg`, `png`).
        codec: &'static str,
        /// What is wrong.
        message: String,
    },
    /// A bridge protocol message is malformed.
    #[error("malformed webfusion protocol message: {message}")]
    Protocol {
        /// What is wrong.
        message: String,
    },
    /// A bridge protocol message has a version this build does not speak.
    #[error("webfusion protocol version {got} is not supported (this build speaks version {supported}); update the bridge or the app so both match")]
    ProtocolVersion {
        /// Version in the message.
        got: u8,
        /// Version this build speaks.
        supported: u8,
    },
    /// Trajectory evaluation found too few ground-truth/estimate pose pairs.
    #[error("{what} needs at least {required} associated pose pairs (timestamps closer than the maximum difference), found {pairs}")]
    TooFewAssociations {
        /// The evaluation (`ATE`, `RPE`, `Umeyama alignment`).
        what: &'static str,
        /// Pairs found.
        pairs: usize,
        /// Pairs needed.
        required: usize,
    },
    /// Trajectories cannot be aligned (positions collinear, coincident or not finite).
    #[error("cannot align the trajectories: {message}")]
    DegenerateAlignment {
        /// What is wrong.
        message: String,
    },
    /// A kernel produced more output than its buffer holds (counted past the capacity).
    #[error("{stage} needs room for {needed} outputs but its buffer holds {capacity}")]
    OutputOverflow {
        /// The kernel whose output overflowed, e.g. `mc_generate`.
        stage: &'static str,
        /// Outputs it produced (the size needed).
        needed: u64,
        /// Outputs the buffer holds.
        capacity: u64,
    },
}

/// `Result` with [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;
