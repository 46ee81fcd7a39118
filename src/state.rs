//! The state shared by both adapters: settings, the API keys, readiness, the
//! in-flight limit and the metrics handle. One `AppState` is built at start-up and cloned
//! (cheaply, it is an `Arc`) into every server.

use std::sync::{
    Arc,
    atomic::{AtomicBool, Ordering},
};

use metrics_exporter_prometheus::PrometheusHandle;
use tokio::sync::{OwnedSemaphorePermit, Semaphore};

use crate::{auth::ApiKeys, config::Settings};

#[derive(Clone)]
pub struct AppState {
    inner: Arc<Inner>,
}

struct Inner {
    settings: Settings,
    api_keys: ApiKeys,
    ready: AtomicBool,
    in_flight: Arc<Semaphore>,
    metrics: PrometheusHandle,
}

impl AppState {
    pub fn new(settings: Settings, api_keys: ApiKeys, metrics: PrometheusHandle) -> Self {
        let in_flight = Arc::new(Semaphore::new(settings.max_in_flight));
        Self {
            inner: Arc::new(Inner {
                settings,
                api_keys,
                ready: AtomicBool::new(false),
                in_flight,
                metrics,
            }),
        }
    }

    pub fn settings(&self) -> &Settings {
        &self.inner.settings
    }

    /// The API keys both adapters authenticate requests with.
    pub fn api_keys(&self) -> &ApiKeys {
        &self.inner.api_keys
    }

    /// Whether the service should receive traffic (`/readyz`, gRPC health).
    pub fn is_ready(&self) -> bool {
        self.inner.ready.load(Ordering::Acquire)
    }

    pub fn set_ready(&self, ready: bool) {
        self.inner.ready.store(ready, Ordering::Release);
    }

    /// A slot for one API request, or `None` when `max_in_flight` requests are
    /// being served already: the caller sheds the request instead of queueing it.
    pub fn try_admit(&self) -> Option<OwnedSemaphorePermit> {
        self.inner.in_flight.clone().try_acquire_owned().ok()
    }

    pub fn metrics(&self) -> &PrometheusHandle {
        &self.inner.metrics
    }
}
