//! Devices, errors and the engine handle.

use super::buffers::BufferPool;
use super::{
    deform::DeformKernel, project::ProjectKernel, silhouette::SilhouetteKernel,
    srvf_band::SrvfBandKernel, srvf_dp::SrvfDpKernel,
};
use std::sync::{Condvar, Mutex};
use std::thread::ThreadId;

/// One lock for everything done on an OpenGL device, in every engine of the process and by a
/// host that takes its own turns (`GlTurn`). wgpu's GL backend shares one context per adapter
/// behind a lock it waits for at most 6 s and then panics ("Could not lock adapter context"); a
/// reading-back wait holds that lock while a long dispatch runs (seconds on Mesa's software GL),
/// so two threads working the same device at once could abort the process. On GL the engine's
/// kernels therefore take turns here, where waiting is unbounded. Vulkan, Metal and DX12 are not
/// serialised. The state names the thread holding the turn and how many turns it holds (a
/// thread may take it again inside its own: a host's turn, then an engine's call in it); the
/// condition variable wakes the threads waiting for it.
static GL_TURNS: (Mutex<Option<(ThreadId, usize)>>, Condvar) = (Mutex::new(None), Condvar::new());

/// One turn on an OpenGL device (`GL_TURNS`), given back when dropped. A token rather than a
/// lock guard, so that an engine being dropped can keep it until its last field is gone.
pub(crate) struct Turn(());

impl Turn {
    /// Wait until no other thread holds the turn, then take it (again, where this thread holds
    /// it already). A thread that panicked while it held the lock left nothing half-done on the
    /// host side, so a poisoned lock is taken as it is.
    fn take() -> Turn {
        let me = std::thread::current().id();
        let (held, freed) = &GL_TURNS;
        let mut held = held.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            match *held {
                None => {
                    *held = Some((me, 1));
                    break;
                }
                Some((owner, ref mut n)) if owner == me => {
                    *n += 1;
                    break;
                }
                Some(_) => held = freed.wait(held).unwrap_or_else(|e| e.into_inner()),
            }
        }
        Turn(())
    }
}

impl Drop for Turn {
    fn drop(&mut self) {
        let (held, freed) = &GL_TURNS;
        let mut held = held.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, n)) = held.as_mut() {
            *n -= 1;
            if *n == 0 {
                *held = None;
                freed.notify_all();
            }
        }
    }
}

/// Whether work on `device` takes turns (`GL_TURNS`): an OpenGL device does.
fn takes_turns(device: &wgpu::Device) -> bool {
    device.adapter_info().backend == wgpu::Backend::Gl
}

/// A host's turn on an OpenGL device that it shares with acetab's engines. A planning tool that
/// works on the same GL device from threads of its own (its uploads, submissions, polls and
/// read-backs) while acetab computes on it holds one around that work, so that neither waits on
/// wgpu's context lock past the GL backend's 6 s limit (which panics): while it is held, acetab's
/// kernel calls on other threads wait, and the host's `take` waits for theirs. Acetab's own calls
/// made on the thread that holds it go straight in (a thread's turns nest). Not `Send`: it is
/// given back on the thread that took it.
pub struct GlTurn {
    _turn: Turn,
    _here: std::marker::PhantomData<*const ()>,
}

impl GlTurn {
    /// Wait for the turn on `device` and take it: `None` where the device is not OpenGL
    /// (Vulkan, Metal and DX12 need no turns), so the host may call this whatever its backend.
    pub fn take(device: &wgpu::Device) -> Option<GlTurn> {
        takes_turns(device).then(|| GlTurn {
            _turn: Turn::take(),
            _here: std::marker::PhantomData,
        })
    }
}

