// SPDX-License-Identifier: MIT
//! OpenNI2 `.oni` recordings as a [`FrameSource`] and live cameras as a [`LiveSource`] (cargo
//! feature `openni2`, which links Debian's `libopenni2-dev`), and a generator of test `.oni` files from OpenNI2's built-in
//! "Dummy" device so CI exercises this path without hardware.
//!
//! Two defects of Debian's OpenNI 2.2.0.33 file player shape this code:
//! - seeking crashes, so random access reopens the file and reads forward;
//! - in manual playback a read past the end blocks forever, so every wait has a timeout and
//!   reads stop at the reported frame count.
//!
//! Recordings without a colour stream (depth-only sensors, the Dummy device) yield mid-grey
//! colour images.
#![allow(unsafe_code, reason = "FFI to the OpenNI2 C API; every call and pointer is checked in this module")]

use std::ffi::{CStr, CString, c_int, c_void};
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use openni2_sys as oni;
use webfusion_core::source::{FrameSource, LiveSource, TimedPose};
use webfusion_core::{ColorImage, DepthImage, Error, PinholeIntrinsics, Result, RgbdCalibration, RgbdFrame};

/// `ONI_API_VERSION` of OpenNI 2.2 (`major * 1000 + minor`).
const ONI_API_VERSION: c_int = 2002;
/// Longest wait for one frame from the file player.
const FRAME_TIMEOUT_MS: c_int = 5000;
/// Grey level of the colour image of a depth-only recording.
const GREY: u8 = 128;

fn oni_error(path: &Path, what: &str) -> Error {
    // SAFETY: oniGetExtendedError returns a NUL-terminated string owned by OpenNI2 (or null).
    let detail = unsafe {
        let message = oni::oniGetExtendedError();
        if message.is_null() { String::new() } else { CStr::from_ptr(message).to_string_lossy().into_owned() }
    };
    let detail = if detail.is_empty() { String::new() } else { format!(": {detail}") };
    Error::Dataset { path: path.to_owned(), message: format!("OpenNI2: {what}{detail}") }
}

/// Initialises OpenNI2 once per process.
fn initialise(path: &Path) -> Result<()> {
    static INIT: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    // SAFETY: plain C call without pointers.
    let result = INIT.get_or_init(|| match unsafe { oni::oniInitialize(ONI_API_VERSION) } {
        oni::ONI_STATUS_OK => Ok(()),
        status => Err(format!("oniInitialize failed with status {status} (is libopenni2-0 installed?)")),
    });
    result.clone().map_err(|message| Error::Dataset { path: path.to_owned(), message })
}

/// Why a recording's player stops delivering frames.
const RECORDING_TIMEOUT_CAUSE: &str = "truncated or unplayable recording";
/// Why a live camera stops delivering frames.
const LIVE_TIMEOUT_CAUSE: &str = "device unplugged or stalled?";

fn no_frame_within(path: &Path, timeout_ms: c_int, cause: &str) -> Error {
    Error::Dataset { path: path.to_owned(), message: format!("OpenNI2: no frame within {timeout_ms} ms ({cause})") }
}

/// One frame as OpenNI2 delivered it, copied out of the driver's buffer.
struct RawFrame {
    bytes: Vec<u8>,
    width: i32,
    height: i32,
    pixel_format: oni::OniPixelFormat,
    timestamp_us: u64,
    /// The device's own number for the frame (consecutive unless frames were dropped).
    device_index: i32,
}

/// Checks a depth frame (16-bit) and, when the source has colour, its RGB888 partner against
/// the calibration's size, and builds frame `index`; without colour the image is mid-grey.
fn rgbd_frame(path: &Path, index: u64, calibration: &RgbdCalibration, depth: RawFrame, color: Option<RawFrame>) -> Result<RgbdFrame> {
    let (w, h) = (calibration.intrinsics.width_px, calibration.intrinsics.height_px);
    if (depth.width, depth.height) != (w as i32, h as i32) || depth.bytes.len() != 2 * (w * h) as usize {
        return Err(Error::Dataset { path: path.to_owned(), message: format!("OpenNI2: depth frame {index} is {}x{} ({} bytes), expected {w}x{h}", depth.width, depth.height, depth.bytes.len()) });
    }
    let units = depth.bytes.chunks_exact(2).map(|b| u16::from_le_bytes([b[0], b[1]])).collect();
    let (rgb8, color_us) = match color {
        None => (vec![GREY; 3 * (w * h) as usize], depth.timestamp_us),
        Some(c) => {
            if c.pixel_format != oni::ONI_PIXEL_FORMAT_RGB888 || (c.width, c.height) != (w as i32, h as i32) || c.bytes.len() != 3 * (w * h) as usize {
                return Err(Error::Dataset {
                    path: path.to_owned(),
                    message: format!("OpenNI2: colour frame {index} is {}x{} in pixel format {}; need RGB888 at the depth size, {w}x{h} (registration on)", c.width, c.height, c.pixel_format),
                });
            }
            (c.bytes, c.timestamp_us)
        }
    };
    Ok(RgbdFrame {
        index,
        depth_timestamp_ns: (depth.timestamp_us as i64).saturating_mul(1000),
        color_timestamp_ns: (color_us as i64).saturating_mul(1000),
        depth: DepthImage::new(w, h, units)?,
        color: ColorImage::new(w, h, rgb8)?,
    })
}

