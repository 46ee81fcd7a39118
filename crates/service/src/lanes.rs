//! Compute lanes: where the CPU-bound work of a request runs.
//!
//! Every endpoint's computation runs off the async workers (a large request
//! must never stall the requests beside it). tokio's blocking pool did that
//! with one thread per request in flight: under 64 concurrent small requests
//! it ran 64 threads on 2 cores, and each request paid a thread wake-up on
//! the way in and a context switch on the way out. A profile of the small
//! correlation request under load put ≈ 30 % of the server's CPU in the
//! kernel's scheduler and futexes, and running the same requests inline
//! doubled the throughput of the rules endpoint and of the small correlation
//! request alike (docs/RESULTS.md, "Request path").
//!
//! Lanes keep the offload and drop the thrashing: one thread per core, fed
//! from one FIFO queue. Under load the queue is never empty, so a lane takes
//! its next job without sleeping and nobody is woken; a lane is woken only
//! when it sleeps (idle count kept under the queue's lock, so an idle pool
//! costs one wake-up and a busy one none).
//!
//! A long job must not hold every lane: a lane whose current job started
//! more than [`LONG_JOB`] ago counts as held. While some lane is not held,
//! work is queued to the lanes (served in order by the lanes not held);
//! when every lane is held, new work goes to tokio's blocking pool as
//! before, where the operating system shares the cores among all of it.
//! Work already queued goes there too: a job queued while a lane was free
//! can find every lane taken by long jobs after it was queued (jobs queued
//! before it, or started by the lanes meanwhile), and the lanes' watch (a
//! thread that sleeps while nothing waits for a busy lane) hands it back to
//! its request once they are all held. So a 10 s request delays nobody by
//! more than [`LONG_JOB`] per lane, and small requests never wait behind
//! large ones.
//!
//! A request the adapters admitted runs its jobs under [`admitted`]: its
//! in-flight slot travels with them and is given back only when the
//! request and every job it queued have finished, and jobs that would go to
//! the blocking pool beyond the service's bound ([`BlockingBound`]) are
//! refused ([`ServiceError::Overloaded`], 503) instead of queueing there
//! without bound. A request abandoned before its job ends (its timeout
//! passed: 504, or its client left) cancels the job: one still queued never
//! runs, and one running stops at its next [`checkpoint`], which the long
//! loops of the computations call (between instants of a correlation, scans
//! of a JPDA update, frames of the tracker). `/metrics` counts both in
//! `compute_jobs_cancelled_total{stage="queued"|"running"}`.

use std::{
    collections::VecDeque,
    panic::{AssertUnwindSafe, catch_unwind},
    sync::{
        Arc, Condvar, Mutex, OnceLock,
        atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering},
    },
    time::{Duration, Instant},
};

use super::ServiceError;

/// A lane running one job for longer than this is held: new work does not
/// queue behind it.
pub const LONG_JOB: Duration = Duration::from_millis(2);

type Job = Box<dyn FnOnce() + Send>;

/// The `started` mark of a lane whose thread could not be started.
const NEVER_STARTED: u64 = u64::MAX;

/// A request's admission, which its jobs carry: the in-flight slot (any
/// value whose drop gives it back, such as a semaphore permit), held until
/// the request and its jobs have all finished, and the bound on jobs on the
/// blocking pool of the service that admitted it.
#[derive(Clone)]
pub struct Admitted {
    _slot: Arc<dyn Send + Sync>,
    blocking: Arc<BlockingBound>,
}

impl Admitted {
    /// The admission of a request holding `slot`, under `blocking`.
    pub fn new(slot: impl Send + Sync + 'static, blocking: Arc<BlockingBound>) -> Self {
        Self {
            _slot: Arc::new(slot),
            blocking,
        }
    }
}

/// The most jobs of one service that may run on (or wait for) tokio's
/// blocking pool at once: the pool takes work only when every lane is held
/// by a long job, and its own queue has no bound.
#[derive(Debug)]
pub struct BlockingBound {
    running: AtomicUsize,
    max: usize,
    /// The setting that raises `max`, named in the refusal.
    setting: &'static str,
}

impl BlockingBound {
    /// A bound of `max` jobs, raised by `setting` (named in the 503).
    pub fn new(max: usize, setting: &'static str) -> Self {
        Self {
            running: AtomicUsize::new(0),
            max,
            setting,
        }
    }

    /// Jobs on the blocking pool now.
    pub fn running(&self) -> usize {
        self.running.load(Ordering::Relaxed)
    }

