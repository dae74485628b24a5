// SPDX-License-Identifier: MIT
//! GPU test harness for webfusion's native tests.
//!
//! - [`gpu`] creates a fresh device per test on a Vulkan adapter, preferring a CPU adapter
//!   (Mesa lavapipe) so results do not depend on the machine's GPU. No adapter is a loud
//!   failure, never a skip.
//! - [`run_kernel`] runs one kernel on given inputs with outputs pre-filled with
//!   [`SENTINEL_F32`], so "not written" can never pass as a result.
//! - [`compare_f32`] / [`compare_vec4`] compare GPU and CPU outputs: NaN (invalid) masks must
//!   agree exactly, valid values within a [`Tolerance`]. [`assert_negative_control`] proves, for
//!   each test, that the comparison does fail on a perturbed result.
//! - [`finish`] fails the test if wgpu reported any uncaptured validation error.

use std::path::PathBuf;

use webfusion_core::recording::RecordingReader;
use webfusion_core::kernels::KernelPipeline;
use webfusion_core::source::FrameSource;
use webfusion_core::{Gpu, GpuOptions, RgbdCalibration, RgbdFrame};

/// Written into every output buffer before a kernel runs: finite, so it cannot be mistaken
/// for the NaN invalid marker, and far from any real value.
pub const SENTINEL_F32: f32 = f32::from_bits(0xDEAD_BEEF);

/// A fresh GPU context on a Vulkan adapter (lavapipe preferred). Panics with a clear message
/// when none exists.
pub fn gpu() -> Gpu {
    let options = GpuOptions { prefer_cpu_adapter: true, ..Default::default() };
    match pollster::block_on(Gpu::new(&options)) {
        Ok(gpu) => gpu,
        Err(e) => panic!("GPU tests need a Vulkan adapter and none is usable: {e}"),
    }
}

/// Fails the test if wgpu reported any uncaptured error during it.
pub fn finish(gpu: &Gpu) {
    let errors = gpu.take_errors();
    assert!(errors.is_empty(), "wgpu reported {} uncaptured error(s):\n{}", errors.len(), errors.join("\n"));
}

/// Maximum allowed |gpu - cpu| = `absolute + relative * |cpu|`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerance {
    /// Absolute part, in the compared quantity's unit.
    pub absolute: f32,
    /// Relative part.
    pub relative: f32,
}

impl Tolerance {
    /// Bit-for-bit equality of valid values.
    pub const EXACT: Tolerance = Tolerance { absolute: 0.0, relative: 0.0 };

    /// The allowed error at reference value `cpu`.
    pub fn allowed(&self, cpu: f32) -> f32 {
        self.absolute + self.relative * cpu.abs()
    }
}

/// What a successful comparison saw.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Comparison {
    /// Values compared.
    pub compared: usize,
    /// Of those, invalid (NaN) in both.
    pub invalid: usize,
    /// Largest |gpu - cpu| among valid values.
    pub max_abs_err: f32,
}

/// Compares flat f32 outputs. Invalid (NaN) must match exactly; valid values within `tol`.
pub fn compare_f32(what: &str, gpu: &[f32], cpu: &[f32], tol: Tolerance) -> Result<Comparison, String> {
    if gpu.len() != cpu.len() {
        return Err(format!("{what}: GPU gave {} values, CPU {}", gpu.len(), cpu.len()));
    }
    let mut c = Comparison { compared: gpu.len(), ..Default::default() };
    for (i, (&g, &r)) in gpu.iter().zip(cpu).enumerate() {
        match (g.is_nan(), r.is_nan()) {
            (true, true) => c.invalid += 1,
            (false, false) => {
                let err = (g - r).abs();
                if !(err <= tol.allowed(r)) {
                    return Err(format!("{what}[{i}]: GPU {g:e} vs CPU {r:e}, |diff| {err:e} > allowed {:e}", tol.allowed(r)));
                }
                c.max_abs_err = c.max_abs_err.max(err);
            }
            _ => return Err(format!("{what}[{i}]: validity differs: GPU {g:e} vs CPU {r:e}")),
        }
    }
    Ok(c)
}