/// The calibration of a `width_px`x`height_px` depth stream stored in `depth_units_per_metre`:
/// `calibration_override` when given (its size and depth scale must match), else pinhole
/// intrinsics from `fov_stream`'s field of view. `name` is what errors call the source.
fn resolve_calibration(name: &str, calibration_override: Option<RgbdCalibration>, (width_px, height_px): (u32, u32), depth_units_per_metre: f32, fov_stream: oni::OniStreamHandle) -> Result<RgbdCalibration> {
    if let Some(calibration) = calibration_override {
        let k = &calibration.intrinsics;
        if (k.width_px, k.height_px) != (width_px, height_px) {
            return Err(Error::InvalidConfig(format!("{name}: depth is {width_px}x{height_px} but the calibration is for {}x{} (--image-size)", k.width_px, k.height_px)));
        }
        if calibration.depth_units_per_metre != depth_units_per_metre {
            return Err(Error::InvalidConfig(format!(
                "{name}: the depth is stored as {depth_units_per_metre} units per metre but the calibration says {} (pass --depth-scale {depth_units_per_metre})",
                calibration.depth_units_per_metre
            )));
        }
        return Ok(calibration);
    }
    let (Some(hfov), Some(vfov)) = (Player::float_property(fov_stream, oni::ONI_STREAM_PROPERTY_HORIZONTAL_FOV), Player::float_property(fov_stream, oni::ONI_STREAM_PROPERTY_VERTICAL_FOV)) else {
        return Err(Error::UnknownCalibration { source_name: name.to_owned() });
    };
    let fx_px = width_px as f32 / (2.0 * (hfov / 2.0).tan());
    let fy_px = height_px as f32 / (2.0 * (vfov / 2.0).tan());
    let intrinsics = PinholeIntrinsics { fx_px, fy_px, cx_px: (width_px as f32 - 1.0) / 2.0, cy_px: (height_px as f32 - 1.0) / 2.0, width_px, height_px };
    Ok(RgbdCalibration { intrinsics, depth_units_per_metre })
}

/// An opened file player with its depth (and, when recorded, colour) stream started.
struct Player {
    device: oni::OniDeviceHandle,
    depth: oni::OniStreamHandle,
    color: Option<oni::OniStreamHandle>,
}

// SAFETY: OpenNI2 handles may be used from any thread, one at a time; `Player` is only used
// through `&mut`.
unsafe impl Send for Player {}

