//! Cross-run batching: the runs of a study that are in flight at the same time hand their
//! deform, project and banded SRVF DP requests to one `GpuBatcher`, which merges compatible
//! requests (same mesh size, graph size and views; the same DP step set) into one dispatch per
//! kernel and one submit, and hands each run its slice back. A request waits at most `wait` for
//! companions, so a lone run is not held up.
//!
//! Lock-step: runs that register (`GpuBatcher::run`, as a study's runs do) are advanced together.
//! A lane then dispatches as soon as every registered run is waiting for the device (in any
//! lane), so each step of the method goes to the device once for all the runs that take it;
//! `wait` stays as the longest a request waits, so a run held up elsewhere cannot stall the others
//! for good.

use super::{Gpu, GpuError};
use crate::correspond::srvf::{BandProblem, BandSolver};
use crate::engine::cpu::deform::DeformBatch;
use crate::engine::cpu::project::ViewRows;
use crate::engine::cpu::srvf_band::BandBatch;
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::{Duration, Instant};

type Out = Result<Vec<[f32; 4]>, GpuError>;

struct LaneState<T, R> {
    pending: Vec<(u64, T)>,
    done: HashMap<u64, R>,
    next: u64,
    busy: bool,
}

struct Lane<T, R = Out> {
    state: Mutex<LaneState<T, R>>,
    cv: Condvar,
}

/// The registered runs and how many of them wait for the device, over every lane.
#[derive(Default)]
struct Gate {
    active: AtomicUsize,
    waiting: AtomicUsize,
}

impl Gate {
    /// Every registered run waits for the device (none registered: never).
    fn all_waiting(&self) -> bool {
        let active = self.active.load(Ordering::SeqCst);
        active > 0 && self.waiting.load(Ordering::SeqCst) >= active
    }
}

/// This thread waits for the device until dropped (counted in `Gate::waiting`).
struct Waiting<'g>(&'g Gate);

impl<'g> Waiting<'g> {
    fn on(gate: &'g Gate) -> Self {
        gate.waiting.fetch_add(1, Ordering::SeqCst);
        Waiting(gate)
    }
}

impl Drop for Waiting<'_> {
    fn drop(&mut self) {
        self.0.waiting.fetch_sub(1, Ordering::SeqCst);
    }
}

/// How often a waiting request looks whether every registered run waits (a run waiting in
/// another lane does not wake this one).
const GATE_POLL: Duration = Duration::from_micros(200);

impl<T, R> Lane<T, R> {
    fn new() -> Self {
        Lane {
            state: Mutex::new(LaneState {
                pending: Vec::new(),
                done: HashMap::new(),
                next: 0,
                busy: false,
            }),
            cv: Condvar::new(),
        }
    }