/// Compares vec4 outputs component-wise (see [`compare_f32`]).
pub fn compare_vec4(what: &str, gpu: &[[f32; 4]], cpu: &[[f32; 4]], tol: Tolerance) -> Result<Comparison, String> {
    compare_f32(what, gpu.as_flattened(), cpu.as_flattened(), tol)
}

/// Proves the comparison can fail: for a passing pair, each of these perturbations of the GPU
/// result must be rejected: a valid value moved by 4x the tolerance (plus 1e-3 relative), a
/// valid value replaced by NaN, an invalid value replaced by 0, and a value left at the
/// sentinel.
pub fn assert_negative_control(what: &str, gpu: &[f32], cpu: &[f32], tol: Tolerance) {
    compare_f32(what, gpu, cpu, tol).unwrap_or_else(|e| panic!("negative control needs a passing pair first: {e}"));
    let valid_ix = cpu.iter().position(|v| !v.is_nan()).expect("negative control needs at least one valid value");
    let mut moved = gpu.to_vec();
    let r = cpu[valid_ix];
    moved[valid_ix] = r + 4.0 * tol.allowed(r) + 1e-3 * r.abs().max(1e-3);
    assert!(compare_f32(what, &moved, cpu, tol).is_err(), "{what}: a value moved beyond tolerance was accepted");
    let mut nan = gpu.to_vec();
    nan[valid_ix] = f32::NAN;
    assert!(compare_f32(what, &nan, cpu, tol).is_err(), "{what}: a valid value turned NaN was accepted");
    let mut sentinel = gpu.to_vec();
    sentinel[valid_ix] = SENTINEL_F32;
    assert!(compare_f32(what, &sentinel, cpu, tol).is_err(), "{what}: an unwritten (sentinel) value was accepted");
    if let Some(invalid_ix) = cpu.iter().position(|v| v.is_nan()) {
        let mut filled = gpu.to_vec();
        filled[invalid_ix] = 0.0;
        assert!(compare_f32(what, &filled, cpu, tol).is_err(), "{what}: an invalid value turned 0 was accepted");
    }
}

/// [`assert_negative_control`] for vec4 outputs.
pub fn assert_negative_control_vec4(what: &str, gpu: &[[f32; 4]], cpu: &[[f32; 4]], tol: Tolerance) {
    assert_negative_control(what, gpu.as_flattened(), cpu.as_flattened(), tol);
}

/// Runs `pipeline` once: binding 0 gets `params` as a uniform, then `inputs` (bytes) and then
/// `output_sizes` storage buffers (bytes), all outputs pre-filled with [`SENTINEL_F32`].
/// Returns the outputs' bytes.
pub fn run_kernel<P: bytemuck::Pod>(gpu: &Gpu, pipeline: &KernelPipeline, params: &P, inputs: &[&[u8]], output_sizes: &[usize], invocations: [u32; 3]) -> Vec<Vec<u8>> {
    let name = pipeline.kernel.name;
    let params_buffer = gpu.uniform_buffer(&format!("test.{name}.params"), params);
    let input_buffers: Vec<wgpu::Buffer> = inputs
        .iter()
        .enumerate()
        .map(|(i, bytes)| {
            let b = gpu.storage_buffer::<u8>(&format!("test.{name}.input{i}"), bytes.len());
            gpu.write_buffer(&b, bytes);
            b
        })
        .collect();
    let output_buffers: Vec<wgpu::Buffer> = output_sizes
        .iter()
        .enumerate()
        .map(|(i, &size)| {
            let b = gpu.storage_buffer::<u8>(&format!("test.{name}.output{i}"), size);
            gpu.fill_buffer(&b, SENTINEL_F32);
            b
        })
        .collect();
    let mut all = vec![&params_buffer];
    all.extend(input_buffers.iter());
    all.extend(output_buffers.iter());
    let bind_group = bind_in_order(gpu, pipeline, &all);
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.run_kernel") });
    pipeline.dispatch(&mut encoder, &bind_group, invocations);
    pollster::block_on(gpu.submit_and_wait(encoder)).expect("GPU work finishes");
    output_buffers
        .iter()
        .zip(output_sizes)
        .map(|(b, &size)| pollster::block_on(gpu.read_buffer::<u8>(b, size.next_multiple_of(4))).expect("readback").into_iter().take(size).collect())
        .collect()
}