    /// A place on the blocking pool, given back when dropped, or the 503
    /// naming the bound.
    fn take(self: &Arc<Self>) -> Result<BlockingSeat, ServiceError> {
        self.running
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < self.max).then_some(n + 1)
            })
            .map_err(|_| {
                metrics::counter!("compute_jobs_refused_total").increment(1);
                ServiceError::Overloaded(format!(
                    "every compute lane is busy with a long request and {} computations are \
                     running on or waiting for the blocking pool, the limit ({}); retry shortly",
                    self.max, self.setting
                ))
            })?;
        Ok(BlockingSeat(Arc::clone(self)))
    }
}

struct BlockingSeat(Arc<BlockingBound>);

impl Drop for BlockingSeat {
    fn drop(&mut self) {
        self.0.running.fetch_sub(1, Ordering::AcqRel);
    }
}

tokio::task_local! {
    static ADMITTED: Admitted;
}

/// Runs `request` (an admitted request's handling) with its admission, so
/// that the jobs it queues through [`run`] carry the slot and the bound.
pub async fn admitted<F: std::future::Future>(admission: Admitted, request: F) -> F::Output {
    ADMITTED.scope(admission, request).await
}

/// `Err(ServiceError::Cancelled)` when the request whose job runs on this
/// thread was abandoned (timed out, or its client left): long loops call it
/// and stop. `Ok` outside a job of [`run`].
pub fn checkpoint() -> Result<(), ServiceError> {
    let cancelled = CANCEL.with_borrow(|c| c.as_ref().is_some_and(|c| c.load(Ordering::Relaxed)));
    if cancelled {
        if !CANCEL_SEEN.replace(true) {
            metrics::counter!("compute_jobs_cancelled_total", "stage" => "running").increment(1);
        }
        return Err(ServiceError::Cancelled);
    }
    Ok(())
}

/// Runs `work` here as a job of a request that was abandoned: its first
/// [`checkpoint`] stops it. For the tests of the computations' checkpoints.
#[cfg(test)]
pub(crate) fn as_abandoned<T>(work: impl FnOnce() -> T) -> T {
    Context::current(Arc::new(AtomicBool::new(true))).in_job(work)
}

/// Sets a job's cancellation flag when the request awaiting it goes away
/// before the job answered.
struct Abandon(Arc<AtomicBool>);