impl Player {
    fn open(path: &Path) -> Result<Self> {
        initialise(path)?;
        let uri = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| Error::Dataset { path: path.to_owned(), message: "path contains a NUL byte".to_owned() })?;
        let mut device: oni::OniDeviceHandle = std::ptr::null_mut();
        // SAFETY: `uri` is NUL-terminated and `device` a valid out-pointer.
        if unsafe { oni::oniDeviceOpen(uri.as_ptr(), &mut device) } != oni::ONI_STATUS_OK || device.is_null() {
            return Err(oni_error(path, "cannot open the recording"));
        }
        let mut player = Player { device, depth: std::ptr::null_mut(), color: None };
        // Manual playback (one frame per read), no repeat.
        let speed: f32 = -1.0;
        let repeat: c_int = 0;
        // SAFETY: the device is open; the values outlive the calls and have the sizes given.
        unsafe {
            oni::oniDeviceSetProperty(device, oni::ONI_DEVICE_PROPERTY_PLAYBACK_SPEED, (&raw const speed).cast::<c_void>(), 4);
            oni::oniDeviceSetProperty(device, oni::ONI_DEVICE_PROPERTY_PLAYBACK_REPEAT_ENABLED, (&raw const repeat).cast::<c_void>(), 4);
        }
        player.depth = player.create_stream(oni::ONI_SENSOR_DEPTH).ok_or_else(|| oni_error(path, "the recording has no depth stream"))?;
        player.color = player.create_stream(oni::ONI_SENSOR_COLOR);
        for stream in std::iter::once(player.depth).chain(player.color) {
            // SAFETY: the stream was created on this device.
            if unsafe { oni::oniStreamStart(stream) } != oni::ONI_STATUS_OK {
                return Err(oni_error(path, "cannot start a stream"));
            }
        }
        Ok(player)
    }

    fn create_stream(&self, sensor: oni::OniSensorType) -> Option<oni::OniStreamHandle> {
        let mut stream: oni::OniStreamHandle = std::ptr::null_mut();
        // SAFETY: the device is open and `stream` a valid out-pointer.
        let status = unsafe { oni::oniDeviceCreateStream(self.device, sensor, &mut stream) };
        (status == oni::ONI_STATUS_OK && !stream.is_null()).then_some(stream)
    }

    fn int_property(stream: oni::OniStreamHandle, property: oni::OniStreamProperty) -> Option<c_int> {
        let mut value: c_int = 0;
        let mut size: c_int = 4;
        // SAFETY: `value` holds `size` bytes.
        let status = unsafe { oni::oniStreamGetProperty(stream, property, (&raw mut value).cast::<c_void>(), &mut size) };
        (status == oni::ONI_STATUS_OK && size == 4).then_some(value)
    }

    fn float_property(stream: oni::OniStreamHandle, property: oni::OniStreamProperty) -> Option<f32> {
        let mut value: f32 = 0.0;
        let mut size: c_int = 4;
        // SAFETY: `value` holds `size` bytes.
        let status = unsafe { oni::oniStreamGetProperty(stream, property, (&raw mut value).cast::<c_void>(), &mut size) };
        (status == oni::ONI_STATUS_OK && size == 4 && value.is_finite() && value > 0.0).then_some(value)
    }

    fn video_mode(stream: oni::OniStreamHandle) -> Option<oni::OniVideoMode> {
        let mut mode = oni::OniVideoMode { pixelFormat: 0, resolutionX: 0, resolutionY: 0, fps: 0 };
        let mut size = std::mem::size_of::<oni::OniVideoMode>() as c_int;
        // SAFETY: `mode` holds `size` bytes.
        let status = unsafe { oni::oniStreamGetProperty(stream, oni::ONI_STREAM_PROPERTY_VIDEO_MODE, (&raw mut mode).cast::<c_void>(), &mut size) };
        (status == oni::ONI_STATUS_OK).then_some(mode)
    }

    /// Reads the next frame of `stream`: its bytes, size, pixel format and timestamp (µs).
    fn read(path: &Path, stream: oni::OniStreamHandle) -> Result<RawFrame> {
        Self::read_within(path, stream, FRAME_TIMEOUT_MS, RECORDING_TIMEOUT_CAUSE)
    }

    /// [`Self::read`], waiting at most `timeout_ms`; a timeout's error names `cause`.
    fn read_within(path: &Path, stream: oni::OniStreamHandle, timeout_ms: c_int, cause: &str) -> Result<RawFrame> {
        let mut streams = [stream];
        let mut ready: c_int = -1;
        // SAFETY: one valid stream handle and a valid out-pointer.
        let status = unsafe { oni::oniWaitForAnyStream(streams.as_mut_ptr(), 1, &mut ready, timeout_ms) };
        if status == oni::ONI_STATUS_TIME_OUT {
            return Err(no_frame_within(path, timeout_ms, cause));
        }
        if status != oni::ONI_STATUS_OK {
            return Err(oni_error(path, "waiting for a frame failed"));
        }
        let mut frame: *mut oni::OniFrame = std::ptr::null_mut();
        // SAFETY: the stream has a frame ready; `frame` is a valid out-pointer.
        if unsafe { oni::oniStreamReadFrame(stream, &mut frame) } != oni::ONI_STATUS_OK || frame.is_null() {
            return Err(oni_error(path, "reading a frame failed"));
        }
        // SAFETY: `frame` is a valid frame until released below; `data` holds `dataSize` bytes.
        let copied = unsafe {
            let f = &*frame;
            let bytes = if f.data.is_null() || f.dataSize <= 0 { Vec::new() } else { std::slice::from_raw_parts(f.data.cast::<u8>(), f.dataSize as usize).to_vec() };
            let result = RawFrame { bytes, width: f.width, height: f.height, pixel_format: f.videoMode.pixelFormat, timestamp_us: f.timestamp, device_index: f.frameIndex };
            oni::oniFrameRelease(frame);
            result
        };
        Ok(copied)
    }
}

impl Drop for Player {
    fn drop(&mut self) {
        // SAFETY: the handles were created by this player and are destroyed once.
        unsafe {
            for stream in std::iter::once(self.depth).chain(self.color).filter(|s| !s.is_null()) {
                oni::oniStreamStop(stream);
                oni::oniStreamDestroy(stream);
            }
            oni::oniDeviceClose(self.device);
        }
    }
}

/// An OpenNI2 `.oni` recording.
pub(crate) struct OniSource {
    path: PathBuf,
    calibration: RgbdCalibration,
    frame_count: usize,
    /// The open player; `None` only while it is being reopened (OpenNI2 plays two players of
    /// one file in lockstep, so the old one must close first).
    player: Option<Player>,
    /// Index of the frame the player reads next.
    next_index: usize,
}

impl OniSource {
    /// Opens `path`. The calibration comes from the recorded field of view; recordings
    /// without one (the Dummy device) need `calibration_override`, whose depth scale must
    /// match the recorded pixel format.
    pub(crate) fn open(path: &Path, calibration_override: Option<RgbdCalibration>) -> Result<Self> {
        let player = Player::open(path)?;
        let frame_count = Player::int_property(player.depth, oni::ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES).unwrap_or(0).max(0) as usize;
        if frame_count == 0 {
            return Err(Error::Dataset { path: path.to_owned(), message: "OpenNI2: the recording has no depth frames".to_owned() });
        }
        let mode = Player::video_mode(player.depth).ok_or_else(|| oni_error(path, "the depth stream has no video mode"))?;
        let depth_units_per_metre = match mode.pixelFormat {
            oni::ONI_PIXEL_FORMAT_DEPTH_1_MM => 1000.0,
            oni::ONI_PIXEL_FORMAT_DEPTH_100_UM => 10_000.0,
            other => return Err(Error::Dataset { path: path.to_owned(), message: format!("OpenNI2: unsupported depth pixel format {other} (need 1 mm or 100 µm)") }),
        };
        let (width_px, height_px) = (u32::try_from(mode.resolutionX).unwrap_or(0), u32::try_from(mode.resolutionY).unwrap_or(0));
        if width_px == 0 || height_px == 0 {
            return Err(Error::Dataset { path: path.to_owned(), message: format!("OpenNI2: depth resolution {}x{}", mode.resolutionX, mode.resolutionY) });
        }
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let calibration = resolve_calibration(&name, calibration_override, (width_px, height_px), depth_units_per_metre, player.depth)?;
        Ok(Self { path: path.to_owned(), calibration, frame_count, player: Some(player), next_index: 0 })
    }