/// Binds `buffers` to the kernel's reflected bindings in WGSL order (the harness feeds any
/// kernel generic inputs; production code uses the kernels' typed `Bindings`).
fn bind_in_order(gpu: &Gpu, pipeline: &KernelPipeline, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
    let bindings = pipeline.kernel.bindings;
    assert_eq!(buffers.len(), bindings.len(), "kernel {} has {} bindings, the test gave {}", pipeline.kernel.name, bindings.len(), buffers.len());
    let entries: Vec<wgpu::BindGroupEntry> = bindings.iter().zip(buffers).map(|(b, buf)| wgpu::BindGroupEntry { binding: b.binding, resource: buf.as_entire_binding() }).collect();
    pipeline.bind_group(&gpu.device, &entries)
}

/// A buffer of `len` bytes for the `slot`-th binding after the params: a uniform buffer where
/// the kernel declares a uniform (the camera pose), else a storage buffer.
fn slot_buffer(gpu: &Gpu, pipeline: &KernelPipeline, slot: usize, label: &str, len: usize) -> wgpu::Buffer {
    let uniform = pipeline.kernel.bindings.get(slot + 1).is_some_and(|b| b.kind == webfusion_shaders::BindingKind::Uniform);
    if !uniform {
        return gpu.storage_buffer::<u8>(label, len);
    }
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: len.max(1).next_multiple_of(16) as u64,
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// One storage binding of [`run_kernel_slots`], in WGSL binding order after the params.
#[derive(Clone, Copy, Debug)]
pub enum Slot<'a> {
    /// A read-only input with these bytes.
    In(&'a [u8]),
    /// An output of this many bytes, pre-filled with [`SENTINEL_F32`].
    Out(usize),
    /// A buffer read and written in place, starting with these bytes (returned with the
    /// outputs).
    InOut(&'a [u8]),
}

/// Runs `pipeline` once with `params` at binding 0 and `slots` (inputs and outputs in any order,
/// as the kernel declares them); returns the outputs' bytes in order.
pub fn run_kernel_slots<P: bytemuck::Pod>(gpu: &Gpu, pipeline: &KernelPipeline, params: &P, slots: &[Slot], invocations: [u32; 3]) -> Vec<Vec<u8>> {
    let name = pipeline.kernel.name;
    let params_buffer = gpu.uniform_buffer(&format!("test.{name}.params"), params);
    let buffers: Vec<(wgpu::Buffer, Option<usize>)> = slots
        .iter()
        .enumerate()
        .map(|(i, slot)| match slot {
            Slot::In(bytes) => {
                let b = slot_buffer(gpu, pipeline, i, &format!("test.{name}.slot{i}"), bytes.len());
                gpu.write_buffer(&b, bytes);
                (b, None)
            }
            Slot::Out(size) => {
                let b = gpu.storage_buffer::<u8>(&format!("test.{name}.slot{i}"), *size);
                gpu.fill_buffer(&b, SENTINEL_F32);
                (b, Some(*size))
            }
            Slot::InOut(bytes) => {
                let b = gpu.storage_buffer::<u8>(&format!("test.{name}.slot{i}"), bytes.len());
                gpu.write_buffer(&b, bytes);
                (b, Some(bytes.len()))
            }
        })
        .collect();
    let mut all = vec![&params_buffer];
    all.extend(buffers.iter().map(|(b, _)| b));
    let bind_group = bind_in_order(gpu, pipeline, &all);
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.run_kernel_slots") });
    pipeline.dispatch(&mut encoder, &bind_group, invocations);
    pollster::block_on(gpu.submit_and_wait(encoder)).expect("GPU work finishes");
    buffers
        .iter()
        .filter_map(|(b, size)| size.map(|size| pollster::block_on(gpu.read_buffer::<u8>(b, size.next_multiple_of(4))).expect("readback").into_iter().take(size).collect()))
        .collect()
}

/// Reinterprets bytes read back from the GPU.
pub fn cast<T: bytemuck::Pod>(bytes: &[u8]) -> Vec<T> {
    bytemuck::pod_collect_to_vec(bytes)
}

/// The bundled sample, `data/sample/fr1_rpy.wfr`: TUM `freiburg1_rpy` frames 0-99 (real
/// Kinect frames, depth bit-exact, colour JPEG) with their motion-capture ground truth. Part
/// of the repository, so these tests need nothing beside it.
pub fn sample() -> RecordingReader {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data/sample/fr1_rpy.wfr");
    RecordingReader::open(&path).unwrap_or_else(|e| panic!("opening the bundled sample {}: {e}", path.display()))
}

/// Frame `index` of the sample with its calibration.
pub fn sample_frame(index: usize) -> (RgbdCalibration, RgbdFrame) {
    let mut sample = sample();
    let frame = sample.read_frame(index).expect("reading a sample frame");
    (sample.calibration(), frame)
}

/// Runs `pipeline` once with `params` at binding 0 and `buffers` (initial bytes, in binding
/// order) as storage buffers that the kernel may read and write; returns every buffer's bytes
/// afterwards. For kernels that update state in place (the TSDF volume).
pub fn run_kernel_in_place<P: bytemuck::Pod>(gpu: &Gpu, pipeline: &KernelPipeline, params: &P, buffers: &[&[u8]], invocations: [u32; 3]) -> Vec<Vec<u8>> {
    let name = pipeline.kernel.name;
    let params_buffer = gpu.uniform_buffer(&format!("test.{name}.params"), params);
    let storage: Vec<wgpu::Buffer> = buffers
        .iter()
        .enumerate()
        .map(|(i, bytes)| {
            let b = slot_buffer(gpu, pipeline, i, &format!("test.{name}.buffer{i}"), bytes.len());
            gpu.write_buffer(&b, bytes);
            b
        })
        .collect();
    let mut all = vec![&params_buffer];
    all.extend(storage.iter());
    let bind_group = bind_in_order(gpu, pipeline, &all);
    let mut encoder = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("test.run_kernel_in_place") });
    pipeline.dispatch(&mut encoder, &bind_group, invocations);
    pollster::block_on(gpu.submit_and_wait(encoder)).expect("GPU work finishes");
    storage
        .iter()
        .zip(buffers)
        .map(|(b, bytes)| pollster::block_on(gpu.read_buffer::<u8>(b, bytes.len().next_multiple_of(4))).expect("readback").into_iter().take(bytes.len()).collect())
        .collect()
}

