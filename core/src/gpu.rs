// SPDX-License-Identifier: MIT
//! The GPU context: one adapter, device and queue, with every kernel pipeline built once.
//!
//! Natively this is Vulkan (Mesa lavapipe is a valid adapter, device type `Cpu`); in the
//! browser it is WebGPU. The constructor is async so the same code serves both: native callers
//! drive it with `pollster::block_on`, the web app with `wasm_bindgen_futures`.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use crate::kernels::Kernels;
use crate::{Error, Result};

/// Bytes of workgroup memory requested where the adapter offers them (lavapipe and desktop
/// GPUs do; wgpu's default is 16 KiB).
pub const PREFERRED_WORKGROUP_STORAGE_BYTES: u32 = 32 * 1024;
/// Storage-buffer binding size the volume kernels need: a 256^3 TSDF of 2 x 16-bit voxels.
pub const REQUIRED_STORAGE_BINDING_BYTES: u64 = 128 * 1024 * 1024;
/// The largest storage binding requested where the adapter offers more than
/// [`REQUIRED_STORAGE_BINDING_BYTES`] (natively and in browsers alike): 1 GiB, a 512^3 dense box
/// or a sparse pool of 524,288 blocks. Beyond it a byte offset into one binding would pass
/// 2^31, which some drivers compute in signed 32-bit arithmetic. Requesting the limit costs
/// nothing: buffers are still sized by what they hold.
pub const LARGEST_STORAGE_BINDING_BYTES: u64 = 1 << 30;
/// Seconds a native wait on the GPU may take before it is reported as an error.
pub const POLL_TIMEOUT_S: u64 = 30;

/// How to pick the adapter.
#[derive(Clone, Debug, Default)]
pub struct GpuOptions {
    /// Only use an adapter whose name contains this (case-insensitive), e.g. `llvmpipe`.
    /// Natively the environment variable `WEBFUSION_ADAPTER` supplies a default.
    pub adapter_name_contains: Option<String>,
    /// Prefer a CPU adapter (lavapipe) over real GPUs, as the test suite does for determinism.
    pub prefer_cpu_adapter: bool,
}

/// Device, queue, adapter facts and the kernel pipelines.
pub struct Gpu {
    /// The logical device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Name, backend and type of the adapter.
    pub adapter_info: wgpu::AdapterInfo,
    /// The limits the device was created with.
    pub limits: wgpu::Limits,
    /// Every kernel, compiled for this device.
    pub kernels: Kernels,
    /// Whether passes can carry GPU timestamps (`Features::TIMESTAMP_QUERY`).
    pub has_timestamps: bool,
    /// Submissions, host waits and readbacks so far.
    pub counters: GpuCounters,
    errors: Arc<Mutex<Vec<String>>>,
    lost: Arc<Mutex<Option<String>>>,
    /// Mappable staging buffers kept for reuse by [`Gpu::read_buffers`].
    staging: Mutex<Vec<wgpu::Buffer>>,
    /// The instance the adapter came from (none when built from a given adapter): what
    /// surfaces (a browser canvas) are created on.
    pub instance: Option<wgpu::Instance>,
}

/// How often the host touched the GPU: every submission, every wait for the GPU (a blocking
/// poll natively, an awaited callback in the browser) and every readback. A frame of the
/// pipeline is meant to be one submission and one late readback with no wait.
#[derive(Debug, Default)]
pub struct GpuCounters {
    submits: AtomicU64,
    host_waits: AtomicU64,
    readbacks: AtomicU64,
    readback_bytes: AtomicU64,
}

/// A snapshot of [`GpuCounters`]; subtract two to count what happened between them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GpuCounts {
    /// Command buffer submissions.
    pub submits: u64,
    /// Times the host waited for the GPU.
    pub host_waits: u64,
    /// Buffers copied back to the host.
    pub readbacks: u64,
    /// Bytes copied back.
    pub readback_bytes: u64,
}