    /// Reads the player's next frame (depth, then colour when recorded).
    fn read_next(&mut self) -> Result<RgbdFrame> {
        let player = match &self.player {
            Some(player) => player,
            None => self.player.insert(Player::open(&self.path)?),
        };
        let (depth, color) = (player.depth, player.color);
        let depth = Player::read(&self.path, depth)?;
        let color = color.map(|stream| Player::read(&self.path, stream)).transpose()?;
        let frame = rgbd_frame(&self.path, self.next_index as u64, &self.calibration, depth, color)?;
        self.next_index += 1;
        Ok(frame)
    }
}

impl FrameSource for OniSource {
    fn name(&self) -> String {
        self.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
    }

    fn calibration(&self) -> RgbdCalibration {
        self.calibration
    }

    fn frame_count(&self) -> usize {
        self.frame_count
    }

    fn read_frame(&mut self, index: usize) -> Result<RgbdFrame> {
        if index >= self.frame_count {
            return Err(Error::InvalidConfig(format!("frame {index} of {}, which has {} frames", self.name(), self.frame_count)));
        }
        if index < self.next_index {
            // The player's seek crashes: reopen and read forward.
            self.player = None;
            self.next_index = 0;
        }
        while self.next_index < index {
            self.read_next()?;
        }
        self.read_next()
    }

    fn ground_truth(&self) -> Option<&[TimedPose]> {
        None
    }
}

/// Longest wait for a frame from a live camera before it counts as gone.
const LIVE_FRAME_TIMEOUT_MS: c_int = 2000;

/// The video modes a device's sensor supports (empty when it does not say).
fn supported_modes(device: oni::OniDeviceHandle, sensor: oni::OniSensorType) -> Vec<oni::OniVideoMode> {
    // SAFETY: the device is open; the returned info (or null) is owned by OpenNI2 and read here only.
    unsafe {
        let info = oni::oniDeviceGetSensorInfo(device, sensor);
        if info.is_null() || (*info).pSupportedVideoModes.is_null() || (*info).numSupportedVideoModes <= 0 {
            return Vec::new();
        }
        std::slice::from_raw_parts((*info).pSupportedVideoModes, (*info).numSupportedVideoModes as usize).to_vec()
    }
}

/// Picks the mode of `pixel_format` at `size` (any size when `None`), preferring 640x480
/// and then the fps nearest 30.
fn pick_mode(modes: &[oni::OniVideoMode], pixel_format: oni::OniPixelFormat, size: Option<(i32, i32)>) -> Option<oni::OniVideoMode> {
    modes
        .iter()
        .filter(|m| m.pixelFormat == pixel_format && size.is_none_or(|s| (m.resolutionX, m.resolutionY) == s))
        .min_by_key(|m| ((m.resolutionX, m.resolutionY) != (640, 480), (m.fps - 30).abs()))
        .copied()
}

/// Sets `stream`'s video mode unless it is already `mode` (some drivers refuse any set).
fn set_mode(stream: oni::OniStreamHandle, mode: &oni::OniVideoMode) -> bool {
    if Player::video_mode(stream).is_some_and(|current| (current.pixelFormat, current.resolutionX, current.resolutionY, current.fps) == (mode.pixelFormat, mode.resolutionX, mode.resolutionY, mode.fps)) {
        return true;
    }
    // SAFETY: the stream is valid and `mode` has the size given.
    unsafe { oni::oniStreamSetProperty(stream, oni::ONI_STREAM_PROPERTY_VIDEO_MODE, (mode as *const oni::OniVideoMode).cast::<c_void>(), std::mem::size_of::<oni::OniVideoMode>() as c_int) == oni::ONI_STATUS_OK }
}

/// "vendor model (uri)" of an open device, if the driver says.
fn device_name(device: oni::OniDeviceHandle) -> Option<String> {
    // SAFETY: all-zero is a valid OniDeviceInfo (arrays of chars and integers).
    let mut info: oni::OniDeviceInfo = unsafe { std::mem::zeroed() };
    // SAFETY: the device is open and `info` a valid out-pointer.
    if unsafe { oni::oniDeviceGetInfo(device, &mut info) } != oni::ONI_STATUS_OK {
        return None;
    }
    let (vendor, name, uri) = (c_text(&info.vendor), c_text(&info.name), c_text(&info.uri));
    Some(format!("{} ({uri})", format!("{vendor} {name}").trim()))
}