impl Drop for Abandon {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Runs CPU-bound work on a compute lane (or, when every lane is held by a
/// long job, on tokio's blocking pool) and awaits its result. A panic in the
/// work is an internal error of this request only.
pub async fn offload<T, F>(work: F) -> Result<T, ServiceError>
where
    F: FnOnce() -> Result<T, ServiceError> + Send + 'static,
    T: Send + 'static,
{
    run(work).await?
}

/// [`offload`] for work of any result type: the adapters run a request's
/// parsing, computation and response encoding as one job, so that the
/// request's memory is allocated and freed on one thread. `/metrics` counts
/// the jobs by where they ran
/// (`compute_jobs_total{lane="compute"|"blocking_pool"}`).
///
/// Work offloaded from within a job (a gRPC call run whole on a lane,
/// [`block_on`]) runs in place: it is already off the async workers, and a
/// job that waited on the lanes for another could wait on itself.
pub async fn run<T, F>(work: F) -> Result<T, ServiceError>
where
    F: FnOnce() -> T + Send + 'static,
    T: Send + 'static,
{
    if IN_JOB.get() {
        return Ok(work());
    }
    // Boxed at once: the futures below do not carry `work` (a debug build
    // copies each level's state on the stack).
    let (job, bound, rx, _abandon) = job_of(work);
    Lanes::global().dispatch(job, bound).await?;
    rx.await.map_err(panicked)
}

/// The answer of a job whose sender went without answering: the job
/// panicked (a job abandoned by its request is not awaited).
fn panicked(_: tokio::sync::oneshot::error::RecvError) -> ServiceError {
    ServiceError::Internal("compute task failed (it panicked)".into())
}

/// Runs `job` on tokio's blocking pool, within the blocking bound of the
/// request that queued it (`None`: a job no request admitted).
fn on_blocking_pool(job: Job, bound: Option<&Arc<BlockingBound>>) -> Result<(), ServiceError> {
    let seat = bound.map(BlockingBound::take).transpose()?;
    metrics::counter!("compute_jobs_total", "lane" => "blocking_pool").increment(1);
    // Detached: the job answers its request itself.
    drop(tokio::task::spawn_blocking(move || {
        let _seat = seat;
        job();
    }));
    Ok(())
}

/// Runs `work` once on every compute lane (starting the lanes if they are
/// not yet), each lane taking its own call before any queued work, and
/// waits for all of them: the start-up warm-up, so that what a lane's first
/// job would pay once (the thread itself, its allocator heap, code and
/// tables touched for the first time) is paid before the service reports
/// ready. A lane busy with a job takes its call after that job. Returns one
/// result per lane (none for a lane whose call panicked).
pub async fn on_every_lane<T, F>(work: F) -> Vec<T>
where
    F: Fn() -> T + Send + Sync + 'static,
    T: Send + 'static,
{
    let lanes = Lanes::global();
    let work = Arc::new(work);
    let mut answers = Vec::with_capacity(lanes.started.len());
    for (lane, started) in lanes.started.iter().enumerate() {
        // A lane that could not start never takes a job: it is left out.
        if started.load(Ordering::Relaxed) == NEVER_STARTED {
            continue;
        }
        let work = Arc::clone(&work);
        let (tx, rx) = tokio::sync::oneshot::channel();
        lanes.push_to(
            lane,
            Box::new(move || {
                let _ = tx.send(work());
            }),
        );
        answers.push(rx);
    }
    let mut out = Vec::with_capacity(answers.len());
    for rx in answers {
        if let Ok(v) = rx.await {
            out.push(v);
        }
    }
    out
}

/// Allocates `mib` MiB in blocks of 64 KiB, writes a byte in every 4 KiB
/// page of them and frees them: the kernel hands the process those pages
/// (zeroed) now, and the allocator keeps them for the next allocations of
/// this thread, instead of the first request that needs them paying for it.
pub fn touch_memory(mib: usize) {
    const BLOCK: usize = 64 << 10;
    let blocks: Vec<Box<[u8]>> = (0..mib * 16)
        .map(|_| {
            let mut block = vec![0u8; BLOCK].into_boxed_slice();
            for page in block.chunks_mut(4096) {
                page[0] = 1;
            }
            std::hint::black_box(block)
        })
        .collect();
    drop(std::hint::black_box(blocks));
}

thread_local! {
    /// Whether this thread is running a job of [`run`].
    static IN_JOB: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    /// The cancellation flag of the job running on this thread.
    static CANCEL: std::cell::RefCell<Option<Arc<AtomicBool>>> =
        const { std::cell::RefCell::new(None) };
    /// Whether [`checkpoint`] has reported this job's cancellation (counted once).
    static CANCEL_SEEN: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// What a job takes along from the request that queued it: the log
/// subscriber and the request's span (its `request_id`), so that a line
/// logged on a lane names the request as one logged on the async worker
/// does, and the flag that says the request was abandoned.
struct Context {
    dispatch: tracing::Dispatch,
    span: tracing::Span,
    cancel: Arc<AtomicBool>,
}

impl Context {
    fn current(cancel: Arc<AtomicBool>) -> Self {
        Self {
            dispatch: tracing::dispatcher::get_default(Clone::clone),
            span: tracing::Span::current(),
            cancel,
        }
    }

    /// Runs `work` in the request's span, marked as a job of [`run`] with
    /// its cancellation flag (both cleared again on the way out, by
    /// unwinding too).
    fn in_job<T>(self, work: impl FnOnce() -> T) -> T {
        struct Clear;
        impl Drop for Clear {
            fn drop(&mut self) {
                IN_JOB.set(false);
                CANCEL.set(None);
                CANCEL_SEEN.set(false);
            }
        }
        tracing::dispatcher::with_default(&self.dispatch, || {
            let _entered = self.span.enter();
            IN_JOB.set(true);
            CANCEL.set(Some(self.cancel));
            CANCEL_SEEN.set(false);
            let _clear = Clear;
            work()
        })
    }
}

/// Drives a future to completion on the current thread, parking it while
/// the future waits. For work run whole on a lane whose awaits complete
/// without the async runtime's reactor or timers: a gRPC call whose message
/// is already in memory, its compute offloaded in place ([`run`]).
pub fn block_on<F: std::future::Future>(future: F) -> F::Output {
    struct Unpark(std::thread::Thread);
    impl std::task::Wake for Unpark {
        fn wake(self: Arc<Self>) {
            self.0.unpark();
        }
        fn wake_by_ref(self: &Arc<Self>) {
            self.0.unpark();
        }
    }
    let waker = std::task::Waker::from(Arc::new(Unpark(std::thread::current())));
    let mut cx = std::task::Context::from_waker(&waker);
    let mut future = std::pin::pin!(future);
    loop {
        if let std::task::Poll::Ready(out) = future.as_mut().poll(&mut cx) {
            return out;
        }
        std::thread::park();
    }
}

/// The process's lanes: one thread per available core, started on first
/// use, and their watch: a thread that hands the jobs waiting in the
/// shared queue back to their requests once every lane is held.
struct Lanes {
    queue: Mutex<Queue>,
    /// Where idle lanes wait for work.
    ready: Condvar,
    /// Where the watch waits for jobs to wait behind busy lanes.
    watch: Condvar,
    /// Per lane: nanoseconds since `epoch` when its current job started
    /// (plus one, so that 0 means idle).
    started: Vec<AtomicU64>,
    epoch: Instant,
}

#[derive(Default)]
struct Queue {
    jobs: VecDeque<Queued>,
    /// Per lane: jobs for that lane alone ([`on_every_lane`]), taken first.
    pinned: Vec<VecDeque<Job>>,
    /// Lanes waiting on `ready`.
    idle: usize,
    /// Whether the watch waits on `watch` with no time limit (nothing queued
    /// then waited for a busy lane).
    watch_asleep: bool,
}

/// A job in the shared queue, and the way back to the request that queued
/// it (`None`: a job only a lane may run).
struct Queued {
    job: Job,
    back: Option<tokio::sync::oneshot::Sender<Job>>,
}

impl Lanes {
    fn global() -> &'static Arc<Lanes> {
        static LANES: OnceLock<Arc<Lanes>> = OnceLock::new();
        LANES.get_or_init(|| {
            let n = std::thread::available_parallelism().map_or(1, |n| n.get());
            Lanes::start(n)
        })
    }

    fn start(n: usize) -> Arc<Lanes> {
        let lanes = Arc::new(Lanes {
            queue: Mutex::new(Queue {
                pinned: (0..n).map(|_| VecDeque::new()).collect(),
                ..Queue::default()
            }),
            ready: Condvar::new(),
            watch: Condvar::new(),
            started: (0..n).map(|_| AtomicU64::new(0)).collect(),
            epoch: Instant::now(),
        });
        for i in 0..n {
            let lane = Arc::clone(&lanes);
            let started = std::thread::Builder::new()
                .name(format!("compute-{i}"))
                .spawn(move || lane.run_lane(i));
            if let Err(e) = started {
                // A lane that could not start counts as held for ever:
                // work goes to the others, or to the blocking pool when
                // none started.
                tracing::error!(lane = i, error = %e, "a compute lane could not start");
                lanes.started[i].store(NEVER_STARTED, Ordering::Relaxed);
            }
        }
        let watch = Arc::clone(&lanes);
        if let Err(e) = std::thread::Builder::new()
            .name("compute-watch".into())
            .spawn(move || watch.watch())
        {
            // Queued jobs then wait for a lane, as they did before the
            // watch existed.
            tracing::error!(error = %e, "the compute lanes' watch could not start");
        }
        lanes
    }

    /// Sends a request's `job` on its way: to the blocking pool when every
    /// lane is held, else to the lanes ([`Lanes::queued`]).
    async fn dispatch(
        &self,
        job: Job,
        bound: Option<Arc<BlockingBound>>,
    ) -> Result<(), ServiceError> {
        if self.all_held() {
            return on_blocking_pool(job, bound.as_ref());
        }
        self.queued(job, bound).await
    }

    /// Queues a request's `job` for the lanes and waits until a lane has
    /// run it, or the lanes' watch hands it back (every lane became held
    /// while it waited) and it goes to the blocking pool.
    async fn queued(
        &self,
        job: Job,
        bound: Option<Arc<BlockingBound>>,
    ) -> Result<(), ServiceError> {
        let (back, handed_back) = tokio::sync::oneshot::channel();
        self.push_queued(Queued {
            job,
            back: Some(back),
        });
        // A lane drops the way back after the job has answered: an error
        // here means the answer is there.
        match handed_back.await {
            Ok(job) => on_blocking_pool(job, bound.as_ref()),
            Err(_) => Ok(()),
        }
    }

    /// [`run`] of work queued for the lanes whatever they do now.
    #[cfg(test)]
    async fn run_queued<T, F>(&self, work: F) -> Result<T, ServiceError>
    where
        F: FnOnce() -> T + Send + 'static,
        T: Send + 'static,
    {
        let (job, bound, rx, _abandon) = job_of(work);
        self.queued(job, bound).await?;
        rx.await.map_err(panicked)
    }

    fn now(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(NEVER_STARTED - 2) + 1
    }

    /// Whether every lane is running a job that started over `LONG_JOB` ago.
    fn all_held(&self) -> bool {
        self.until_all_held() == Some(Duration::ZERO)
    }

    /// How long until every lane is held if none finishes its job first:
    /// zero when they are, `None` while a lane is idle.
    fn until_all_held(&self) -> Option<Duration> {
        let now = self.now();
        let long = LONG_JOB.as_nanos() as u64;
        let mut wait = 0;
        for s in &self.started {
            let t = s.load(Ordering::Relaxed);
            if t == NEVER_STARTED {
                continue;
            }
            if t == 0 {
                return None;
            }
            wait = wait.max((t + long).saturating_sub(now));
        }
        Some(Duration::from_nanos(wait))
    }

    /// Queues `job` for any lane; it runs after the jobs queued before it.
    #[cfg(test)]
    fn push(&self, job: Job) {
        self.push_queued(Queued { job, back: None });
    }

    fn push_queued(&self, queued: Queued) {
        let (wake_lane, wake_watch) = {
            let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
            q.jobs.push_back(queued);
            // More jobs than idle lanes: one waits for a busy lane, and the
            // watch follows it.
            (q.idle > 0, q.watch_asleep && q.jobs.len() > q.idle)
        };
        if wake_lane {
            self.ready.notify_one();
        }
        if wake_watch {
            self.watch.notify_one();
        }
    }

    /// Queues `job` for `lane` alone; it runs before the shared queue's.
    fn push_to(&self, lane: usize, job: Job) {
        let wake = {
            let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
            q.pinned[lane].push_back(job);
            q.idle > 0
        };
        // Only that lane can take it: every sleeping lane looks.
        if wake {
            self.ready.notify_all();
        }
    }

    fn run_lane(&self, lane: usize) {
        loop {
            let (job, back) = {
                let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    if let Some(job) = q.pinned[lane].pop_front() {
                        break (job, None);
                    }
                    if let Some(Queued { job, back }) = q.jobs.pop_front() {
                        break (job, back);
                    }
                    q.idle += 1;
                    q = self.ready.wait(q).unwrap_or_else(|e| e.into_inner());
                    q.idle -= 1;
                }
            };
            if back.is_some() {
                metrics::counter!("compute_jobs_total", "lane" => "compute").increment(1);
            }
            self.started[lane].store(self.now(), Ordering::Relaxed);
            // The job reports its own result; a panic drops its sender,
            // which the waiting request reads as an internal error.
            let _ = catch_unwind(AssertUnwindSafe(job));
            self.started[lane].store(0, Ordering::Relaxed);
            // Dropped after the answer, so that the request is woken once.
            drop(back);
        }
    }

    /// The watch: while jobs wait in the shared queue, looks again each
    /// time every lane could have become held, and when every lane is held
    /// hands each waiting job back to its request, which runs it on the
    /// blocking pool (within its bound) as it would new work: a job queued
    /// while a lane was free never waits behind long jobs that took the
    /// lanes after it was queued. Asleep while nothing waits.
    fn watch(&self) {
        let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if q.jobs.len() <= q.idle {
                q.watch_asleep = true;
                q = self.watch.wait(q).unwrap_or_else(|e| e.into_inner());
                q.watch_asleep = false;
                continue;
            }
            let wait = match self.until_all_held() {
                Some(Duration::ZERO) => {
                    let mut handed = Vec::with_capacity(q.jobs.len());
                    for queued in std::mem::take(&mut q.jobs) {
                        match queued.back {
                            Some(back) => handed.push((back, queued.job)),
                            None => q.jobs.push_back(queued),
                        }
                    }
                    drop(q);
                    for (back, job) in handed {
                        if back.send(job).is_err() {
                            // Its request has gone: it would not have run.
                            metrics::counter!("compute_jobs_cancelled_total", "stage" => "queued")
                                .increment(1);
                        }
                    }
                    q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
                    // Only jobs no request waits for are left: look again
                    // a long job later.
                    LONG_JOB
                }
                Some(wait) => wait,
                None => LONG_JOB,
            };
            q = self
                .watch
                .wait_timeout(q, wait.max(WATCH_MIN_WAIT))
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

/// The watch's shortest sleep, so that it never spins.
const WATCH_MIN_WAIT: Duration = Duration::from_micros(100);

/// A request's job of `work`: the job, which answers on the returned
/// receiver (nothing when its request has gone first), the blocking bound
/// of the request's admission, and the guard that marks the job abandoned
/// when the request stops waiting.
#[allow(clippy::type_complexity)]
fn job_of<T, F>(
    work: F,
) -> (
    Job,
    Option<Arc<BlockingBound>>,
    tokio::sync::oneshot::Receiver<T>,
    Abandon,
)
where
    F: FnOnce() -> T + Send + 'static,
    T: Send + 'static,
{
    let admission = ADMITTED.try_with(Admitted::clone).ok();
    let bound = admission.as_ref().map(|a| Arc::clone(&a.blocking));
    let cancel = Arc::new(AtomicBool::new(false));
    // Dropped with the request's future: when it goes before the answer
    // came, the request was abandoned and the job stops.
    let abandon = Abandon(Arc::clone(&cancel));
    let context = Context::current(cancel);
    let (tx, rx) = tokio::sync::oneshot::channel();
    let job: Job = Box::new(move || {
        if context.cancel.load(Ordering::Relaxed) {
            metrics::counter!("compute_jobs_cancelled_total", "stage" => "queued").increment(1);
            return;
        }
        let out = context.in_job(work);
        // The slot goes back before the answer does, so that a client
        // that sends its next request on the answer finds it free.
        drop(admission);
        let _ = tx.send(out);
    });
    (job, bound, rx, abandon)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn a_lane_returns_the_work_and_its_error() {
        assert_eq!(offload(|| Ok(6 * 7)).await.unwrap(), 42);
        let e = offload::<(), _>(|| Err(ServiceError::Internal("x".into())))
            .await
            .unwrap_err();
        assert!(matches!(e, ServiceError::Internal(m) if m == "x"));
    }

    #[tokio::test]
    async fn a_panic_is_an_internal_error_and_the_lane_lives_on() {
        let e = offload::<(), _>(|| panic!("boom")).await.unwrap_err();
        assert!(matches!(e, ServiceError::Internal(_)));
        // Every lane still serves: more jobs than lanes, all answered.
        let n = Lanes::global().started.len();
        for i in 0..4 * n {
            assert_eq!(offload(move || Ok(i)).await.unwrap(), i);
        }
    }

    #[tokio::test]
    async fn work_offloaded_from_a_job_runs_in_place() {
        // The inner `run` answers on the job's own thread, without queueing
        // behind (or waiting for) the job that runs it.
        let (outer, inner) = run(|| {
            let outer = std::thread::current().id();
            let inner = block_on(run(|| std::thread::current().id()));
            (outer, inner.expect("the inner work ran"))
        })
        .await
        .unwrap();
        assert_eq!(outer, inner);
        assert!(!IN_JOB.get(), "the async worker is not marked");
    }

    #[tokio::test]
    async fn on_every_lane_runs_once_on_each_lane() {
        // As many answers as lanes, each from a different lane thread.
        let n = Lanes::global().started.len();
        let mut names: Vec<String> = on_every_lane(|| {
            std::thread::current()
                .name()
                .unwrap_or_default()
                .to_string()
        })
        .await;
        names.sort();
        names.dedup();
        assert_eq!(names.len(), n, "{names:?}");
        assert!(names.iter().all(|name| name.starts_with("compute-")));
        // A panic on a lane is that lane's missing answer, not a hang.
        let answers = on_every_lane(|| -> u8 { panic!("warm-up failed") }).await;
        assert!(answers.is_empty());
        assert_eq!(offload(|| Ok(1)).await.unwrap(), 1);
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
    async fn calls_side_by_side_all_finish() {
        // Eight warm-ups at once (as servers starting side by side in one
        // test process): each lane runs each call once, and all finish.
        let n = Lanes::global().started.len();
        let calls: Vec<_> = (0..8)
            .map(|_| tokio::spawn(on_every_lane(|| 1usize)))
            .collect();
        let done = tokio::time::timeout(Duration::from_secs(30), async {
            let mut total = 0;
            for call in calls {
                total += call.await.unwrap().iter().sum::<usize>();
            }
            total
        })
        .await
        .expect("the warm-ups finished");
        assert_eq!(done, 8 * n);
    }

    #[test]
    fn a_lane_held_by_a_job_takes_its_call_after_it_and_the_others_serve() {
        // Lane 0 of two is held by a job waiting for a gate; the call for
        // lane 1 runs at once and shared work still runs (on lane 1); the
        // call for lane 0 runs when the gate opens. (A warm-up that made
        // every lane wait for the others at a barrier hung servers started
        // while a test held a lane.)
        let lanes = Lanes::start(2);
        let (gate_tx, gate_rx) = std::sync::mpsc::channel::<()>();
        let (held_tx, held_rx) = std::sync::mpsc::channel();
        lanes.push_to(
            0,
            Box::new(move || {
                held_tx.send(()).unwrap();
                gate_rx.recv().unwrap();
            }),
        );
        held_rx.recv().unwrap();
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        for lane in [0, 1] {
            let done = done_tx.clone();
            lanes.push_to(lane, Box::new(move || done.send(lane).unwrap()));
        }
        let shared = done_tx.clone();
        lanes.push(Box::new(move || shared.send(7).unwrap()));
        let wait = || done_rx.recv_timeout(Duration::from_secs(10)).unwrap();
        let mut first = [wait(), wait()];
        first.sort();
        assert_eq!(first, [1, 7], "lane 1's call and the shared job");
        gate_tx.send(()).unwrap();
        assert_eq!(wait(), 0);
    }

    #[test]
    fn block_on_parks_until_the_future_is_woken() {
        // A future that is pending until another thread sends its value.
        let (tx, rx) = tokio::sync::oneshot::channel();
        let sender = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            tx.send(7).unwrap();
        });
        assert_eq!(block_on(rx), Ok(7));
        sender.join().unwrap();
    }

    #[test]
    fn the_job_mark_is_cleared_by_a_panic() {
        let r = catch_unwind(|| Context::current(Arc::default()).in_job::<()>(|| panic!("boom")));
        assert!(r.is_err());
        assert!(!IN_JOB.get());
    }

    #[tokio::test]
    async fn a_job_runs_in_the_span_of_the_request_that_queued_it() {
        use tracing::Instrument;
        // A subscriber for this thread only; the lane is another thread.
        let _subscriber =
            tracing::subscriber::set_default(tracing_subscriber::registry::Registry::default());
        let span = tracing::info_span!("request", request_id = "r-42");
        let seen = async {
            run(|| {
                let current = tracing::Span::current();
                (
                    std::thread::current().name().map(str::to_string),
                    current.metadata().map(|m| m.name()),
                    current.id(),
                )
            })
            .await
            .unwrap()
        }
        .instrument(span.clone())
        .await;
        assert_ne!(seen.0, std::thread::current().name().map(str::to_string));
        assert_eq!(seen.1, Some("request"));
        assert_eq!(seen.2, span.id());
        // Outside the request, a job runs in no span.
        let outside = run(|| tracing::Span::current().is_none()).await.unwrap();
        assert!(outside);
    }

    /// A gate the jobs of [`hold_every_lane`] wait on until [`open`].
    type Gate = Arc<(Mutex<bool>, Condvar)>;

    /// Gives each of `lanes`' lanes a job that waits on the returned gate.
    fn hold_every_lane(lanes: &Lanes) -> Gate {
        let gate: Gate = Arc::new((Mutex::new(false), Condvar::new()));
        for _ in 0..lanes.started.len() {
            let gate = Arc::clone(&gate);
            lanes.push(Box::new(move || {
                let (open, cv) = &*gate;
                let mut o = open.lock().unwrap();
                while !*o {
                    o = cv.wait(o).unwrap();
                }
            }));
        }
        gate
    }

    /// Lets the gate's jobs end.
    fn open(gate: &Gate) {
        *gate.0.lock().unwrap() = true;
        gate.1.notify_all();
    }

    #[test]
    fn long_jobs_hold_their_lanes_and_new_work_goes_around_them() {
        // A private pool of two lanes, both given a job that waits on a
        // gate: once LONG_JOB has passed, both are held.
        let lanes = Lanes::start(2);
        let gate = hold_every_lane(&lanes);
        let deadline = Instant::now() + Duration::from_secs(10);
        while !lanes.all_held() {
            assert!(Instant::now() < deadline, "the lanes never counted as held");
            std::thread::sleep(LONG_JOB / 2);
        }
        open(&gate);
        while lanes.started.iter().any(|s| s.load(Ordering::Relaxed) != 0) {
            assert!(Instant::now() < deadline, "the lanes never finished");
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(!lanes.all_held());
    }

    #[tokio::test]
    async fn a_job_queued_before_the_lanes_were_held_goes_around_them() {
        // One lane, taken by a job that waits on a gate, and a small job
        // queued behind it as a request queues one while a lane is not yet
        // held. Before the lanes' watch, the small job waited in the queue
        // until the gate opened (here: never, the test's bound). Now, once
        // the lane counts as held (LONG_JOB), it is handed back to its
        // request and runs on the blocking pool.
        let lanes = Lanes::start(1);
        let gate = hold_every_lane(&lanes);
        let answered = tokio::time::timeout(Duration::from_secs(30), lanes.run_queued(|| 42)).await;
        // Admitted under a bound of none on the blocking pool, it is shed
        // (503) instead of waiting.
        let none = Arc::new(BlockingBound::new(0, "FUSION_MAX_BLOCKING_JOBS"));
        let shed = tokio::time::timeout(
            Duration::from_secs(30),
            admitted(Admitted::new((), none), lanes.run_queued(|| 7)),
        )
        .await;
        open(&gate);
        assert_eq!(
            answered
                .expect("the small job waited behind the long one")
                .unwrap(),
            42
        );
        let shed = shed.expect("the admitted job waited behind the long one");
        assert!(
            matches!(&shed, Err(ServiceError::Overloaded(m)) if m.contains("FUSION_MAX_BLOCKING_JOBS")),
            "{shed:?}"
        );
    }

    /// Polls `request` until its job says it started, then drops it (the
    /// request is abandoned while its job runs).
    async fn abandon_once_started<F: std::future::Future>(
        request: F,
        started: &std::sync::mpsc::Receiver<()>,
    ) {
        let mut request = std::pin::pin!(request);
        let deadline = Instant::now() + Duration::from_secs(60);
        loop {
            tokio::select! {
                _ = &mut request => panic!("the request was answered before it was abandoned"),
                () = tokio::time::sleep(Duration::from_millis(1)) => {}
            }
            if started.try_recv().is_ok() {
                return;
            }
            assert!(Instant::now() < deadline, "the job never started");
        }
    }

    #[tokio::test]
    async fn an_abandoned_request_stops_its_job_at_the_next_checkpoint() {
        // A job that would run for 100 s checks for cancellation every
        // millisecond; the request awaiting it gives up after 50 ms.
        let (tx, rx) = std::sync::mpsc::channel();
        let (started_tx, started_rx) = std::sync::mpsc::channel();
        let job = run(move || {
            started_tx.send(()).unwrap();
            for i in 0..100_000 {
                if let Err(e) = checkpoint() {
                    let _ = tx.send((i, e));
                    return;
                }
                std::thread::sleep(Duration::from_millis(1));
            }
        });
        abandon_once_started(job, &started_rx).await;
        // A generous bound against a hang, not a measure of speed.
        let (i, e) = rx
            .recv_timeout(Duration::from_secs(60))
            .expect("the job stopped at a checkpoint");
        assert!(i < 100_000);
        assert!(matches!(e, ServiceError::Cancelled));
        // Outside a job, and in a job nobody abandoned, a checkpoint passes.
        assert!(checkpoint().is_ok());
        assert!(run(checkpoint).await.unwrap().is_ok());
    }

    #[test]
    fn the_blocking_bound_refuses_past_its_limit_naming_the_setting() {
        let bound = Arc::new(BlockingBound::new(2, "FUSION_MAX_BLOCKING_JOBS"));
        let first = bound.take().unwrap();
        let _second = bound.take().unwrap();
        assert_eq!(bound.running(), 2);
        let Err(ServiceError::Overloaded(message)) = bound.take() else {
            panic!("a third job was taken");
        };
        assert!(
            message.contains("2 computations") && message.contains("FUSION_MAX_BLOCKING_JOBS"),
            "{message}"
        );
        drop(first);
        assert_eq!(bound.running(), 1);
        assert!(bound.take().is_ok());
    }

    #[tokio::test]
    async fn with_every_lane_held_an_admitted_job_over_the_bound_is_refused() {
        // Hold every lane of the process with a job that waits on a gate
        // (other tests' jobs go to the blocking pool meanwhile).
        let lanes = Lanes::global();
        let gate = hold_every_lane(lanes);
        let deadline = Instant::now() + Duration::from_secs(60);
        while !lanes.all_held() {
            assert!(Instant::now() < deadline, "the lanes never counted as held");
            tokio::time::sleep(LONG_JOB).await;
        }
        // Admitted under a bound of none on the blocking pool: refused.
        let bound = Arc::new(BlockingBound::new(0, "FUSION_MAX_BLOCKING_JOBS"));
        let refused = admitted(Admitted::new((), Arc::clone(&bound)), run(|| 1)).await;
        // Under a bound of one: it runs there, and gives its place back.
        let one = Arc::new(BlockingBound::new(1, "FUSION_MAX_BLOCKING_JOBS"));
        let ran = admitted(Admitted::new((), Arc::clone(&one)), run(|| 2)).await;
        open(&gate);
        assert!(
            matches!(&refused, Err(ServiceError::Overloaded(m)) if m.contains("FUSION_MAX_BLOCKING_JOBS")),
            "{refused:?}"
        );
        assert_eq!(ran.unwrap(), 2);
        // The job's place is given back as its thread lets go of it, which
        // can be just after its answer arrived (seen on a loaded machine).
        let deadline = Instant::now() + Duration::from_secs(10);
        while one.running() != 0 {
            assert!(Instant::now() < deadline, "the job kept its place");
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    }

    #[tokio::test]
    async fn an_admitted_request_holds_its_slot_until_its_job_ends() {
        // The slot is a semaphore permit: the request's future is dropped
        // at once, its job still runs and keeps the slot until it ends.
        let slots = Arc::new(tokio::sync::Semaphore::new(1));
        let permit = Arc::clone(&slots).try_acquire_owned().unwrap();
        let bound = Arc::new(BlockingBound::new(8, "FUSION_MAX_BLOCKING_JOBS"));
        let (started_tx, started_rx) = std::sync::mpsc::channel();
        let (finish_tx, finish_rx) = std::sync::mpsc::channel::<()>();
        let request = admitted(
            Admitted::new(permit, bound),
            run(move || {
                started_tx.send(()).unwrap();
                let _ = finish_rx.recv_timeout(Duration::from_secs(60));
            }),
        );
        abandon_once_started(request, &started_rx).await;
        assert_eq!(
            slots.available_permits(),
            0,
            "the running job holds the slot"
        );
        finish_tx.send(()).unwrap();
        let deadline = Instant::now() + Duration::from_secs(60);
        while slots.available_permits() == 0 {
            assert!(Instant::now() < deadline, "the slot was never given back");
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
    }

    #[test]
    fn a_lane_that_never_started_is_held_from_the_first_instant() {
        let lanes = Lanes::start(1);
        assert!(!lanes.all_held());
        lanes.started[0].store(NEVER_STARTED, Ordering::Relaxed);
        assert!(
            lanes.all_held(),
            "work would queue for a lane that never runs"
        );
    }
}