/// Compares a Rust mirror with naga's layout of WGSL struct `$wgsl` in `$kernel`: size, and the
/// listed members' names and offsets in declaration order (generated padding fields excluded).
#[macro_export]
macro_rules! check_layout {
    ($kernel:expr, $wgsl:literal, $ty:ty, [$($field:ident),* $(,)?]) => {{
        let layout = $kernel.struct_layout($wgsl).unwrap_or_else(|| panic!("{} has no struct {}", $kernel.name, $wgsl));
        assert_eq!(std::mem::size_of::<$ty>() as u32, layout.size_bytes, "size of {}", $wgsl);
        let rust: Vec<(&str, u32)> = vec![$((stringify!($field), std::mem::offset_of!($ty, $field) as u32)),*];
        let wgsl: Vec<(&str, u32)> = layout.members.iter().map(|m| (m.name, m.offset_bytes)).collect();
        assert_eq!(rust, wgsl, "members of {}", $wgsl);
    }};
}


/// Compares two arrays of integer results (labels, ids) element by element: equal lengths and
/// at most `max_differ_per_mille` ‰ of the elements different (results at a threshold may fall
/// either way when WGSL fuses a multiply-add); returns how many differ.
pub fn compare_u32_mostly(what: &str, gpu: &[u32], cpu: &[u32], max_differ_per_mille: usize) -> Result<usize, String> {
    if gpu.len() != cpu.len() {
        return Err(format!("{what}: {} GPU values vs {} CPU", gpu.len(), cpu.len()));
    }
    let differ = gpu.iter().zip(cpu).filter(|(a, b)| a != b).count();
    if differ * 1000 > gpu.len() * max_differ_per_mille {
        return Err(format!("{what}: {differ} of {} values differ (allowed {max_differ_per_mille} per mille)", gpu.len()));
    }
    Ok(differ)
}