/// Everything that can go wrong on the GPU side.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter matched (none installed, or WGPU_ADAPTER_NAME / WGPU_BACKEND exclude all).
    #[error("no GPU adapter found ({0}); install a Vulkan driver (e.g. mesa-vulkan-drivers for lavapipe) or check WGPU_BACKEND / WGPU_ADAPTER_NAME")]
    NoAdapter(String),
    /// The adapter refused to make a device.
    #[error("the adapter refused a device: {0}")]
    RequestDevice(String),
    /// A wgpu validation or out-of-memory error raised while running `kernel`.
    #[error("{kernel}: wgpu error: {message}")]
    Wgpu {
        /// The kernel that was running.
        kernel: &'static str,
        /// wgpu's message.
        message: String,
    },
    /// Mapping a result buffer back to the host failed.
    #[error("{kernel}: reading results back failed: {message}")]
    Readback {
        /// The kernel.
        kernel: &'static str,
        /// wgpu's message.
        message: String,
    },
    /// A batch larger than the device allows.
    #[error("{kernel}: {what} is {value}, the device allows at most {limit}")]
    TooLarge {
        /// The kernel.
        kernel: &'static str,
        /// What is too large.
        what: &'static str,
        /// Its size.
        value: u64,
        /// The device's limit.
        limit: u64,
    },
    /// A deformation batch the kernel cannot take.
    #[error("deform: {0}")]
    DeformBatch(#[from] crate::engine::cpu::deform::DeformBatchError),
    /// An SRVF DP batch the kernel cannot take.
    #[error("srvf_dp: {0}")]
    DpBatch(#[from] crate::engine::cpu::srvf_dp::DpBatchError),
    /// A banded DP batch that cannot be built.
    #[error("srvf_band: {0}")]
    BandBatch(#[from] crate::engine::cpu::srvf_band::BandBatchError),
    /// An input the kernel cannot take (no vertex in front of the source, triangles that do not
    /// index the vertices).
    #[error("{kernel}: {message}")]
    Input {
        /// The kernel.
        kernel: &'static str,
        /// What is wrong with the input.
        message: String,
    },
}

/// A device made by acetab itself, from the environment: `WGPU_BACKEND` (e.g. `vulkan`),
/// `WGPU_ADAPTER_NAME` (a substring of the adapter's name, e.g. `llvmpipe`), and
/// `WGPU_POWER_PREF`. Without them, the first adapter wgpu offers.
pub struct GpuDevice {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter it came from.
    pub adapter: wgpu::AdapterInfo,
}

impl GpuDevice {
    /// A device from the environment (WGPU_BACKEND, WGPU_ADAPTER_NAME; a CPU adapter such as lavapipe is taken when nothing else is asked for).
    pub fn from_env() -> Result<Self, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle().with_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(
            &instance, None,
        ))
        .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("acetab"),
            required_features: wgpu::Features::empty(),
            required_limits: adapter.limits(),
            ..Default::default()
        }))
        .map_err(|e| GpuError::RequestDevice(e.to_string()))?;
        Ok(GpuDevice {
            device,
            queue,
            adapter: info,
        })
    }

    /// One line naming the adapter, for logs.
    pub fn describe(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.adapter.name, self.adapter.device_type, self.adapter.backend
        )
    }

    /// Whether the adapter is a CPU (a software rasteriser such as lavapipe or llvmpipe).
    pub fn is_software(&self) -> bool {
        self.adapter.device_type == wgpu::DeviceType::Cpu
    }

    /// The adapter for reports: name, driver and its version, device type, graphics API.
    pub fn adapter_json(&self) -> serde_json::Value {
        let a = &self.adapter;
        serde_json::json!({
            "name": a.name,
            "driver": a.driver,
            "driver_info": a.driver_info,
            "device_type": format!("{:?}", a.device_type),
            "api": format!("{:?}", a.backend),
        })
    }

    /// The engine on this device.
    pub fn engine(&self) -> Result<Gpu<'_>, GpuError> {
        Gpu::new(&self.device, &self.queue)
    }
}

