//! Operational routes: liveness, readiness and Prometheus metrics. They are
//! served outside the in-flight limit so that probes answer under load.

use axum::{
    Json,
    extract::State,
    http::{StatusCode, header},
    response::IntoResponse,
};
use serde::Serialize;
use utoipa::ToSchema;

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
    Json(HealthStatus {
        status: "ok",
        reason: None,
        store: None,
    })
}

/// The session store's health, for monitoring (not for rotation: every
/// replica shares the store, and the stateless endpoints work without it).
#[utoipa::path(get, path = "/healthz/store", tag = "operations",
    responses(
        (status = 200, description = "The session store answers", body = HealthStatus),
        (status = 503, description = "The session store is unreachable", body = HealthStatus)))]
pub async fn store_health(State(state): State<AppState>) -> (StatusCode, Json<HealthStatus>) {
    match state.check_store().await {
        StoreHealth::Ok => (
            StatusCode::OK,
            Json(HealthStatus {
                status: "ok",
                reason: None,
                store: None,
            }),
        ),
        StoreHealth::Degraded => (
            StatusCode::SERVICE_UNAVAILABLE,
            Json(HealthStatus {
                status: "degraded",
                reason: Some(STORE_DOWN),
                store: None,
            }),
        ),
    }
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
            Json(HealthStatus {
                status: "ready",
                reason: (store == StoreHealth::Degraded).then_some(STORE_DOWN),
                store: Some(store_word(store)),
            }),
        ),
        Readiness::NotReady(reason) => (
            StatusCode::SERVICE_UNAVAILABLE,
            Json(HealthStatus {
                status: "not_ready",
                reason: Some(reason),
                store: None,
            }),
        ),
    }
}

/// Prometheus metrics: request counts and latency histograms per route and per gRPC method.
#[utoipa::path(get, path = "/metrics", tag = "operations",
    responses((status = 200, description = "Prometheus text format", body = String, content_type = "text/plain")))]
pub async fn metrics(State(state): State<AppState>) -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "text/plain; version=0.0.4")],
        state.metrics().render(),
    )
}
