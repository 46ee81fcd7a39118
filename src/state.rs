//! The state shared by both adapters: settings, the API keys, readiness, the
//! in-flight limit, the budget of request-body bytes buffered before
//! admission, the metrics handle and the session store. One `AppState` is built at start-up and cloned
//! (cheaply, it is an `Arc`) into every server.

use std::sync::{
    Arc,
    atomic::{AtomicBool, Ordering},
};

use metrics_exporter_prometheus::PrometheusHandle;
use service::lanes::{Admitted, BlockingBound};
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::{auth::ApiKeys, config::Settings};
use service::session::persist::{Sessions, SnapshotPolicy};
use store::SessionStore;

#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    settings: Settings,
    api_keys: ApiKeys,
    ready: AtomicBool,
    in_flight: Arc<Semaphore>,
    blocking: Arc<BlockingBound>,
    body_budget: BodyBudget,
    metrics: PrometheusHandle,
    sessions: Sessions,
}

impl AppState {
    pub fn new(
        settings: Settings,
        api_keys: ApiKeys,
        metrics: PrometheusHandle,
        store: SessionStore,
    ) -> Self {
        let sessions = Sessions::with_watch_limits(
            store,
            settings.session_cache_bytes,
            settings.watch_limits(),
        )
        .with_snapshots(SnapshotPolicy {
            max_entries: settings.session_snapshot_batches,
            max_replay_s: settings.session_snapshot_replay_s,
            ..SnapshotPolicy::default()
        });
        let in_flight = Arc::new(Semaphore::new(settings.max_in_flight));
        let body_budget = BodyBudget::new(settings.max_buffered_body_bytes);
        let blocking = Arc::new(BlockingBound::new(
            settings.max_blocking_jobs,
            "FUSION_MAX_BLOCKING_JOBS",
        ));
        Self {
            inner: Arc::new(Inner {
                settings,
                api_keys,
                ready: AtomicBool::new(false),
                in_flight,
                blocking,
                body_budget,
                metrics,
                sessions,
            }),
        }
    }

    /// A state over `settings` with their API keys and a memory store (for
    /// unit tests of the adapters).
    #[cfg(test)]
    pub(crate) fn for_tests(settings: Settings) -> Self {
        let api_keys = ApiKeys::from_settings(&settings).expect("test API keys");
        let store =
            SessionStore::Memory(store::memory::MemoryStore::new(&settings.store_settings()));
        Self::new(
            settings,
            api_keys,
            crate::telemetry::metrics_handle(),
            store,
        )
    }

    pub fn settings(&self) -> &Settings {
        &self.inner.settings
    }

    /// The API keys both adapters authenticate requests with.
    pub fn api_keys(&self) -> &ApiKeys {
        &self.inner.api_keys
    }

    /// Whether the service is started and not draining. Readiness for traffic
    /// (`/readyz`, gRPC health) also needs the session store: [`Self::check_ready`].
    pub fn is_ready(&self) -> bool {
        self.inner.ready.load(Ordering::Acquire)
    }

    pub fn set_ready(&self, ready: bool) {
        self.inner.ready.store(ready, Ordering::Release);
    }

    /// A slot for one API request, or `None` when `max_in_flight` requests are
    /// being served already: the caller sheds the request instead of queueing it.
    /// The caller serves the request under [`service::lanes::admitted`], so
    /// that the slot is given back only once the request and every
    /// computation it queued have finished (a request that timed out keeps
    /// it until its computation has stopped), and its computations on the
    /// blocking pool are bounded by `max_blocking_jobs`.
    pub fn try_admit(&self) -> Option<Admitted> {
        let permit = self.inner.in_flight.clone().try_acquire_owned().ok()?;
        Some(Admitted::new(permit, Arc::clone(&self.inner.blocking)))
    }

    /// Computations of this service on tokio's blocking pool now.
    pub fn blocking_jobs(&self) -> usize {
        self.inner.blocking.running()
    }

