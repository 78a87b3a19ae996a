//! [`GpuContext`]: the adapter, device and queue every kernel shares, and
//! the error handling around them (no adapter, lost device, validation).

use edtmap_core::{BackendError, DeviceCounters};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// The longest a single submission may run before the device is declared
/// hung; a real frame takes milliseconds.
const SUBMIT_TIMEOUT: Duration = Duration::from_secs(120);

/// A GPU device opened for edtmap's compute kernels.
#[derive(Debug, Clone)]
pub struct GpuContext {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: CountingQueue,
    info: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    /// Set by the device-lost callback: why the device went away.
    lost: Arc<Mutex<Option<String>>>,
}

impl GpuContext {
    /// Opens the highest-performance adapter wgpu finds (a discrete GPU
    /// before an integrated one, before a software one such as lavapipe),
    /// with the adapter's real limits, so large volumes fit. The
    /// `WGPU_BACKEND` and `WGPU_ADAPTER_NAME` environment variables narrow
    /// the choice.
    pub fn new() -> Result<Self, BackendError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = match pollster::block_on(wgpu::util::initialize_adapter_from_env(&instance, None)) {
            Ok(adapter) => adapter,
            Err(_) => {
                let options = wgpu::RequestAdapterOptions {
                    power_preference: wgpu::PowerPreference::from_env().unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                };
                pollster::block_on(instance.request_adapter(&options)).map_err(|e| BackendError::NoAdapter(e.to_string()))?
            }
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        let desc = wgpu::DeviceDescriptor {
            label: Some("edtmap"),
            required_limits: limits.clone(),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&desc))
            .map_err(|e| BackendError::NoAdapter(format!("{} ({:?}) refused a device: {e}", info.name, info.backend)))?;
        let lost = Arc::new(Mutex::new(None));
        let flag = Arc::clone(&lost);
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut slot) = flag.lock() {
                *slot = Some(format!("{reason:?}: {message}"));
            }
        });
        // Errors outside an error scope would otherwise abort the process.
        device.on_uncaptured_error(Arc::new(|_| {}));
        let queue = CountingQueue { queue, counters: Arc::new(Counters::default()) };
        Ok(GpuContext { device, queue, info, limits, lost })
    }

    /// The adapter's name and API, e.g. `NVIDIA H100 (Vulkan)`.
    pub fn name(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    /// Whether the adapter is a software rasteriser (lavapipe, WARP).
    pub fn is_software(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }

    /// The device's limits (the adapter's own, requested in full).
    pub fn limits(&self) -> &wgpu::Limits {
        &self.limits
    }

    /// An error if the device has been lost.
    pub(crate) fn check_lost(&self) -> Result<(), BackendError> {
        match self.lost.lock().ok().and_then(|slot| slot.clone()) {
            Some(why) => Err(BackendError::DeviceLost(why)),
            None => Ok(()),
        }
    }

    /// A buffer of `size` bytes (zeroed by wgpu) for `usage`.
    pub(crate) fn buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor { label: Some(label), size, usage, mapped_at_creation: false })
    }

    /// A bind group of `layout` with `resources[k]` at binding `k`.
    pub(crate) fn bind_group(&self, label: &str, layout: &wgpu::BindGroupLayout, resources: &[wgpu::BindingResource<'_>]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry<'_>> =
            resources.iter().enumerate().map(|(k, r)| wgpu::BindGroupEntry { binding: k as u32, resource: r.clone() }).collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
    }

    /// Refuses a storage buffer of `bytes` over the device's limits.
    pub(crate) fn check_buffer(&self, what: &'static str, bytes: u64) -> Result<(), BackendError> {
        let limit = self.limits.max_buffer_size.min(self.limits.max_storage_buffer_binding_size);
        if bytes > limit {
            return Err(BackendError::OverLimit { what, needed: bytes, limit });
        }
        Ok(())
    }

    /// Runs `f` (resource creation, encoding, submission) inside error
    /// scopes, turning validation and out-of-memory errors into
    /// [`BackendError::Device`].
    pub(crate) fn scoped<T>(&self, f: impl FnOnce() -> T) -> Result<T, BackendError> {
        self.check_lost()?;
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let errors = [pollster::block_on(validation.pop()), pollster::block_on(oom.pop())];
        if let Some(e) = errors.into_iter().flatten().next() {
            self.check_lost()?;
            return Err(BackendError::Device(e.to_string()));
        }
        Ok(out)
    }

    /// Waits for everything submitted so far; a device that does not
    /// finish in time, or is lost meanwhile, is an error.
    pub(crate) fn wait(&self) -> Result<(), BackendError> {
        let poll = self.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: Some(SUBMIT_TIMEOUT) });
        self.check_lost()?;
        poll.map(|_| ()).map_err(|e| BackendError::DeviceLost(format!("waiting for the GPU: {e}")))
    }

    /// The running totals of uploads, read-backs, dispatches and
    /// submissions, and the device memory held now (the allocator's
    /// report, where the backend has one).
    pub fn counters(&self) -> DeviceCounters {
        let memory_bytes = self.device.generate_allocator_report().map_or(0, |r| r.total_allocated_bytes);
        DeviceCounters { memory_bytes, ..self.queue.counters.snapshot() }
    }

    /// The counters, for kernels to count their dispatches.
    pub(crate) fn counter_handle(&self) -> Arc<Counters> {
        Arc::clone(&self.queue.counters)
    }

    /// Copies `bytes` bytes of `staging` (a `MAP_READ` buffer the caller
    /// already filled in a submitted command) into `out` through `read`.
    pub(crate) fn read_back(
        &self,
        staging: &wgpu::Buffer,
        bytes: u64,
        read: impl FnOnce(&[u8]),
    ) -> Result<(), BackendError> {
        self.queue.counters.downloaded.fetch_add(bytes, Ordering::Relaxed);
        let slice = staging.slice(..bytes);
        let status = Arc::new(Mutex::new(None));
        let done = Arc::clone(&status);
        slice.map_async(wgpu::MapMode::Read, move |r| {
            if let Ok(mut slot) = done.lock() {
                *slot = Some(r);
            }
        });
        self.wait()?;
        let mapped = status.lock().ok().and_then(|mut s| s.take());
        match mapped {
            Some(Ok(())) => {}
            Some(Err(e)) => return Err(BackendError::Device(format!("reading results back: {e}"))),
            None => return Err(BackendError::DeviceLost("results never became readable".into())),
        }
        {
            let view = slice.get_mapped_range().map_err(|e| BackendError::Device(format!("mapping results: {e}")))?;
            read(&view);
        }
        staging.unmap();
        Ok(())
    }
}