impl std::ops::Sub for GpuCounts {
    type Output = Self;
    fn sub(self, rhs: Self) -> Self {
        Self {
            submits: self.submits - rhs.submits,
            host_waits: self.host_waits - rhs.host_waits,
            readbacks: self.readbacks - rhs.readbacks,
            readback_bytes: self.readback_bytes - rhs.readback_bytes,
        }
    }
}

impl GpuCounters {
    /// The counts so far.
    pub fn snapshot(&self) -> GpuCounts {
        GpuCounts {
            submits: self.submits.load(Ordering::Relaxed),
            host_waits: self.host_waits.load(Ordering::Relaxed),
            readbacks: self.readbacks.load(Ordering::Relaxed),
            readback_bytes: self.readback_bytes.load(Ordering::Relaxed),
        }
    }

    pub(crate) fn count_submit(&self) {
        self.submits.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn count_wait(&self) {
        self.host_waits.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn count_readback(&self, bytes: u64) {
        self.readbacks.fetch_add(1, Ordering::Relaxed);
        self.readback_bytes.fetch_add(bytes, Ordering::Relaxed);
    }
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu").field("adapter", &self.adapter_info.name).field("backend", &self.adapter_info.backend).finish()
    }
}

impl Gpu {
    /// Finds an adapter, checks it offers what the kernels need, creates the device and builds
    /// every pipeline.
    pub async fn new(options: &GpuOptions) -> Result<Self> {
        let backends = if cfg!(target_arch = "wasm32") { wgpu::Backends::BROWSER_WEBGPU } else { wgpu::Backends::VULKAN };
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends;
        desc.flags = wgpu::InstanceFlags::from_build_config().with_env();
        let instance = wgpu::Instance::new(desc);
        let adapter = select_adapter(&instance, backends, options).await?;
        let mut gpu = Self::from_adapter(&adapter).await?;
        gpu.instance = Some(instance);
        Ok(gpu)
    }