/// The engine: borrowed device and queue, every kernel's pipeline compiled once, a buffer pool
/// and one staging buffer for read-back. `Sync`: study threads may share it (submissions are
/// serialised by wgpu's queue).
pub struct Gpu<'a> {
    pub(crate) device: &'a wgpu::Device,
    pub(crate) queue: &'a wgpu::Queue,
    pub(crate) deform: DeformKernel,
    pub(crate) project: ProjectKernel,
    pub(crate) silhouette: SilhouetteKernel,
    pub(crate) srvf_band: SrvfBandKernel,
    pub(crate) srvf_dp: SrvfDpKernel,
    pub(crate) surface: super::surface::SurfaceKernel,
    pub(crate) pool: BufferPool,
    pub(crate) staging: Mutex<Option<wgpu::Buffer>>,
    /// Whether the device is OpenGL, whose kernels take turns (`GL_TURNS`).
    takes_turns: bool,
    /// The turn an engine being dropped holds while its fields go; declared last, so that it is
    /// dropped after the pipelines and buffers above.
    dropping: Option<Turn>,
}

impl<'a> Gpu<'a> {
    /// Compile every kernel on the caller's device. Validation errors come back as `Err`.
    pub fn new(device: &'a wgpu::Device, queue: &'a wgpu::Queue) -> Result<Self, GpuError> {
        let takes_turns = takes_turns(device);
        let _turn = takes_turns.then(Turn::take);
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let deform = DeformKernel::new(device);
        let project = ProjectKernel::new(device);
        let silhouette = SilhouetteKernel::new(device);
        let srvf_band = SrvfBandKernel::new(device);
        let srvf_dp = SrvfDpKernel::new(device);
        let surface = super::surface::SurfaceKernel::new(device);
        if let Some(e) = pollster::block_on(scope.pop()) {
            return Err(GpuError::Wgpu {
                kernel: "pipelines",
                message: e.to_string(),
            });
        }
        Ok(Gpu {
            device,
            queue,
            deform,
            project,
            silhouette,
            srvf_band,
            srvf_dp,
            surface,
            pool: BufferPool::default(),
            staging: Mutex::new(None),
            takes_turns,
            dropping: None,
        })
    }

    /// This thread's turn on the device, held until dropped: on OpenGL, one kernel call at a
    /// time over every engine of the process (`GL_TURNS`); elsewhere none is needed. Each public
    /// kernel call takes it first, so everything it creates, writes, submits, waits for and drops
    /// happens inside its turn.
    pub(crate) fn turn(&self) -> Option<Turn> {
        self.takes_turns.then(Turn::take)
    }

    /// The borrowed device.
    pub fn device(&self) -> &wgpu::Device {
        self.device
    }

    /// The borrowed queue.
    pub fn queue(&self) -> &wgpu::Queue {
        self.queue
    }

    /// Check a buffer size against the device's binding limit.
    pub(crate) fn check_size(
        &self,
        kernel: &'static str,
        what: &'static str,
        bytes: u64,
    ) -> Result<(), GpuError> {
        let lim = self.device.limits();
        let limit = lim.max_storage_buffer_binding_size.min(lim.max_buffer_size);
        if bytes > limit {
            return Err(GpuError::TooLarge {
                kernel,
                what,
                value: bytes,
                limit,
            });
        }
        Ok(())
    }