/// A fixed-size C string field as text.
fn c_text(chars: &[std::ffi::c_char]) -> String {
    let bytes: Vec<u8> = chars.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

/// A live OpenNI2 camera (Kinect v1, Xtion, or the built-in "Dummy" device): depth in 1 mm
/// units registered to the colour camera, depth/colour pairs synchronised by the driver.
pub(crate) struct LiveDevice {
    /// What errors name: `openni2` or `openni2:<uri>`.
    label: PathBuf,
    name: String,
    calibration: RgbdCalibration,
    streams: Player,
    next_index: u64,
    /// Timestamp of the last depth frame handed out (µs).
    last_depth_us: Option<u64>,
    /// The device's number for the last depth frame handed out.
    last_device_index: Option<i32>,
    /// Depth frames the device numbered between those handed out: dropped before we read them.
    dropped: u64,
}

impl LiveDevice {
    /// Opens the device at `uri` (the first one when `None`). The calibration comes from the
    /// device's field of view unless `calibration_override` is given; its image size must be
    /// the depth stream's and its depth scale 1000 units per metre.
    pub(crate) fn open(uri: Option<&str>, calibration_override: Option<RgbdCalibration>) -> Result<Self> {
        let label = PathBuf::from(uri.map_or_else(|| "openni2".to_owned(), |u| format!("openni2:{u}")));
        initialise(&label)?;
        let c_uri = uri.map(CString::new).transpose().map_err(|_| Error::Dataset { path: label.clone(), message: "the URI contains a NUL byte".to_owned() })?;
        let mut device: oni::OniDeviceHandle = std::ptr::null_mut();
        // SAFETY: a NUL-terminated URI or null (any device), and a valid out-pointer.
        if unsafe { oni::oniDeviceOpen(c_uri.as_ref().map_or(std::ptr::null(), |u| u.as_ptr()), &mut device) } != oni::ONI_STATUS_OK || device.is_null() {
            let hint = "; `webfusion devices` lists what OpenNI2 sees (a Kinect v1 needs libfreenect's OpenNI2 driver)";
            return Err(Error::Dataset { path: label.clone(), message: format!("{}{hint}", oni_error(&label, "cannot open the device")) });
        }
        let mut streams = Player { device, depth: std::ptr::null_mut(), color: None };
        streams.depth = streams.create_stream(oni::ONI_SENSOR_DEPTH).ok_or_else(|| oni_error(&label, "the device has no depth stream"))?;
        if let Some(mode) = pick_mode(&supported_modes(device, oni::ONI_SENSOR_DEPTH), oni::ONI_PIXEL_FORMAT_DEPTH_1_MM, None)
            && !set_mode(streams.depth, &mode)
        {
            return Err(oni_error(&label, "cannot set the depth mode"));
        }
        let depth_mode = Player::video_mode(streams.depth).ok_or_else(|| oni_error(&label, "the depth stream has no video mode"))?;
        if depth_mode.pixelFormat != oni::ONI_PIXEL_FORMAT_DEPTH_1_MM {
            return Err(Error::Dataset { path: label, message: format!("OpenNI2: the depth stream has pixel format {} and offers no 1 mm mode", depth_mode.pixelFormat) });
        }
        let size = (depth_mode.resolutionX, depth_mode.resolutionY);
        // The Dummy device crashes OpenNI2 when asked about a colour sensor it lacks.
        let wants_color = uri != Some("Dummy");
        if wants_color && let Some(color) = streams.create_stream(oni::ONI_SENSOR_COLOR) {
            streams.color = Some(color);
            let mode = pick_mode(&supported_modes(device, oni::ONI_SENSOR_COLOR), oni::ONI_PIXEL_FORMAT_RGB888, Some(size))
                .ok_or_else(|| Error::Dataset { path: label.clone(), message: format!("OpenNI2: the colour camera has no RGB888 mode at the depth size {}x{}", size.0, size.1) })?;
            if !set_mode(color, &mode) {
                return Err(oni_error(&label, "cannot set the colour mode"));
            }
            // SAFETY: the device is open; the property value outlives the call.
            let registered = unsafe {
                let mode = oni::ONI_IMAGE_REGISTRATION_DEPTH_TO_COLOR;
                oni::oniDeviceIsImageRegistrationModeSupported(device, mode) != 0
                    && oni::oniDeviceSetProperty(device, oni::ONI_DEVICE_PROPERTY_IMAGE_REGISTRATION, (&raw const mode).cast::<c_void>(), std::mem::size_of_val(&mode) as c_int) == oni::ONI_STATUS_OK
            };
            if !registered {
                eprintln!("warning: {}: the driver cannot register depth to colour; colour will be offset from depth", label.display());
            }
            // SAFETY: the device is open. Failure only means unsynchronised pairs.
            unsafe { oni::oniDeviceEnableDepthColorSync(device) };
        }
        let (width_px, height_px) = (u32::try_from(size.0).unwrap_or(0), u32::try_from(size.1).unwrap_or(0));
        let name = device_name(device).unwrap_or_else(|| label.display().to_string());
        // Registered depth lives in the colour camera, so its field of view applies.
        let fov_stream = streams.color.unwrap_or(streams.depth);
        let calibration = resolve_calibration(&label.display().to_string(), calibration_override, (width_px, height_px), 1000.0, fov_stream)?;
        // Started last: an error above closes streams that never ran.
        for stream in std::iter::once(streams.depth).chain(streams.color) {
            // SAFETY: the stream was created on this device.
            if unsafe { oni::oniStreamStart(stream) } != oni::ONI_STATUS_OK {
                return Err(oni_error(&label, "cannot start a stream"));
            }
        }
        Ok(Self { label, name, calibration, streams, next_index: 0, last_depth_us: None, last_device_index: None, dropped: 0 })
    }
}

impl LiveSource for LiveDevice {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn frames_dropped(&self) -> u64 {
        self.dropped
    }

    fn calibration(&self) -> RgbdCalibration {
        self.calibration
    }

    fn next_frame(&mut self) -> Result<RgbdFrame> {
        // Some drivers (the Dummy device among them) hand the same frame out again; wait for a newer one.
        let deadline = std::time::Instant::now() + std::time::Duration::from_millis(LIVE_FRAME_TIMEOUT_MS as u64);
        let depth = loop {
            let depth = Player::read_within(&self.label, self.streams.depth, LIVE_FRAME_TIMEOUT_MS, LIVE_TIMEOUT_CAUSE)?;
            if self.last_depth_us.is_none_or(|last| depth.timestamp_us > last) {
                break depth;
            }
            if std::time::Instant::now() > deadline {
                return Err(no_frame_within(&self.label, LIVE_FRAME_TIMEOUT_MS, LIVE_TIMEOUT_CAUSE));
            }
            std::thread::sleep(std::time::Duration::from_millis(2));
        };
        self.last_depth_us = Some(depth.timestamp_us);
        if let Some(last) = self.last_device_index {
            self.dropped += u64::try_from(i64::from(depth.device_index) - i64::from(last) - 1).unwrap_or(0);
        }
        self.last_device_index = Some(depth.device_index);
        let color = self.streams.color.map(|stream| Player::read_within(&self.label, stream, LIVE_FRAME_TIMEOUT_MS, LIVE_TIMEOUT_CAUSE)).transpose()?;
        let frame = rgbd_frame(&self.label, self.next_index, &self.calibration, depth, color)?;
        self.next_index += 1;
        Ok(frame)
    }
}

/// One connected OpenNI2 device.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct DeviceInfo {
    /// URI to open it with (`--source openni2:<uri>`).
    pub(crate) uri: String,
    /// Vendor name.
    pub(crate) vendor: String,
    /// Model name.
    pub(crate) name: String,
    /// USB vendor and product id.
    pub(crate) usb_id: (u16, u16),
}