    /// Creates the device on a given adapter.
    pub async fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self> {
        let adapter_info = adapter.get_info();
        let required_limits = required_limits(&adapter_info.name, &adapter.limits())?;
        let required_features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("core.device"),
                required_features,
                required_limits: required_limits.clone(),
                memory_hints: wgpu::MemoryHints::Performance,
                ..Default::default()
            })
            .await?;
        let errors = Arc::new(Mutex::new(Vec::new()));
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let message = e.to_string();
            log_error(&message);
            if let Ok(mut v) = sink.lock() {
                v.push(message);
            }
        }));
        let lost = Arc::new(Mutex::new(None));
        let lost_sink = lost.clone();
        device.set_device_lost_callback(move |reason, message| {
            let text = format!("{reason:?}: {message}");
            log_error(&format!("device lost: {text}"));
            if let Ok(mut l) = lost_sink.lock() {
                *l = Some(text);
            }
        });
        let kernels = Kernels::new(&device);
        Ok(Self {
            device,
            queue,
            adapter_info,
            limits: required_limits,
            kernels,
            has_timestamps: required_features.contains(wgpu::Features::TIMESTAMP_QUERY),
            counters: GpuCounters::default(),
            errors,
            lost,
            staging: Mutex::new(Vec::new()),
            instance: None,
        })
    }

    /// [`Error::DeviceLost`] once the device is gone (a driver reset, the browser's GPU
    /// process crashing, `destroy`): everything on it must be rebuilt on a new [`Gpu`].
    pub fn check_lost(&self) -> Result<()> {
        match self.lost.lock().ok().and_then(|l| l.clone()) {
            Some(reason) => Err(Error::DeviceLost { reason }),
            None => Ok(()),
        }
    }

    /// Submits command buffers (counted in [`Gpu::counters`]).
    pub fn submit(&self, buffers: impl IntoIterator<Item = wgpu::CommandBuffer>) -> wgpu::SubmissionIndex {
        self.counters.count_submit();
        self.queue.submit(buffers)
    }

    /// Validation and out-of-memory errors wgpu reported since the last call. Tests fail on
    /// any, even when the outputs look right.
    pub fn take_errors(&self) -> Vec<String> {
        self.errors.lock().map(|mut v| std::mem::take(&mut *v)).unwrap_or_default()
    }

    /// One line describing the adapter, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)`.
    pub fn adapter_summary(&self) -> String {
        format!("{} ({:?}, {:?})", self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type)
    }

    /// A storage buffer of `len` elements of `T`, usable as kernel input or output and as a
    /// copy source/destination.
    pub fn storage_buffer<T: bytemuck::Pod>(&self, label: &str, len: usize) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (len.max(1) * std::mem::size_of::<T>()).next_multiple_of(4) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A uniform buffer holding `value`.
    pub fn uniform_buffer<T: bytemuck::Pod>(&self, label: &str, value: &T) -> wgpu::Buffer {
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: std::mem::size_of::<T>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.queue.write_buffer(&buffer, 0, bytemuck::bytes_of(value));
        buffer
    }

    /// Uploads `data` to the start of `buffer`; odd byte lengths are zero-padded to 4 bytes.
    pub fn write_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.len().is_multiple_of(4) {
            self.queue.write_buffer(buffer, 0, bytes);
        } else {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().next_multiple_of(4), 0);
            self.queue.write_buffer(buffer, 0, &padded);
        }
    }

    /// Fills `buffer` with copies of `value` (tests use a sentinel so "not written" cannot pass).
    pub fn fill_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, value: T) {
        let n = buffer.size() as usize / std::mem::size_of::<T>();
        self.queue.write_buffer(buffer, 0, bytemuck::cast_slice(&vec![value; n]));
    }

    /// Submits the encoder and waits until the GPU has finished it.
    pub async fn submit_and_wait(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        let index = self.submit(Some(encoder.finish()));
        self.wait(Some(index)).await
    }

    /// Waits for the queue (natively blocking with a timeout; in the browser by yielding to
    /// the event loop).
    pub async fn wait(&self, index: Option<wgpu::SubmissionIndex>) -> Result<()> {
        self.counters.count_wait();
        #[cfg(not(target_arch = "wasm32"))]
        {
            self.device
                .poll(wgpu::PollType::Wait { submission_index: index, timeout: Some(std::time::Duration::from_secs(POLL_TIMEOUT_S)) })
                .map_err(|e| Error::Poll(e.to_string()))?;
        }
        #[cfg(target_arch = "wasm32")]
        {
            let _ = index;
            let (sender, receiver) = oneshot();
            self.queue.on_submitted_work_done(move || sender.send(()));
            receiver.await;
        }
        self.check_lost()
    }

    /// Copies the first `len` elements of `buffer` back to the CPU.
    pub async fn read_buffer<T: bytemuck::Pod>(&self, buffer: &wgpu::Buffer, len: usize) -> Result<Vec<T>> {
        self.read_buffers(&[(buffer, len)]).await
    }

    /// Copies the first `len` elements of each buffer back to the CPU in one submission and
    /// one mapping, concatenated in order (ICP reads its two partial-sum buffers this way).
    pub async fn read_buffers<T: bytemuck::Pod>(&self, parts: &[(&wgpu::Buffer, usize)]) -> Result<Vec<T>> {
        let sizes: Vec<u64> = parts.iter().map(|&(_, len)| ((len * std::mem::size_of::<T>()) as u64).next_multiple_of(4)).collect();
        let total: u64 = sizes.iter().sum();
        let label = "core.readback".to_owned();
        let staging = self.take_staging(total.max(4));
        self.counters.count_readback(total);
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(&label) });
        let mut offset = 0;
        for (&(buffer, _), &size) in parts.iter().zip(&sizes) {
            encoder.copy_buffer_to_buffer(buffer, 0, &staging, offset, size);
            offset += size;
        }
        let index = self.submit(Some(encoder.finish()));
        let (sender, receiver) = oneshot();
        staging.map_async(wgpu::MapMode::Read, .., move |r| sender.send(r));
        self.wait(Some(index)).await?;
        receiver.await.map_err(|e| Error::BufferMap { label: label.clone(), message: e.to_string() })?;
        let view = staging.get_mapped_range(..).map_err(|e| Error::BufferMap { label: label.clone(), message: e.to_string() })?;
        let mut out = Vec::with_capacity(parts.iter().map(|p| p.1).sum());
        let mut offset = 0usize;
        for (&(_, len), &size) in parts.iter().zip(&sizes) {
            out.extend(bytemuck::pod_collect_to_vec::<u8, T>(&view[offset..offset + len * std::mem::size_of::<T>()]));
            offset += size as usize;
        }
        drop(view);
        staging.unmap();
        self.return_staging(staging);
        Ok(out)
    }

    /// A mappable staging buffer of at least `size` bytes, reused when one is free.
    fn take_staging(&self, size: u64) -> wgpu::Buffer {
        if let Ok(mut pool) = self.staging.lock()
            && let Some(i) = pool.iter().position(|b| b.size() >= size && b.size() <= size.saturating_mul(4).max(4096))
        {
            return pool.swap_remove(i);
        }
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("core.readback.staging"),
            size: size.next_multiple_of(256),
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Keeps a staging buffer for reuse (a few, so a burst of readbacks cannot pile up memory).
    fn return_staging(&self, buffer: wgpu::Buffer) {
        if let Ok(mut pool) = self.staging.lock()
            && pool.len() < 8
        {
            pool.push(buffer);
        }
    }
}