    /// One compute dispatch of `pipeline` with bind group 0, then read back `read`.
    pub(crate) fn dispatch_and_read(
        &self,
        kernel: &'static str,
        pipeline: &wgpu::ComputePipeline,
        group: &wgpu::BindGroup,
        groups: (u32, u32, u32),
        read: &[(&wgpu::Buffer, u64)],
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        self.submit_and_read(
            kernel,
            |enc| {
                let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some(kernel),
                    timestamp_writes: None,
                });
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, group, &[]);
                pass.dispatch_workgroups(groups.0, groups.1, groups.2);
            },
            read,
        )
    }

    /// Run `record` under a validation + out-of-memory error scope, submit, and read back
    /// `(buffer, bytes)` through the shared staging buffer.
    pub(crate) fn submit_and_read(
        &self,
        kernel: &'static str,
        record: impl FnOnce(&mut wgpu::CommandEncoder),
        read: &[(&wgpu::Buffer, u64)],
    ) -> Result<Vec<Vec<u8>>, GpuError> {
        let validation = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let total: u64 = read
            .iter()
            .map(|(_, n)| n.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT))
            .sum();
        let mut staging = self.staging.lock().unwrap_or_else(|e| e.into_inner());
        if staging.as_ref().is_none_or(|s| s.size() < total.max(4)) {
            *staging = Some(self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("acetab staging"),
                size: total.max(4).next_power_of_two(),
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }));
        }
        let stage = staging.as_ref().expect("created above");
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some(kernel),
            });
        record(&mut enc);
        let mut offset = 0;
        for (buf, n) in read {
            let n = n.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
            enc.copy_buffer_to_buffer(buf, 0, stage, offset, n);
            offset += n;
        }
        self.queue.submit([enc.finish()]);
        let errors = [
            pollster::block_on(oom.pop()),
            pollster::block_on(validation.pop()),
        ];
        if let Some(e) = errors.into_iter().flatten().next() {
            return Err(GpuError::Wgpu {
                kernel,
                message: e.to_string(),
            });
        }
        let slice = stage.slice(..total.max(4));
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Readback {
                kernel,
                message: e.to_string(),
            })?;
        rx.recv()
            .map_err(|e| GpuError::Readback {
                kernel,
                message: e.to_string(),
            })?
            .map_err(|e| GpuError::Readback {
                kernel,
                message: e.to_string(),
            })?;
        let out = {
            let view = slice.get_mapped_range().map_err(|e| GpuError::Readback {
                kernel,
                message: e.to_string(),
            })?;
            let mut out = Vec::with_capacity(read.len());
            let mut offset = 0usize;
            for (_, n) in read {
                out.push(view[offset..offset + *n as usize].to_vec());
                offset += n.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT) as usize;
            }
            out
        };
        stage.unmap();
        Ok(out)
    }
}

