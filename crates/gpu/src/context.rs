//! [`GpuContext`]: the adapter, device and queue every kernel shares, and
//! the error handling around them (no adapter, lost device, validation).

use edtmap_core::{BackendError, DeviceCounters};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
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
    /// Timestamps around every compute pass, where the adapter has them.
    timer: Option<Arc<Timer>>,
    /// The stage the passes recorded now belong to ([`Stage`]).
    stage: Arc<AtomicUsize>,
}

/// The pipeline stages device time is reported for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Stage {
    /// Ray casting or projection.
    Occupancy = 0,
    /// The batch EDT of the window.
    BatchEdt = 1,
    /// The global integration (its batch EDT included).
    Integrate = 2,
}

/// Most compute passes timed between two reads of the counters; passes
/// past it go untimed.
const TIMED_PASSES: u32 = 256;

/// A timestamp query set around compute passes and what it has measured.
#[derive(Debug)]
struct Timer {
    set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    staging: wgpu::Buffer,
    /// Nanoseconds per timestamp tick.
    period_ns: f64,
    state: Mutex<TimerState>,
}

#[derive(Debug, Default)]
struct TimerState {
    /// The stage of each pass timed since the last collection.
    passes: Vec<Stage>,
    /// Device nanoseconds per stage, collected so far.
    totals: [u64; 3],
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
                    power_preference: wgpu::PowerPreference::from_env()
                        .unwrap_or(wgpu::PowerPreference::HighPerformance),
                    ..Default::default()
                };
                pollster::block_on(instance.request_adapter(&options))
                    .map_err(|e| BackendError::NoAdapter(e.to_string()))?
            }
        };
        let info = adapter.get_info();
        let limits = adapter.limits();
        let features = adapter.features() & wgpu::Features::TIMESTAMP_QUERY;
        let desc = wgpu::DeviceDescriptor {
            label: Some("edtmap"),
            required_features: features,
            required_limits: limits.clone(),
            ..Default::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&desc)).map_err(|e| {
            BackendError::NoAdapter(format!("{} ({:?}) refused a device: {e}", info.name, info.backend))
        })?;
        let lost = Arc::new(Mutex::new(None));
        let flag = Arc::clone(&lost);
        device.set_device_lost_callback(move |reason, message| {
            if let Ok(mut slot) = flag.lock() {
                *slot = Some(format!("{reason:?}: {message}"));
            }
        });
        // Errors outside an error scope would otherwise abort the process.
        device.on_uncaptured_error(Arc::new(|_| {}));
        let timer = features.contains(wgpu::Features::TIMESTAMP_QUERY).then(|| {
            let bytes = 16 * u64::from(TIMED_PASSES);
            let buffer = |label, usage| {
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: bytes,
                    usage,
                    mapped_at_creation: false,
                })
            };
            Arc::new(Timer {
                set: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("edtmap passes"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * TIMED_PASSES,
                }),
                resolve: buffer("timestamps", wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC),
                staging: buffer("timestamps staging", wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST),
                period_ns: f64::from(queue.get_timestamp_period()),
                state: Mutex::new(TimerState::default()),
            })
        });
        let queue = CountingQueue { queue, counters: Arc::new(Counters::default()) };
        Ok(GpuContext {
            device,
            queue,
            info,
            limits,
            lost,
            timer,
            stage: Arc::new(AtomicUsize::new(Stage::BatchEdt as usize)),
        })
    }

    /// Whether compute passes are timed on the device (the adapter has
    /// timestamp queries).
    pub fn has_timestamps(&self) -> bool {
        self.timer.is_some()
    }

    /// Attributes the passes recorded from now on to `stage`.
    pub(crate) fn set_stage(&self, stage: Stage) {
        self.stage.store(stage as usize, Ordering::Relaxed);
    }

    /// Begins a compute pass on `enc`, timed on the device where the
    /// adapter allows.
    pub(crate) fn pass<'e>(&self, enc: &'e mut wgpu::CommandEncoder, label: &str) -> wgpu::ComputePass<'e> {
        let stage = match self.stage.load(Ordering::Relaxed) {
            0 => Stage::Occupancy,
            1 => Stage::BatchEdt,
            _ => Stage::Integrate,
        };
        let slot = self.timer.as_ref().and_then(|t| {
            let mut state = t.state.lock().ok()?;
            let k = state.passes.len() as u32;
            (k < TIMED_PASSES).then(|| {
                state.passes.push(stage);
                (t, k)
            })
        });
        let timestamp_writes = slot.map(|(t, k)| wgpu::ComputePassTimestampWrites {
            query_set: &t.set,
            beginning_of_pass_write_index: Some(2 * k),
            end_of_pass_write_index: Some(2 * k + 1),
        });
        enc.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes })
    }

    /// Reads the timestamps of the passes timed since the last call into
    /// the totals (its own submission and read-back are not counted as
    /// the pipeline's traffic). Every pass timed must have been submitted.
    fn collect_times(&self) -> Result<[u64; 3], BackendError> {
        let Some(t) = &self.timer else { return Ok([0; 3]) };
        let mut state = t.state.lock().map_err(|_| BackendError::Device("timer lock poisoned".into()))?;
        let n = state.passes.len() as u64;
        if n > 0 {
            let mut enc =
                self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("timestamps") });
            enc.resolve_query_set(&t.set, 0..2 * n as u32, &t.resolve, 0);
            enc.copy_buffer_to_buffer(&t.resolve, 0, &t.staging, 0, 16 * n);
            self.queue.queue.submit([enc.finish()]);
            let mut ticks = vec![0u64; 2 * n as usize];
            self.map_read(
                &t.staging,
                16 * n,
                |bytes| {
                    for (tick, b) in ticks.iter_mut().zip(bytes.chunks_exact(8)) {
                        *tick = u64::from_ne_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]);
                    }
                },
                None,
            )?;
            let passes = std::mem::take(&mut state.passes);
            for (stage, pair) in passes.into_iter().zip(ticks.chunks_exact(2)) {
                let ns = (pair[1].saturating_sub(pair[0]) as f64 * t.period_ns).round() as u64;
                state.totals[stage as usize] += ns;
            }
        }
        Ok(state.totals)
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
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    }

    /// A bind group of `layout` with `resources[k]` at binding `k`.
    pub(crate) fn bind_group(
        &self,
        label: &str,
        layout: &wgpu::BindGroupLayout,
        resources: &[wgpu::BindingResource<'_>],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
            .iter()
            .enumerate()
            .map(|(k, r)| wgpu::BindGroupEntry { binding: k as u32, resource: r.clone() })
            .collect();
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
        // A device that fails here fails the next job too; the times are
        // then missing, not wrong.
        let [occupancy_ns, batch_edt_ns, integrate_ns] = self.collect_times().unwrap_or([0; 3]);
        DeviceCounters { memory_bytes, occupancy_ns, batch_edt_ns, integrate_ns, ..self.queue.counters.snapshot() }
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
        self.map_read(staging, bytes, read, Some(&self.queue.counters.waited_ns))
    }

    /// Maps the first `bytes` of `staging` once the device is done and
    /// gives them to `read`, uncounted; the time spent waiting for the
    /// device is added to `waited` where given.
    fn map_read(
        &self,
        staging: &wgpu::Buffer,
        bytes: u64,
        read: impl FnOnce(&[u8]),
        waited: Option<&AtomicU64>,
    ) -> Result<(), BackendError> {
        let slice = staging.slice(..bytes);
        let status = Arc::new(Mutex::new(None));
        let done = Arc::clone(&status);
        slice.map_async(wgpu::MapMode::Read, move |r| {
            if let Ok(mut slot) = done.lock() {
                *slot = Some(r);
            }
        });
        let start = std::time::Instant::now();
        let done = self.wait();
        if let Some(w) = waited {
            w.fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        }
        done?;
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
    waited_ns: AtomicU64,
}

impl Counters {
    fn snapshot(&self) -> DeviceCounters {
        DeviceCounters {
            uploaded_bytes: self.uploaded.load(Ordering::Relaxed),
            downloaded_bytes: self.downloaded.load(Ordering::Relaxed),
            dispatches: self.dispatches.load(Ordering::Relaxed),
            submissions: self.submissions.load(Ordering::Relaxed),
            wait_ns: self.waited_ns.load(Ordering::Relaxed),
            ..DeviceCounters::default()
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

    /// `wgpu::Queue::submit`, counted. Its time counts as waiting for the
    /// device: a software device (lavapipe) may run the work inside it.
    pub(crate) fn submit<I: IntoIterator<Item = wgpu::CommandBuffer>>(&self, buffers: I) -> wgpu::SubmissionIndex {
        self.counters.submissions.fetch_add(1, Ordering::Relaxed);
        let start = std::time::Instant::now();
        let index = self.queue.submit(buffers);
        self.counters.waited_ns.fetch_add(start.elapsed().as_nanos() as u64, Ordering::Relaxed);
        index
    }
}