fn log_error(message: &str) {
    #[cfg(not(target_arch = "wasm32"))]
    eprintln!("wgpu error: {message}");
    #[cfg(target_arch = "wasm32")]
    let _ = message;
}

/// Picks an adapter by the options: name filter, then device type preference.
async fn select_adapter(instance: &wgpu::Instance, backends: wgpu::Backends, options: &GpuOptions) -> Result<wgpu::Adapter> {
    let wanted = options.adapter_name_contains.clone().or_else(|| {
        if cfg!(target_arch = "wasm32") { None } else { std::env::var("WEBFUSION_ADAPTER").ok().filter(|s| !s.is_empty()) }
    });
    let no_adapter = || Error::NoAdapter { backends: format!("{backends:?}"), wanted: wanted.clone() };
    #[cfg(target_arch = "wasm32")]
    {
        let _ = options;
        instance
            .request_adapter(&wgpu::RequestAdapterOptions { power_preference: wgpu::PowerPreference::HighPerformance, ..Default::default() })
            .await
            .map_err(|_| no_adapter())
    }
    #[cfg(not(target_arch = "wasm32"))]
    {
        let adapters = instance.enumerate_adapters(backends).await;
        let rank = |t: wgpu::DeviceType| -> u8 {
            use wgpu::DeviceType as D;
            match (options.prefer_cpu_adapter, t) {
                (true, D::Cpu) => 0,
                (false, D::DiscreteGpu) => 0,
                (_, D::IntegratedGpu) => 1,
                (_, D::VirtualGpu) => 2,
                (false, D::Cpu) => 3,
                _ => 4,
            }
        };
        adapters
            .into_iter()
            .filter(|a| wanted.as_ref().is_none_or(|w| a.get_info().name.to_lowercase().contains(&w.to_lowercase())))
            .min_by_key(|a| rank(a.get_info().device_type))
            .ok_or_else(no_adapter)
    }
}