/// Atomic running totals behind [`DeviceCounters`].
#[derive(Debug, Default)]
pub(crate) struct Counters {
    uploaded: AtomicU64,
    downloaded: AtomicU64,
    pub(crate) dispatches: AtomicU64,
    submissions: AtomicU64,
}

impl Counters {
    fn snapshot(&self) -> DeviceCounters {
        DeviceCounters {
            uploaded_bytes: self.uploaded.load(Ordering::Relaxed),
            downloaded_bytes: self.downloaded.load(Ordering::Relaxed),
            dispatches: self.dispatches.load(Ordering::Relaxed),
            submissions: self.submissions.load(Ordering::Relaxed),
            memory_bytes: 0,
        }
    }
}

/// The device's queue, counting what goes through it: every upload and
/// submission of the kernels passes here.
#[derive(Debug, Clone)]
pub(crate) struct CountingQueue {
    queue: wgpu::Queue,
    counters: Arc<Counters>,
}

impl CountingQueue {
    /// `wgpu::Queue::write_buffer`, counted.
    pub(crate) fn write_buffer(&self, buffer: &wgpu::Buffer, offset: u64, data: &[u8]) {
        self.counters.uploaded.fetch_add(data.len() as u64, Ordering::Relaxed);
        self.queue.write_buffer(buffer, offset, data);
    }

    /// `wgpu::Queue::submit`, counted.
    pub(crate) fn submit<I: IntoIterator<Item = wgpu::CommandBuffer>>(&self, buffers: I) -> wgpu::SubmissionIndex {
        self.counters.submissions.fetch_add(1, Ordering::Relaxed);
        self.queue.submit(buffers)
    }
}