    /// Queue `input`; whoever finds the lane idle with enough requests (every registered run
    /// waiting, `lanes` requests, or after `wait`) runs all pending ones through `run` and posts
    /// every result.
    fn submit(
        &self,
        input: T,
        lanes: usize,
        wait: Duration,
        gate: &Gate,
        run: impl Fn(Vec<(u64, T)>) -> Vec<(u64, R)>,
    ) -> R {
        let start = Instant::now();
        let mut s = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let id = s.next;
        s.next += 1;
        s.pending.push((id, input));
        // Counted as waiting only once its request is queued: counted before, a run polling this
        // lane could find every run waiting and send the queue without this request (two
        // dispatches for one step; seen on a loaded machine).
        let _waiting = Waiting::on(gate);
        self.cv.notify_all();
        loop {
            if let Some(r) = s.done.remove(&id) {
                return r;
            }
            let waited = start.elapsed();
            let ready = s.pending.len() >= lanes || waited >= wait || gate.all_waiting();
            if !s.busy && !s.pending.is_empty() && ready {
                s.busy = true;
                let jobs = std::mem::take(&mut s.pending);
                drop(s);
                let results = run(jobs);
                s = self.state.lock().unwrap_or_else(|e| e.into_inner());
                s.done.extend(results);
                s.busy = false;
                self.cv.notify_all();
                continue;
            }
            let mut left = wait.saturating_sub(waited).max(Duration::from_micros(50));
            if gate.active.load(Ordering::SeqCst) > 0 {
                left = left.min(GATE_POLL);
            }
            s = self
                .cv
                .wait_timeout(s, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

/// One projection request: the vertices, the vertex count per mesh and the views.
type ProjectJob = (Vec<[f32; 4]>, usize, Vec<ViewRows>);

/// One kernel's work through a batcher: the runs' requests, the dispatches they were merged
/// into, and the seconds from submit to read-back (upload, dispatch and copy back: what the
/// runs waited for the device).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct KernelStats {
    /// Requests from runs.
    pub requests: usize,
    /// Dispatches (one submit each).
    pub dispatches: usize,
    /// Seconds from submit to read-back, summed over the dispatches.
    pub device_seconds: f64,
}

impl KernelStats {
    /// The work done since `before` (an earlier reading of the same batcher).
    pub fn since(&self, before: &KernelStats) -> KernelStats {
        KernelStats {
            requests: self.requests - before.requests,
            dispatches: self.dispatches - before.dispatches,
            device_seconds: self.device_seconds - before.device_seconds,
        }
    }
}

/// Per kernel, what a batcher did.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct BatcherStats {
    /// The deformation kernel.
    pub deform: KernelStats,
    /// The projection kernel.
    pub project: KernelStats,
    /// The banded SRVF DP kernel.
    pub srvf_band: KernelStats,
    /// Banded DPs the device could not take (a failed dispatch, an input it refused), solved
    /// on the host instead.
    pub srvf_band_on_host: usize,
}

impl BatcherStats {
    /// The work done since `before`.
    pub fn since(&self, before: &BatcherStats) -> BatcherStats {
        BatcherStats {
            deform: self.deform.since(&before.deform),
            project: self.project.since(&before.project),
            srvf_band: self.srvf_band.since(&before.srvf_band),
            srvf_band_on_host: self.srvf_band_on_host - before.srvf_band_on_host,
        }
    }

    /// The three kernels' work together: requests, dispatches and device seconds summed.
    pub fn total(&self) -> KernelStats {
        let [d, p, b] = [self.deform, self.project, self.srvf_band];
        KernelStats {
            requests: d.requests + p.requests + b.requests,
            dispatches: d.dispatches + p.dispatches + b.dispatches,
            device_seconds: d.device_seconds + p.device_seconds + b.device_seconds,
        }
    }
}

/// The longest a study's request waits for the other runs in flight (`GpuBatcher::new`'s
/// `wait`): with the runs registered, a lane dispatches as soon as every run waits, so this is
/// only the bound on how long a run held up on the host (a long final stage) stalls the others.
/// On lavapipe (8 runs in flight, phantom) 50 ms instead of 2 ms merged 2.5 instead of 1.2
/// requests a dispatch with the DPs on the host, at the same throughput.
pub const STUDY_WAIT: Duration = Duration::from_millis(50);

/// A registered run (`GpuBatcher::run`); dropping it unregisters the run.
pub struct RunGuard<'b> {
    gate: &'b Gate,
    /// The gate this thread was registered with before (restored on drop).
    before: usize,
}

impl Drop for RunGuard<'_> {
    fn drop(&mut self) {
        self.gate.active.fetch_sub(1, Ordering::SeqCst);
        REGISTERED.with(|r| r.set(self.before));
    }
}

/// The independent parts of a registered run on threads of their own (`GpuBatcher::parts`):
/// the run steps aside while they go on in its place, and comes back when dropped.
struct Aside<'b>(&'b Gate);

impl Drop for Aside<'_> {
    fn drop(&mut self) {
        self.0.active.fetch_add(1, Ordering::SeqCst);
    }
}

thread_local! {
    /// The gate (by address) this thread's run is registered with, or 0.
    static REGISTERED: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The requests `jobs` in groups that `same` says can share a dispatch, in arrival order.
fn grouped<T>(jobs: Vec<(u64, T)>, same: impl Fn(&T, &T) -> bool) -> Vec<Vec<(u64, T)>> {
    let mut groups: Vec<Vec<(u64, T)>> = Vec::new();
    for j in jobs {
        match groups.iter_mut().find(|g| same(&g[0].1, &j.1)) {
            Some(g) => g.push(j),
            None => groups.push(vec![j]),
        }
    }
    groups
}

/// Each request of group `g` its part of the merged dispatch's output `all` (`len` entries
/// each, in order), or the dispatch's error.
fn hand_out<T, V: Clone>(
    g: &[(u64, T)],
    all: Result<Vec<V>, GpuError>,
    len: impl Fn(&T) -> usize,
    out: &mut Vec<(u64, Result<Vec<V>, GpuError>)>,
) {
    match all {
        Ok(all) => {
            let mut at = 0;
            for (id, t) in g {
                let n = len(t);
                out.push((*id, Ok(all[at..at + n].to_vec())));
                at += n;
            }
        }
        Err(e) => out.extend(g.iter().map(|(id, _)| (*id, Err(e.clone())))),
    }
}

/// Merges concurrent kernel requests from up to `lanes` runs.
pub struct GpuBatcher<'g> {
    gpu: &'g Gpu<'g>,
    lanes: usize,
    wait: Duration,
    deform: Lane<DeformBatch>,
    project: Lane<(Vec<[f32; 4]>, usize, Vec<ViewRows>)>,
    band: Lane<BandBatch, Result<Vec<u32>, GpuError>>,
    gate: Gate,
    dp_on_device: bool,
    stats: Mutex<BatcherStats>,
}