    /// Reads a request body whole, within `limit` bytes (after any
    /// decompression layer in front), the body-read timeout
    /// (`FUSION_BODY_READ_TIMEOUT_S`) and the global budget of buffered
    /// body bytes (`FUSION_MAX_BUFFERED_BODY_BYTES`): both adapters call it
    /// before a request takes an in-flight slot, so a slow or withholding
    /// client holds none, and all the bodies being read at once hold at
    /// most the budget. The bytes stay charged to the budget until the
    /// returned [`BodyCharge`] is dropped (the caller keeps it while the
    /// request is served, since the body lives as long). A timeout is
    /// counted in `requests_slow_body_total`, a body refused for the budget
    /// in `request_bodies_over_budget_total`.
    pub async fn read_body(
        &self,
        body: axum::body::Body,
        limit: usize,
    ) -> Result<(axum::body::Bytes, BodyCharge), BodyReadError> {
        let read = self.inner.body_budget.read(body, limit);
        match tokio::time::timeout(self.settings().body_read_timeout(), read).await {
            Ok(Ok(read)) => Ok(read),
            Ok(Err(e)) => {
                if matches!(e, BodyReadError::OverBudget) {
                    metrics::counter!("request_bodies_over_budget_total").increment(1);
                }
                Err(e)
            }
            Err(_) => {
                metrics::counter!("requests_slow_body_total").increment(1);
                Err(BodyReadError::TimedOut)
            }
        }
    }

    /// Request-body bytes buffered now (charged to the budget of
    /// `FUSION_MAX_BUFFERED_BODY_BYTES`).
    pub fn buffered_body_bytes(&self) -> usize {
        self.inner.body_budget.charged()
    }

    /// Charges `n` more bytes of a body to the budget, into `charge`;
    /// false (nothing charged) when the budget cannot take them. For bodies
    /// read piecemeal (the messages of a gRPC stream) rather than by
    /// [`Self::read_body`].
    pub fn charge_body_bytes(&self, charge: &mut BodyCharge, n: usize) -> bool {
        let charged = self.inner.body_budget.charge(charge, n).is_ok();
        if !charged {
            metrics::counter!("request_bodies_over_budget_total").increment(1);
        }
        charged
    }

    pub fn metrics(&self) -> &PrometheusHandle {
        &self.inner.metrics
    }

    /// Where streaming sessions keep their state.
    pub fn store(&self) -> &SessionStore {
        self.inner.sessions.store()
    }

    /// The sessions of every kind: the store and the cache of decoded
    /// sessions in front of it.
    pub fn sessions(&self) -> &Sessions {
        &self.inner.sessions
    }

    /// Whether the service should receive traffic now: started and not
    /// draining. The session store's health is reported beside it and does
    /// not take the replica out of rotation: every stateless endpoint still
    /// works during a store outage, and every replica shares the store.
    pub async fn check_ready(&self) -> Readiness {
        if !self.is_ready() {
            return Readiness::NotReady("starting or shutting down");
        }
        Readiness::Ready {
            store: self.check_store().await,
        }
    }

    /// Whether the session store answers a ping (within the store timeout).
    pub async fn check_store(&self) -> StoreHealth {
        match self.store().ping().await {
            Ok(()) => StoreHealth::Ok,
            Err(e) => {
                // Probes ask often: the change is logged by `app`.
                tracing::debug!(error = %e, backend = self.store().backend(), "session store ping failed");
                StoreHealth::Degraded
            }
        }
    }
}

/// The session store's health.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreHealth {
    Ok,
    /// Unreachable: session calls fail with 503, everything else works.
    Degraded,
}

/// The answer of [`AppState::check_ready`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Readiness {
    /// In rotation, with the store's health.
    Ready { store: StoreHealth },
    /// Not ready, with a reason safe to show to a probe.
    NotReady(&'static str),
}

/// Why a request body could not be read whole ([`AppState::read_body`]).
#[derive(Debug)]
pub enum BodyReadError {
    /// Over the limit (decompressed, when the body was compressed).
    TooLarge,
    /// The bodies being read hold the whole budget of buffered bytes
    /// (`FUSION_MAX_BUFFERED_BODY_BYTES`): the request is shed.
    OverBudget,
    /// It does not decompress as its `Content-Encoding` says.
    Undecodable(std::io::Error),
    /// The connection failed mid-body.
    Failed(String),
    /// Not complete within the body-read timeout.
    TimedOut,
}