/// Lists the devices OpenNI2's drivers see (the Dummy device is never listed).
pub(crate) fn list_devices() -> Result<Vec<DeviceInfo>> {
    initialise(Path::new("openni2"))?;
    let mut list: *mut oni::OniDeviceInfo = std::ptr::null_mut();
    let mut count: c_int = 0;
    // SAFETY: valid out-pointers; the list is released below.
    if unsafe { oni::oniGetDeviceList(&mut list, &mut count) } != oni::ONI_STATUS_OK {
        return Err(oni_error(Path::new("openni2"), "cannot list devices"));
    }
    let devices = if list.is_null() || count <= 0 {
        Vec::new()
    } else {
        // SAFETY: OpenNI2 returned `count` entries at `list`.
        unsafe { std::slice::from_raw_parts(list, count as usize) }
            .iter()
            .map(|d| DeviceInfo { uri: c_text(&d.uri), vendor: c_text(&d.vendor), name: c_text(&d.name), usb_id: (d.usbVendorId, d.usbProductId) })
            .collect()
    };
    if !list.is_null() {
        // SAFETY: the list came from oniGetDeviceList and is released once.
        unsafe { oni::oniReleaseDeviceList(list) };
    }
    Ok(devices)
}

/// Records about `frames` depth frames of OpenNI2's built-in "Dummy" device (320x240, 1 mm)
/// into `path`, then makes the file playable (see [`add_cropping_property`]). Returns the
/// frames the file holds: the recorder runs on its own thread, so on a loaded machine it can
/// miss a frame at either end of the `frames` this function reads.
pub(crate) fn record_dummy(path: &Path, frames: usize) -> Result<usize> {
    initialise(path)?;
    let io_error = |source| Error::Io { path: path.to_owned(), source };
    let dummy = c"Dummy";
    let file = CString::new(path.as_os_str().as_encoded_bytes()).map_err(|_| Error::Dataset { path: path.to_owned(), message: "path contains a NUL byte".to_owned() })?;
    let mut device: oni::OniDeviceHandle = std::ptr::null_mut();
    // SAFETY: NUL-terminated URI, valid out-pointer.
    if unsafe { oni::oniDeviceOpen(dummy.as_ptr(), &mut device) } != oni::ONI_STATUS_OK || device.is_null() {
        return Err(oni_error(path, "cannot open the Dummy device"));
    }
    // Reuse Player's cleanup for the device and its depth stream.
    let mut player = Player { device, depth: std::ptr::null_mut(), color: None };
    player.depth = player.create_stream(oni::ONI_SENSOR_DEPTH).ok_or_else(|| oni_error(path, "the Dummy device has no depth stream"))?;
    let mut recorder: oni::OniRecorderHandle = std::ptr::null_mut();
    // SAFETY: NUL-terminated file name, valid out-pointer; the recorder is destroyed below.
    unsafe {
        if oni::oniCreateRecorder(file.as_ptr(), &mut recorder) != oni::ONI_STATUS_OK || recorder.is_null() {
            return Err(oni_error(path, "cannot create a recorder"));
        }
        // Recorder first, then the stream, so the recording starts with the stream's first frame.
        let started = oni::oniRecorderAttachStream(recorder, player.depth, 0) == oni::ONI_STATUS_OK
            && oni::oniRecorderStart(recorder) == oni::ONI_STATUS_OK
            && oni::oniStreamStart(player.depth) == oni::ONI_STATUS_OK;
        let recorded = if started { (0..frames).try_for_each(|_| Player::read(path, player.depth).map(drop)) } else { Err(oni_error(path, "cannot start recording")) };
        oni::oniRecorderStop(recorder);
        oni::oniRecorderDestroy(&mut recorder);
        recorded?;
    }
    drop(player);
    let bytes = std::fs::read(path).map_err(io_error)?;
    let patched = add_cropping_property(&bytes).map_err(|message| Error::Dataset { path: path.to_owned(), message })?;
    std::fs::write(path, patched).map_err(io_error)?;
    let player = Player::open(path)?;
    match Player::int_property(player.depth, oni::ONI_STREAM_PROPERTY_NUMBER_OF_FRAMES) {
        Some(count) if count > 0 => Ok(count as usize),
        _ => Err(Error::Dataset { path: path.to_owned(), message: "OpenNI2: the recorder wrote no frames".to_owned() }),
    }
}