impl<'g> GpuBatcher<'g> {
    /// `lanes`: how many runs go at once (the study's threads); `wait`: the longest a request
    /// waits for companions (2 ms is plenty when runs are in step).
    pub fn new(gpu: &'g Gpu<'g>, lanes: usize, wait: Duration) -> Self {
        GpuBatcher {
            gpu,
            lanes: lanes.max(1),
            wait,
            deform: Lane::new(),
            project: Lane::new(),
            band: Lane::new(),
            gate: Gate::default(),
            dp_on_device: false,
            stats: Mutex::new(BatcherStats::default()),
        }
    }

    /// The same batcher with the runs' SRVF DPs on the device (`true`) or on the host (`false`,
    /// the default).
    pub fn with_dp_on_device(mut self, on: bool) -> Self {
        self.dp_on_device = on;
        self
    }

    /// Register a run for lock-step until the guard is dropped: while registered runs exist, a
    /// lane dispatches once every one of them waits for the device.
    pub fn run(&self) -> RunGuard<'_> {
        self.gate.active.fetch_add(1, Ordering::SeqCst);
        let here = &self.gate as *const Gate as usize;
        RunGuard {
            gate: &self.gate,
            before: REGISTERED.with(|r| r.replace(here)),
        }
    }

    /// `f(k, &items[k])` for the independent parts of one run (its views, resamples, restarts),
    /// in input order. For a run registered on this thread, each part on a thread of its own,
    /// registered in the run's place, so that the parts' device requests go in the same
    /// lock-step dispatches; otherwise one after the other on this thread.
    pub fn parts<T: Sync, R: Send>(
        &self,
        items: &[T],
        f: impl Fn(usize, &T) -> R + Sync + Send,
    ) -> Vec<R> {
        let here = &self.gate as *const Gate as usize;
        if items.len() < 2 || REGISTERED.with(|r| r.get()) != here {
            return items.iter().enumerate().map(|(k, t)| f(k, t)).collect();
        }
        self.gate.active.fetch_sub(1, Ordering::SeqCst);
        let _back = Aside(&self.gate);
        let f = &f;
        std::thread::scope(|s| {
            let hs: Vec<_> = items
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    s.spawn(move || {
                        let _run = self.run();
                        f(k, t)
                    })
                })
                .collect();
            hs.into_iter()
                .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        })
    }

    /// Whether the runs' SRVF DPs go to the device.
    pub fn dp_on_device(&self) -> bool {
        self.dp_on_device
    }

    /// The engine it submits to.
    pub fn gpu(&self) -> &'g Gpu<'g> {
        self.gpu
    }

    /// How many runs go at once.
    pub fn lanes(&self) -> usize {
        self.lanes
    }

    /// (requests, dispatches) so far over every kernel: their ratio is the mean batch size.
    pub fn counts(&self) -> (usize, usize) {
        let t = self.stats().total();
        (t.requests, t.dispatches)
    }

    /// Per kernel, the requests, dispatches and device seconds so far.
    pub fn stats(&self) -> BatcherStats {
        *self.stats.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Run one merged dispatch of `requests` requests, counting it under `kernel`.
    fn count<T>(
        &self,
        kernel: fn(&mut BatcherStats) -> &mut KernelStats,
        requests: usize,
        dispatch: impl FnOnce() -> T,
    ) -> T {
        let t = Instant::now();
        let out = dispatch();
        let secs = t.elapsed().as_secs_f64();
        let mut s = self.stats.lock().unwrap_or_else(|e| e.into_inner());
        let k = kernel(&mut s);
        k.requests += requests;
        k.dispatches += 1;
        k.device_seconds += secs;
        out
    }

    /// As `Gpu::deform`, merged with other runs' requests of the same shape.
    pub fn deform(&self, b: DeformBatch) -> Out {
        self.deform
            .submit(b, self.lanes, self.wait, &self.gate, |jobs| {
                let key = |b: &DeformBatch| (b.vertex_count, b.node_count, b.neighbours);
                let mut out = Vec::new();
                for g in grouped(jobs, |x, y| key(x) == key(y)) {
                    let mut merged = g[0].1.clone();
                    for (_, b) in &g[1..] {
                        merged.mesh_count += b.mesh_count;
                        merged.rest.extend_from_slice(&b.rest);
                        merged.nodes.extend_from_slice(&b.nodes);
                        merged.affine.extend_from_slice(&b.affine);
                        merged.node_index.extend_from_slice(&b.node_index);
                        merged.weight.extend_from_slice(&b.weight);
                    }
                    let all = self.count(|s| &mut s.deform, g.len(), || self.gpu.deform(&merged));
                    hand_out(&g, all, |b| b.rest.len(), &mut out);
                }
                out
            })
    }

    /// As `Gpu::project`, merged with other runs' requests with the same views and mesh size.
    pub fn project(
        &self,
        vertices: Vec<[f32; 4]>,
        vertex_count: usize,
        views: Vec<ViewRows>,
    ) -> Out {
        self.project.submit(
            (vertices, vertex_count, views),
            self.lanes,
            self.wait,
            &self.gate,
            |jobs| {
                let mut out = Vec::new();
                let same = |x: &ProjectJob, y: &ProjectJob| x.1 == y.1 && x.2 == y.2;
                for g in grouped(jobs, same) {
                    let (vc, views) = (g[0].1 .1, g[0].1 .2.clone());
                    let verts: Vec<[f32; 4]> =
                        g.iter().flat_map(|(_, j)| j.0.iter().copied()).collect();
                    let all = self.count(
                        |s| &mut s.project,
                        g.len(),
                        || self.gpu.project(&verts, vc, &views),
                    );
                    // Mesh b's outputs are contiguous: (b * C + view) * V + vertex.
                    hand_out(&g, all, |j| j.0.len() * views.len(), &mut out);
                }
                out
            },
        )
    }
}