/// WebGPU's default limits raised to what the kernels need, or an error naming the first limit
/// the adapter lacks.
fn required_limits(adapter: &str, available: &wgpu::Limits) -> Result<wgpu::Limits> {
    let mut limits = wgpu::Limits::default();
    let need_storage_buffers = webfusion_shaders::ALL
        .iter()
        .map(|k| k.bindings.iter().filter(|b| b.kind != webfusion_shaders::BindingKind::Uniform).count() as u32)
        .max()
        .unwrap_or(0);
    let need_invocations = webfusion_shaders::ALL.iter().map(|k| k.workgroup_size.iter().product::<u32>()).max().unwrap_or(1);
    let check = |name: &'static str, required: u64, got: u64| -> Result<()> {
        if got < required { Err(Error::MissingLimit { adapter: adapter.to_owned(), name, required, available: got }) } else { Ok(()) }
    };
    check("max_storage_buffers_per_shader_stage", need_storage_buffers.into(), available.max_storage_buffers_per_shader_stage.into())?;
    check("max_compute_invocations_per_workgroup", need_invocations.into(), available.max_compute_invocations_per_workgroup.into())?;
    check("max_storage_buffer_binding_size", REQUIRED_STORAGE_BINDING_BYTES, available.max_storage_buffer_binding_size)?;
    check("max_compute_workgroup_storage_size", 16 * 1024, available.max_compute_workgroup_storage_size.into())?;
    limits.max_storage_buffers_per_shader_stage = limits.max_storage_buffers_per_shader_stage.max(need_storage_buffers);
    // As large a binding as the adapter offers, up to the largest one the kernels index safely
    // (maps larger than WebGPU's default 128 MiB binding where the hardware allows them).
    let binding = available.max_storage_buffer_binding_size.min(available.max_buffer_size).min(LARGEST_STORAGE_BINDING_BYTES);
    limits.max_storage_buffer_binding_size = limits.max_storage_buffer_binding_size.max(REQUIRED_STORAGE_BINDING_BYTES).max(binding);
    limits.max_buffer_size = limits.max_buffer_size.max(limits.max_storage_buffer_binding_size).min(available.max_buffer_size);
    limits.max_compute_workgroup_storage_size = PREFERRED_WORKGROUP_STORAGE_BYTES.min(available.max_compute_workgroup_storage_size);
    Ok(limits)
}

/// A single-use channel whose receiver is a future; works without threads (browser) and with
/// them (native map callbacks).
pub(crate) fn oneshot<T: Send + 'static>() -> (OneshotSender<T>, OneshotReceiver<T>) {
    let shared = Arc::new(Mutex::new(OneshotState { value: None, waker: None }));
    (OneshotSender(shared.clone()), OneshotReceiver(shared))
}

struct OneshotState<T> {
    value: Option<T>,
    waker: Option<std::task::Waker>,
}

pub(crate) struct OneshotSender<T>(Arc<Mutex<OneshotState<T>>>);
pub(crate) struct OneshotReceiver<T>(Arc<Mutex<OneshotState<T>>>);

impl<T> OneshotReceiver<T> {
    /// The value, if it has been sent (without waiting).
    pub(crate) fn try_take(&self) -> Option<T> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner).value.take()
    }
}

impl<T> std::fmt::Debug for OneshotReceiver<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("OneshotReceiver")
    }
}

impl<T> OneshotSender<T> {
    pub(crate) fn send(self, value: T) {
        let waker = match self.0.lock() {
            Ok(mut s) => {
                s.value = Some(value);
                s.waker.take()
            }
            Err(_) => None,
        };
        if let Some(w) = waker {
            w.wake();
        }
    }
}

impl<T> std::future::Future for OneshotReceiver<T> {
    type Output = T;
    fn poll(self: std::pin::Pin<&mut Self>, cx: &mut std::task::Context<'_>) -> std::task::Poll<T> {
        let mut s = self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        match s.value.take() {
            Some(v) => std::task::Poll::Ready(v),
            None => {
                s.waker = Some(cx.waker().clone());
                std::task::Poll::Pending
            }
        }
    }
}