/// Compares RGBA8 images (red in the low byte) pixel by pixel: every channel within
/// `max_channel_diff` and at least `min_exact_fraction` of the pixels identical. Pixels the
/// CPU left at [`SENTINEL_F32`] (padding) must be the sentinel on the GPU too.
pub fn compare_rgba8(what: &str, gpu: &[u32], cpu: &[u32], max_channel_diff: u8, min_exact_fraction: f64) -> Result<usize, String> {
    if gpu.len() != cpu.len() {
        return Err(format!("{what}: {} GPU pixels vs {} CPU", gpu.len(), cpu.len()));
    }
    let sentinel = SENTINEL_F32.to_bits();
    let mut exact = 0;
    for (i, (&g, &c)) in gpu.iter().zip(cpu).enumerate() {
        if (g == sentinel) != (c == sentinel) {
            return Err(format!("{what}[{i}]: written on one side only (GPU {g:#010x}, CPU {c:#010x})"));
        }
        let worst = g.to_le_bytes().iter().zip(c.to_le_bytes()).map(|(a, b)| a.abs_diff(b)).max().unwrap_or(0);
        if worst > max_channel_diff {
            return Err(format!("{what}[{i}]: GPU {g:#010x} vs CPU {c:#010x}, a channel {worst} apart (allowed {max_channel_diff})"));
        }
        exact += usize::from(g == c);
    }
    if (exact as f64) < min_exact_fraction * gpu.len() as f64 {
        return Err(format!("{what}: only {exact} of {} pixels identical (need {min_exact_fraction})", gpu.len()));
    }
    Ok(exact)
}

/// Proves [`compare_rgba8`] can fail on `gpu`: a channel moved past the tolerance, a written
/// pixel turned into the sentinel, a padding (sentinel) pixel written, and every pixel off by
/// one when exact pixels are required must each be rejected.
pub fn assert_negative_control_rgba8(what: &str, gpu: &[u32], cpu: &[u32], max_channel_diff: u8, min_exact_fraction: f64) {
    let sentinel = SENTINEL_F32.to_bits();
    let written = cpu.iter().position(|&c| c != sentinel).expect("a written pixel");
    let mut moved = gpu.to_vec();
    moved[written] ^= u32::from(max_channel_diff.max(1)) * 2 + 1;
    let mut erased = gpu.to_vec();
    erased[written] = sentinel;
    let mut cases = vec![("a channel past tolerance", moved), ("a written pixel left at the sentinel", erased)];
    if let Some(pad) = cpu.iter().position(|&c| c == sentinel) {
        let mut padded = gpu.to_vec();
        padded[pad] = 0xff00_0000;
        cases.push(("a padding pixel written", padded));
    }
    if min_exact_fraction > 0.0 {
        cases.push(("every pixel one off", gpu.iter().map(|&g| if g == sentinel { g } else { g ^ 1 }).collect()));
    }
    for (case, perturbed) in cases {
        assert!(compare_rgba8(what, &perturbed, cpu, max_channel_diff, min_exact_fraction).is_err(), "{what}: the comparison accepted {case}");
    }
}
