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
//! So a 10 s request delays nobody by more than [`LONG_JOB`] per lane, and
//! small requests never wait behind large ones.

use std::{
    collections::VecDeque,
    panic::{AssertUnwindSafe, catch_unwind},
    sync::{
        Arc, Condvar, Mutex, OnceLock,
        atomic::{AtomicU64, Ordering},
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
    let context = Context::current();
    let lanes = Lanes::global();
    if lanes.all_held() {
        metrics::counter!("compute_jobs_total", "lane" => "blocking_pool").increment(1);
        return tokio::task::spawn_blocking(move || context.in_job(work))
            .await
            .map_err(|e| ServiceError::Internal(format!("compute task failed: {e}")));
    }
    metrics::counter!("compute_jobs_total", "lane" => "compute").increment(1);
    let (tx, rx) = tokio::sync::oneshot::channel();
    lanes.push(Box::new(move || {
        let _ = tx.send(context.in_job(work));
    }));
    rx.await
        .map_err(|_| ServiceError::Internal("compute task failed (it panicked)".into()))
}

thread_local! {
    /// Whether this thread is running a job of [`run`].
    static IN_JOB: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// What a job takes along from the request that queued it: the log
/// subscriber and the request's span (its `request_id`), so that a line
/// logged on a lane names the request as one logged on the async worker
/// does.
struct Context {
    dispatch: tracing::Dispatch,
    span: tracing::Span,
}

impl Context {
    fn current() -> Self {
        Self {
            dispatch: tracing::dispatcher::get_default(Clone::clone),
            span: tracing::Span::current(),
        }
    }

    /// Runs `work` in the request's span, marked as a job of [`run`] (the
    /// mark is cleared again on the way out, by unwinding too).
    fn in_job<T>(self, work: impl FnOnce() -> T) -> T {
        struct Clear;
        impl Drop for Clear {
            fn drop(&mut self) {
                IN_JOB.set(false);
            }
        }
        tracing::dispatcher::with_default(&self.dispatch, || {
            let _entered = self.span.enter();
            IN_JOB.set(true);
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

/// The process's lanes: one thread per available core, started on first use.
struct Lanes {
    queue: Mutex<Queue>,
    ready: Condvar,
    /// Per lane: nanoseconds since `epoch` when its current job started
    /// (plus one, so that 0 means idle).
    started: Vec<AtomicU64>,
    epoch: Instant,
}

#[derive(Default)]
struct Queue {
    jobs: VecDeque<Job>,
    /// Lanes waiting on `ready`.
    idle: usize,
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
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
            started: (0..n).map(|_| AtomicU64::new(0)).collect(),
            epoch: Instant::now(),
        });
        for i in 0..n {
            let lane = Arc::clone(&lanes);
            let started = std::thread::Builder::new()
                .name(format!("compute-{i}"))
                .spawn(move || lane.run(i));
            if let Err(e) = started {
                // A lane that could not start counts as held for ever:
                // work goes to the others, or to the blocking pool when
                // none started.
                tracing::error!(lane = i, error = %e, "a compute lane could not start");
                lanes.started[i].store(NEVER_STARTED, Ordering::Relaxed);
            }
        }
        lanes
    }

    fn now(&self) -> u64 {
        u64::try_from(self.epoch.elapsed().as_nanos()).unwrap_or(NEVER_STARTED - 2) + 1
    }

    /// Whether every lane is running a job that started over `LONG_JOB` ago.
    fn all_held(&self) -> bool {
        let now = self.now();
        let long = LONG_JOB.as_nanos() as u64;
        self.started.iter().all(|s| {
            let t = s.load(Ordering::Relaxed);
            t == NEVER_STARTED || (t != 0 && now.saturating_sub(t) > long)
        })
    }

    fn push(&self, job: Job) {
        let wake = {
            let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
            q.jobs.push_back(job);
            q.idle > 0
        };
        if wake {
            self.ready.notify_one();
        }
    }

    fn run(&self, lane: usize) {
        loop {
            let job = {
                let mut q = self.queue.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    if let Some(job) = q.jobs.pop_front() {
                        break job;
                    }
                    q.idle += 1;
                    q = self.ready.wait(q).unwrap_or_else(|e| e.into_inner());
                    q.idle -= 1;
                }
            };
            self.started[lane].store(self.now(), Ordering::Relaxed);
            // The job reports its own result; a panic drops its sender,
            // which the waiting request reads as an internal error.
            let _ = catch_unwind(AssertUnwindSafe(job));
            self.started[lane].store(0, Ordering::Relaxed);
        }
    }
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
        let r = catch_unwind(|| Context::current().in_job::<()>(|| panic!("boom")));
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

    #[test]
    fn long_jobs_hold_their_lanes_and_new_work_goes_around_them() {
        // A private pool of two lanes, both given a job that waits on a
        // gate: once LONG_JOB has passed, both are held.
        let lanes = Lanes::start(2);
        let gate = Arc::new((Mutex::new(false), Condvar::new()));
        for _ in 0..2 {
            let gate = Arc::clone(&gate);
            lanes.push(Box::new(move || {
                let (open, cv) = &*gate;
                let mut o = open.lock().unwrap();
                while !*o {
                    o = cv.wait(o).unwrap();
                }
            }));
        }
        let deadline = Instant::now() + Duration::from_secs(10);
        while !lanes.all_held() {
            assert!(Instant::now() < deadline, "the lanes never counted as held");
            std::thread::sleep(LONG_JOB / 2);
        }
        *gate.0.lock().unwrap() = true;
        gate.1.notify_all();
        while lanes.started.iter().any(|s| s.load(Ordering::Relaxed) != 0) {
            assert!(Instant::now() < deadline, "the lanes never finished");
            std::thread::sleep(Duration::from_millis(1));
        }
        assert!(!lanes.all_held());
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