impl GpuBatcher<'_> {
    /// As `Gpu::srvf_band_tables` for one problem's batch, merged with other runs' problems of
    /// the same step set; the problem's back-pointers.
    pub fn band_back_pointers(&self, b: BandBatch) -> Result<Vec<u32>, GpuError> {
        self.band
            .submit(b, self.lanes, self.wait, &self.gate, |jobs| {
                let mut out = Vec::new();
                for g in grouped(jobs, |x, y| x.step_set == y.step_set) {
                    let merged = g[1..]
                        .iter()
                        .try_fold(g[0].1.clone(), |mut m, (_, b)| m.append(b).map(|()| m))
                        .map_err(GpuError::from);
                    let back = merged.and_then(|m| {
                        self.count(
                            |s| &mut s.srvf_band,
                            g.len(),
                            || self.gpu.srvf_band_tables(&m),
                        )
                    });
                    hand_out(&g, back.map(|(_, back)| back), |b| b.cells, &mut out);
                }
                out
            })
    }
}

/// The study's runs hand their SRVF DPs to the device through the batcher; a problem the device
/// cannot take is solved on the host and counted (`BatcherStats::srvf_band_on_host`).
impl BandSolver for GpuBatcher<'_> {
    fn back_pointers(&self, p: &BandProblem) -> Option<Vec<u32>> {
        self.back_pointers_many(std::slice::from_ref(p))?.pop()
    }

    /// The problems as one request (merged with the other runs' into one dispatch).
    fn back_pointers_many(&self, ps: &[BandProblem]) -> Option<Vec<Vec<u32>>> {
        let back = BandBatch::new(ps).map_err(GpuError::from).and_then(|b| {
            let ranges = b.ranges();
            let all = self.band_back_pointers(b)?;
            Ok(ranges.into_iter().map(|r| all[r].to_vec()).collect())
        });
        if back.is_err() {
            self.stats
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .srvf_band_on_host += ps.len();
        }
        back.ok()
    }
}