impl BodyReadError {
    fn classify(e: &axum::Error) -> Self {
        let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
        while let Some(err) = source {
            if let Some(io) = err.downcast_ref::<std::io::Error>()
                && matches!(
                    io.kind(),
                    std::io::ErrorKind::InvalidData | std::io::ErrorKind::UnexpectedEof
                )
            {
                return Self::Undecodable(std::io::Error::new(io.kind(), io.to_string()));
            }
            source = err.source();
        }
        Self::Failed(e.to_string())
    }
}

/// The global budget of request-body bytes buffered by requests not yet
/// answered: a semaphore whose permits are bytes. A body takes permits for
/// each chunk as it arrives (decompressed, when it was compressed) and
/// never waits for them: a chunk that does not fit sheds its request.
#[derive(Clone)]
struct BodyBudget {
    bytes: Arc<Semaphore>,
    total: usize,
}

/// Bytes of one request's body charged to the budget; given back when
/// dropped.
#[must_use = "the bytes are given back to the budget when this is dropped"]
#[derive(Default)]
pub struct BodyCharge(Option<OwnedSemaphorePermit>);

impl BodyBudget {
    fn new(total: usize) -> Self {
        let total = total.min(Semaphore::MAX_PERMITS);
        Self {
            bytes: Arc::new(Semaphore::new(total)),
            total,
        }
    }

    fn charged(&self) -> usize {
        self.total - self.bytes.available_permits()
    }

    /// Adds `n` bytes to `charge`, or [`BodyReadError::OverBudget`] (and
    /// nothing charged) when the budget cannot take them now.
    fn charge(&self, charge: &mut BodyCharge, n: usize) -> Result<(), BodyReadError> {
        let n = u32::try_from(n).map_err(|_| BodyReadError::OverBudget)?;
        let permit = self
            .bytes
            .clone()
            .try_acquire_many_owned(n)
            .map_err(|_| BodyReadError::OverBudget)?;
        match &mut charge.0 {
            Some(held) => held.merge(permit),
            None => charge.0 = Some(permit),
        }
        Ok(())
    }

    /// Reads `body` whole, each chunk charged before it is kept: more than
    /// `limit` bytes is [`BodyReadError::TooLarge`] (whatever the budget
    /// holds), a chunk the budget cannot take [`BodyReadError::OverBudget`];
    /// either way what was read is dropped and given back at once.
    async fn read(
        &self,
        body: axum::body::Body,
        limit: usize,
    ) -> Result<(axum::body::Bytes, BodyCharge), BodyReadError> {
        use http_body_util::BodyExt;
        let mut body = std::pin::pin!(body);
        let mut chunks: Vec<axum::body::Bytes> = Vec::new();
        let mut len = 0usize;
        let mut charge = BodyCharge::default();
        while let Some(frame) = body.frame().await {
            let frame = frame.map_err(|e| BodyReadError::classify(&e))?;
            let Ok(chunk) = frame.into_data() else {
                continue; // trailers: not part of the body
            };
            if chunk.is_empty() {
                continue;
            }
            len = len.saturating_add(chunk.len());
            if len > limit {
                return Err(BodyReadError::TooLarge);
            }
            self.charge(&mut charge, chunk.len())?;
            chunks.push(chunk);
        }
        let bytes = match chunks.len() {
            0 => axum::body::Bytes::new(),
            1 => chunks.pop().expect("one chunk"),
            _ => {
                // One contiguous copy for the parsers; the chunks it is made
                // of are freed at once, so a whole body is held twice only
                // for the moment of the copy.
                let mut whole = Vec::with_capacity(len);
                for chunk in chunks {
                    whole.extend_from_slice(&chunk);
                }
                axum::body::Bytes::from(whole)
            }
        };
        Ok((bytes, charge))
    }
}
