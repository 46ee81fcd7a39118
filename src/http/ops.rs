//! Operational routes: liveness, readiness and Prometheus metrics. They are
//! served outside the in-flight limit so that probes answer under load.
//! The probes need no key and say nothing of the deployment (no host);
//! `/metrics`, which names every tenant's sessions and radars, needs a key
//! when keys are configured ([`ApiKeys::authorize_metrics`]).

use axum::{
    Extension, Json,
    extract::State,
    http::{HeaderMap, StatusCode, header},
    response::{IntoResponse, Response},
};
use serde::Serialize;
use utoipa::ToSchema;

#[cfg(doc)]
use crate::auth::ApiKeys;
use crate::auth::{AuthError, CertTenant};
use crate::http::problem;
use crate::state::{AppState, Readiness, StoreHealth};

#[derive(Debug, Serialize, ToSchema)]
pub struct HealthStatus {
    /// `ok`, `ready`, `not_ready` or (`/healthz/store`) `degraded`.
    #[schema(example = "ok")]
    pub status: &'static str,
    /// Why the service is not ready or degraded.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(example = "starting or shutting down")]
    pub reason: Option<&'static str>,
    /// `/readyz`: the session store, `ok` or `degraded` (sessions answer 503
    /// while it is; every other endpoint works).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(example = "ok")]
    pub store: Option<&'static str>,
    /// `/healthz/store` and `/readyz` with Redis: whether the store lost its
    /// primary and has not completed a command since (a Sentinel failover
    /// being followed). No host is named: the probes need no key.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failing_over: Option<bool>,
}

impl HealthStatus {
    fn new(
        status: &'static str,
        reason: Option<&'static str>,
        store: Option<&'static str>,
    ) -> Self {
        Self {
            status,
            reason,
            store,
            failing_over: None,
        }
    }

    /// With the Redis store's failover state (read after the check, so it
    /// describes its outcome).
    fn with_topology(mut self, state: &AppState) -> Self {
        if let Some(t) = state.store().topology() {
            self.failing_over = Some(t.failing_over);
        }
        self
    }
}

const STORE_DOWN: &str = "session store unavailable";

fn store_word(h: StoreHealth) -> &'static str {
    match h {
        StoreHealth::Ok => "ok",
        StoreHealth::Degraded => "degraded",
    }
}

/// Liveness: the process is up and serving.
#[utoipa::path(get, path = "/healthz", tag = "operations",
    responses((status = 200, description = "Alive", body = HealthStatus)))]
pub async fn healthz() -> Json<HealthStatus> {
    Json(HealthStatus::new("ok", None, None))
}

/// The session store's health, for monitoring (not for rotation: every
/// replica shares the store, and the stateless endpoints work without it).
#[utoipa::path(get, path = "/healthz/store", tag = "operations",
    responses(
        (status = 200, description = "The session store answers", body = HealthStatus),
        (status = 503, description = "The session store is unreachable", body = HealthStatus)))]
pub async fn store_health(State(state): State<AppState>) -> (StatusCode, Json<HealthStatus>) {
    let (code, status) = match state.check_store().await {
        StoreHealth::Ok => (StatusCode::OK, HealthStatus::new("ok", None, None)),
        StoreHealth::Degraded => (
            StatusCode::SERVICE_UNAVAILABLE,
            HealthStatus::new("degraded", Some(STORE_DOWN), None),
        ),
    };
    (code, Json(status.with_topology(&state)))
}

/// Readiness: the service accepts traffic (not while starting or draining).
/// A session store outage does not take a replica out of rotation (every
/// stateless endpoint still works, and every replica shares the store): it
/// is reported as `store: degraded` beside a 200.
#[utoipa::path(get, path = "/readyz", tag = "operations",
    responses(
        (status = 200, description = "Ready", body = HealthStatus),
        (status = 503, description = "Not ready", body = HealthStatus)))]
pub async fn readyz(State(state): State<AppState>) -> (StatusCode, Json<HealthStatus>) {
    match state.check_ready().await {
        Readiness::Ready { store } => (
            StatusCode::OK,
            Json(
                HealthStatus::new(
                    "ready",
                    (store == StoreHealth::Degraded).then_some(STORE_DOWN),
                    Some(store_word(store)),
                )
                .with_topology(&state),
            ),
        ),
        Readiness::NotReady(reason) => (
            StatusCode::SERVICE_UNAVAILABLE,
            Json(HealthStatus::new("not_ready", Some(reason), None)),
        ),
    }
}

/// Prometheus metrics: request counts and latency histograms per route and per gRPC method.
///
/// With Redis behind Sentinel, also the store's failovers and redirections.
/// Per plot-fusion session this replica pushed to in the last 15 minutes,
/// each radar's registration: `fusion_session_radar_*` gauges labelled by
/// tenant, session and radar. They name every tenant's sessions, so with
/// `FUSION_METRICS_KEY` set this needs `Authorization: Bearer` that key,
/// and otherwise, with API keys configured, what a `/v1/` request needs:
/// any tenant's key or a client certificate standing for a tenant (401
/// without).
#[utoipa::path(get, path = "/metrics", tag = "operations",
    responses(
        (status = 200, description = "Prometheus text format", body = String, content_type = "text/plain"),
        (status = 401, description = "A key is configured and the request has none of the keys /metrics takes", body = crate::http::problem::Problem, content_type = "application/problem+json")))]
pub async fn metrics(
    State(state): State<AppState>,
    cert: Option<Extension<CertTenant>>,
    headers: HeaderMap,
) -> Response {
    let authorization = headers
        .get(header::AUTHORIZATION)
        .map(|v| v.to_str().unwrap_or(""));
    if let Err(error) = state
        .api_keys()
        .authorize_metrics(cert.as_deref(), authorization)
    {
        metrics::counter!("auth_failures_total", "transport" => "http").increment(1);
        return match error {
            AuthError::TenantMismatch => problem::forbidden(error),
            AuthError::Missing | AuthError::Malformed | AuthError::UnknownKey => {
                problem::unauthenticated(error)
            }
        };
    }
    if let Some(t) = state.store().topology() {
        // The store counts; the exporter shows the counts as of this scrape.
        metrics::counter!("session_store_failovers_total").absolute(t.failovers);
        metrics::counter!("session_store_redirections_total").absolute(t.redirections);
        metrics::gauge!("session_store_failing_over").set(if t.failing_over { 1.0 } else { 0.0 });
    }
    let mut text = state.metrics().render();
    text.push_str(&state.sessions().gauges().render());
    ([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], text).into_response()
}