impl Drop for Gpu<'_> {
    /// Everything the engine made (its pipelines, pooled and staging buffers) is released inside
    /// a turn, as everything else is: the turn taken here is the last field to go.
    fn drop(&mut self) {
        self.dropping = self.turn();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::cpu::project::ViewRows;
    use std::sync::mpsc;
    use std::time::Duration;

    /// An OpenGL device (Mesa's llvmpipe where nothing else is installed), or None with a
    /// message when this machine has no GL adapter.
    fn gl_device() -> Option<(wgpu::Device, wgpu::Queue)> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::GL;
        let instance = wgpu::Instance::new(desc);
        let adapter = match pollster::block_on(instance.request_adapter(&Default::default())) {
            Ok(a) => a,
            Err(e) => {
                eprintln!("no OpenGL adapter here ({e}): the GL turn test is skipped");
                return None;
            }
        };
        pollster::block_on(adapter.request_device(&Default::default())).ok()
    }

    /// `work` runs on another thread while this thread holds engine `a`'s turn; whether it
    /// finished within `wait`, and (after the turn is let go) what it returned.
    fn finished_during_turn<R: Send>(
        a: &Gpu,
        wait: Duration,
        work: impl FnOnce() -> R + Send,
    ) -> (bool, R) {
        std::thread::scope(|s| {
            let (tx, rx) = mpsc::channel();
            let turn = a.turn();
            s.spawn(move || {
                let _ = tx.send(work());
            });
            let during = rx.recv_timeout(wait);
            drop(turn);
            let arrived = during.is_ok();
            let out = during
                .or_else(|_| rx.recv())
                .expect("the working thread sends");
            (arrived, out)
        })
    }

    /// Engine `b` projects one vertex (the result, or its error).
    fn project_one(b: &Gpu) -> Result<Vec<[f32; 4]>, GpuError> {
        let cams = crate::sim::simulated_views(
            &crate::sim::XrayGeometry::default(),
            &nalgebra::Point3::origin(),
        );
        let view = ViewRows::from_camera(&cams[0]);
        b.project(&[[0.0, 0.0, 0.0, 1.0]], 1, &[view])
    }

    #[test]
    fn on_opengl_a_second_engine_waits_for_the_first_ones_turn() {
        let Some((device, queue)) = gl_device() else {
            return;
        };
        let a = Gpu::new(&device, &queue).expect("pipelines compile on GL");
        let b = Gpu::new(&device, &queue).expect("pipelines compile on GL");
        assert!(a.takes_turns && b.takes_turns, "a GL device takes turns");
        let short = Duration::from_millis(1500);
        let (arrived, out) = finished_during_turn(&a, short, || project_one(&b));
        assert!(!arrived, "engine b ran its kernel inside engine a's turn");
        assert_eq!(out.expect("one vertex projects").len(), 1);
        // An engine dropped releases what it made inside a turn too.
        let (arrived, ()) = finished_during_turn(&a, short, move || drop(b));
        assert!(!arrived, "engine b was dropped inside engine a's turn");
        // Companions: an engine that does not take turns runs, and is dropped, straight through
        // a held turn, and the checks above reject it.
        let long = Duration::from_secs(120);
        let mut free = Gpu::new(&device, &queue).expect("pipelines compile on GL");
        free.takes_turns = false;
        let (arrived, _) = finished_during_turn(&a, long, || project_one(&free));
        assert!(
            arrived,
            "an engine without turns must not wait, so the check can fail"
        );
        let (arrived, ()) = finished_during_turn(&a, long, move || drop(free));
        assert!(arrived, "dropping an engine without turns must not wait");
    }

    /// Whether engine `b`'s projection, made on a detached thread that first takes a host's
    /// turn of its own when `take_host_turn` is set, arrives within `wait`.
    fn arrives_within(b: &'static Gpu<'static>, take_host_turn: bool, wait: Duration) -> bool {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let _host = take_host_turn.then(|| GlTurn::take(b.device()));
            let _ = tx.send(project_one(b).map(|v| v.len()));
        });
        match rx.recv_timeout(wait) {
            Ok(out) => {
                assert_eq!(out.expect("one vertex projects"), 1);
                true
            }
            Err(_) => false,
        }
    }

    #[test]
    fn a_hosts_turn_holds_engines_on_other_threads_back_and_not_its_own_threads_calls() {
        let Some((device, queue)) = gl_device() else {
            return;
        };
        // Leaked, so that a call stuck in a turn (a failure) cannot hold the test's end.
        let device: &'static wgpu::Device = Box::leak(Box::new(device));
        let queue: &'static wgpu::Queue = Box::leak(Box::new(queue));
        let b: &'static Gpu<'static> = Box::leak(Box::new(
            Gpu::new(device, queue).expect("pipelines compile on GL"),
        ));
        // A thread that holds its own turn calls the engine inside it: the turns nest.
        assert!(
            arrives_within(b, true, Duration::from_secs(120)),
            "an engine's call waited for the turn its own thread held"
        );
        // The companion: while this thread holds the host's turn, the same call on another
        // thread waits for it, and the check above would reject that.
        let host = GlTurn::take(device).expect("a GL device takes turns");
        assert!(
            !arrives_within(b, false, Duration::from_millis(1500)),
            "an engine ran inside a host's turn taken on another thread"
        );
        drop(host);
        // Given back, the turn lets the waiting call through (it arrives, and any new one does).
        assert!(arrives_within(b, false, Duration::from_secs(120)));
    }

    #[test]
    fn a_device_that_is_not_opengl_gives_no_turn() {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = wgpu::Backends::VULKAN | wgpu::Backends::METAL | wgpu::Backends::DX12;
        let instance = wgpu::Instance::new(desc);
        let Ok(adapter) = pollster::block_on(instance.request_adapter(&Default::default())) else {
            eprintln!("no Vulkan, Metal or DX12 adapter here: the no-turn test is skipped");
            return;
        };
        let (device, _queue) =
            pollster::block_on(adapter.request_device(&Default::default())).expect("a device");
        assert!(
            GlTurn::take(&device).is_none(),
            "{:?} took a GL turn",
            adapter.get_info().backend
        );
        // The companion: an OpenGL device gives one.
        if let Some((gl, _q)) = gl_device() {
            assert!(GlTurn::take(&gl).is_some(), "an OpenGL device gave no turn");
        }
    }
}