/// `.oni` record header: magic, type, node id, fields size, payload size, undo position.
const RECORD_HEADER_BYTES: usize = 28;
const RECORD_MAGIC: u32 = 0x0052_494E;
const FILE_HEADER_BYTES: usize = 24;
const RECORD_GENERAL_PROPERTY: u32 = 0x06;
const RECORD_END: u32 = 0x0B;
const RECORD_NODE_ADDED: u32 = 0x0D;
const RECORD_SEEK_TABLE: u32 = 0x0E;
/// Seek-table entry: timestamp u64, configuration id u32, file offset u64.
const SEEK_ENTRY_BYTES: usize = 20;

/// Inserts a disabled `xnCropping` general property after a depth node's `xnMapOutputMode`
/// and shifts every stored file offset past it. Debian's player plays no frames of a node
/// without this property, and the Dummy device does not report it.
fn add_cropping_property(bytes: &[u8]) -> std::result::Result<Vec<u8>, String> {
    let u32_at = |at: usize| bytes.get(at..at + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).ok_or_else(|| format!("truncated at byte {at}"));
    let u64_at = |at: usize| bytes.get(at..at + 8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8]))).ok_or_else(|| format!("truncated at byte {at}"));
    if bytes.get(..4) != Some(b"NI10") {
        return Err("not an OpenNI recording (no NI10 header)".to_owned());
    }
    struct Record {
        at: usize,
        kind: u32,
        node: u32,
        fields: usize,
        payload: usize,
    }
    let mut records = Vec::new();
    let mut at = FILE_HEADER_BYTES;
    loop {
        if u32_at(at)? != RECORD_MAGIC {
            return Err(format!("no record at byte {at}"));
        }
        let record = Record { at, kind: u32_at(at + 4)?, node: u32_at(at + 8)?, fields: u32_at(at + 12)? as usize, payload: u32_at(at + 16)? as usize };
        if record.fields < RECORD_HEADER_BYTES || at + record.fields + record.payload > bytes.len() {
            return Err(format!("record at byte {at} overruns the file"));
        }
        at += record.fields + record.payload;
        let end = record.kind == RECORD_END;
        records.push(record);
        if end {
            break;
        }
    }
    let name_of = |r: &Record| -> Option<Vec<u8>> {
        let len = u32_at(r.at + RECORD_HEADER_BYTES).ok()? as usize;
        bytes.get(r.at + RECORD_HEADER_BYTES + 4..r.at + RECORD_HEADER_BYTES + 4 + len.checked_sub(1)?).map(<[u8]>::to_vec)
    };
    let anchor = records
        .iter()
        .find(|r| r.kind == RECORD_GENERAL_PROPERTY && name_of(r).as_deref() == Some(b"xnMapOutputMode"))
        .ok_or("no xnMapOutputMode property to anchor the cropping property")?;
    if records.iter().any(|r| r.kind == RECORD_GENERAL_PROPERTY && name_of(r).as_deref() == Some(b"xnCropping")) {
        return Ok(bytes.to_vec());
    }
    let insert_at = anchor.at + anchor.fields + anchor.payload;
    // XnCropping { enabled: u32, x, y, width, height: u16 } = 12 zero bytes (disabled).
    let name = b"xnCropping\0";
    let data = [0_u8; 12];
    let mut body = Vec::new();
    body.extend_from_slice(&(name.len() as u32).to_le_bytes());
    body.extend_from_slice(name);
    body.extend_from_slice(&(data.len() as u32).to_le_bytes());
    body.extend_from_slice(&data);
    let mut record = Vec::new();
    for v in [RECORD_MAGIC, RECORD_GENERAL_PROPERTY, anchor.node, (RECORD_HEADER_BYTES + body.len()) as u32, 0] {
        record.extend_from_slice(&v.to_le_bytes());
    }
    record.extend_from_slice(&0_u64.to_le_bytes());
    record.extend_from_slice(&body);
    let shift = record.len() as u64;
    let mut out = bytes.to_vec();
    let shift_u64_at = |out: &mut Vec<u8>, at: usize| -> std::result::Result<(), String> {
        let value = u64_at(at)?;
        if value >= insert_at as u64 {
            out[at..at + 8].copy_from_slice(&(value + shift).to_le_bytes());
        }
        Ok(())
    };
    for r in &records {
        shift_u64_at(&mut out, r.at + 20)?; // undo record position
        if r.kind == RECORD_NODE_ADDED {
            // name, node type, codec, frame count, min and max timestamp, seek-table position.
            let name_len = u32_at(r.at + RECORD_HEADER_BYTES)? as usize;
            shift_u64_at(&mut out, r.at + RECORD_HEADER_BYTES + 4 + name_len + 12 + 16)?;
        }
        if r.kind == RECORD_SEEK_TABLE {
            for entry in 0..r.payload / SEEK_ENTRY_BYTES {
                shift_u64_at(&mut out, r.at + r.fields + entry * SEEK_ENTRY_BYTES + 12)?;
            }
        }
    }
    out.splice(insert_at..insert_at, record);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dummy_recordings_play_back_every_frame_and_seek_by_reopening() {
        let path = std::env::temp_dir().join(format!("webfusion-dummy-{}.oni", std::process::id()));
        let count = record_dummy(&path, 12).expect("recording the Dummy device");
        assert!((6..=12).contains(&count), "recorded {count} of 12 frames");
        assert!(matches!(OniSource::open(&path, None), Err(Error::UnknownCalibration { .. })), "no field of view: --intrinsics needed");
        let calibration = |units| RgbdCalibration { intrinsics: PinholeIntrinsics { fx_px: 285.0, fy_px: 285.0, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 }, depth_units_per_metre: units };
        assert!(matches!(OniSource::open(&path, Some(calibration(5000.0))), Err(Error::InvalidConfig(_))), "wrong depth scale");
        let mut source = OniSource::open(&path, Some(calibration(1000.0))).expect("opening");
        assert_eq!(source.frame_count(), count, "frames");
        let frames: Vec<RgbdFrame> = (0..count).map(|i| source.read_frame(i).expect("reading")).collect();
        let stamps: Vec<i64> = frames.iter().map(|f| f.depth_timestamp_ns).collect();
        assert!(stamps.windows(2).all(|w| w[1] > w[0]), "timestamps increase: {stamps:?}");
        assert!(frames.iter().all(|f| f.color.rgb8.iter().all(|&v| v == GREY)), "depth-only recording: grey colour");
        let again = source.read_frame(5).expect("reading backwards");
        assert_eq!(again, frames[5], "frame 5 after reopening");
        assert!(source.read_frame(count).is_err(), "past the end");
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn the_dummy_device_streams_live_frames_in_order() {
        let k = PinholeIntrinsics { fx_px: 285.0, fy_px: 285.0, cx_px: 159.5, cy_px: 119.5, width_px: 320, height_px: 240 };
        let calibration = RgbdCalibration { intrinsics: k, depth_units_per_metre: 1000.0 };
        match LiveDevice::open(Some("Dummy"), None) {
            Err(Error::UnknownCalibration { source_name }) => assert_eq!(source_name, "openni2:Dummy", "names the source"),
            Err(other) => panic!("expected UnknownCalibration without a field of view, got {other}"),
            Ok(_) => panic!("the Dummy device reports no field of view"),
        }
        let wrong_scale = RgbdCalibration { depth_units_per_metre: 5000.0, ..calibration };
        let error = LiveDevice::open(Some("Dummy"), Some(wrong_scale)).err().expect("live depth is in mm").to_string();
        assert!(error.contains("--depth-scale 1000"), "{error}");
        let mut device = LiveDevice::open(Some("Dummy"), Some(calibration)).expect("opening the Dummy device");
        assert!(device.name().contains("Dummy"), "{}", device.name());
        let frames: Vec<RgbdFrame> = (0..5).map(|_| device.next_frame().expect("a live frame")).collect();
        for (i, frame) in frames.iter().enumerate() {
            assert_eq!(frame.index, i as u64, "numbered in order");
            assert_eq!((frame.depth.width_px, frame.depth.height_px, frame.color.width_px), (320, 240, 320), "frame {i} size");
        }
        let stamps: Vec<i64> = frames.iter().map(|f| f.depth_timestamp_ns).collect();
        assert!(stamps.windows(2).all(|w| w[1] > w[0]), "timestamps increase: {stamps:?}");
        let missing = LiveDevice::open(Some("no-such-device://0"), Some(calibration)).err().expect("no such device").to_string();
        assert!(missing.contains("webfusion devices"), "{missing}");
    }

    #[test]
    fn the_patch_needs_an_oni_file() {
        assert!(add_cropping_property(b"hello").is_err(), "not an oni file");
        let mut truncated = b"NI10".to_vec();
        truncated.resize(40, 0);
        assert!(add_cropping_property(&truncated).is_err(), "no records");
    }
}
