//! REST routes of streaming sessions under `/v1/sessions`: every kind of
//! session is created, listed, read and deleted here; a batch goes to the
//! kind of its session (a correlation batch carries `reports`).

use axum::{
    Extension, Json,
    extract::{Path, State},
    http::{StatusCode, header},
    response::IntoResponse,
};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use super::{
    correlation::{
        Alignment, CorrelationMethod, MotionModel, PairResult, SystemTrack, TrackRef, TrackSample,
        config_in, finite, pair_result, sample_in, system_track, track_ref,
    },
    problem::{ApiJson, Problem},
};
use crate::{
    auth::Tenant,
    service::{
        correlation as corr,
        session::{
            Batch, KindName, Spec, Update, View,
            correlation::{self as domain, CorrelationSession, change_name},
            persist::AnyView,
        },
    },
    state::AppState,
};

/// A streaming session. `kind` names what it does (`correlation`, the
/// default: the batch correlation's configuration, the node ids, and the
/// session's own settings).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateSessionRequest {
    /// `correlation` (default).
    #[schema(example = "correlation")]
    pub kind: Option<String>,
    #[schema(example = json!(["x", "vx", "y", "vy"]))]
    pub state_layout: Vec<String>,
    pub method: CorrelationMethod,
    pub motion_model: Option<MotionModel>,
    /// `predict` (default with a motion model) or `nearest`; `tolerance_s` as
    /// in the batch endpoint.
    pub alignment: Option<Alignment>,
    pub measurement_matrix: Option<Vec<Vec<f64>>>,
    /// The ids of the radar nodes (at least two).
    #[schema(example = json!(["radar-1", "radar-2"]))]
    pub nodes: Vec<String>,
    pub pruning: Option<String>,
    pub fuse: Option<bool>,
    /// The session expires after this many seconds without a batch (default 3600).
    pub idle_expiry_s: Option<f64>,
    /// A track not reported for this long (data time, seconds) is retired and
    /// its pairs released (default 60).
    pub retire_after_s: Option<f64>,
    /// Instants kept for the replay of pairs that enter the gate late
    /// (default 32, at most 1024).
    pub history_instants: Option<u32>,
}

/// One batch of track reports.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PushBatchRequest {
    /// The client's sequence number: the first sequenced batch carries 1, each
    /// later one the previous + 1; a number already applied is acknowledged
    /// again without being applied (safe retries); one that skips ahead gets 409.
    pub sequence: Option<u64>,
    #[serde(default)]
    pub reports: Vec<TrackReport>,
    /// Close the open alignment instant now (default false: it closes when a
    /// report later than its start + tolerance arrives).
    #[serde(default)]
    pub flush: bool,
}

/// A local track's estimate at one time.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TrackReport {
    #[schema(example = "radar-1")]
    pub node: String,
    #[schema(example = "17")]
    pub track: String,
    /// Time in seconds.
    #[schema(example = 0.0)]
    pub t: f64,
    #[schema(example = json!([1000.0, 100.0, 2000.0, -50.0]))]
    pub state: Vec<f64>,
    /// Symmetric positive definite, row-major nested arrays.
    pub covariance: Vec<Vec<f64>>,
    /// The local filter's gain K (state × measurement), optional.
    pub gain: Option<Vec<Vec<f64>>>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct PairChange {
    pub a: TrackRef,
    pub b: TrackRef,
    /// `correlated`, `released`, `trial_formed` or `trial_ended`.
    pub change: &'static str,
}

/// What one batch changed.
#[derive(Debug, Serialize, ToSchema)]
pub struct BatchUpdate {
    pub session_id: String,
    pub sequence: Option<u64>,
    /// The session's version after the batch (for a duplicate: the session's
    /// current version).
    pub version: u64,
    /// True when the batch had been applied before and was not applied
    /// again. A retry of the last batch carries that batch's update again
    /// (changes, pairs, system tracks); an older one carries no changes.
    pub duplicate: bool,
    /// Instants closed and correlated by this batch.
    pub instants: Vec<f64>,
    pub pending_reports: u32,
    pub changes: Vec<PairChange>,
    /// Pairs whose quality counters moved in this batch.
    pub pairs: Vec<PairResult>,
    /// Every current system track, fused at its latest instant.
    pub system_tracks: Vec<SystemTrack>,
    pub retired: Vec<TrackRef>,
    pub warnings: Vec<String>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SessionTrack {
    pub id: String,
    pub last_t: Option<f64>,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SessionNode {
    pub id: String,
    pub tracks: Vec<SessionTrack>,
}

/// The whole state of a session.
#[derive(Debug, Serialize, ToSchema)]
pub struct SessionState {
    pub id: String,
    /// The session's kind: `correlation`.
    pub kind: &'static str,
    pub version: u64,
    pub created_unix_ms: u64,
    pub last_sequence: Option<u64>,
    pub batches: u64,
    pub instants_processed: u64,
    pub last_instant_t: Option<f64>,
    pub pending_reports: u32,
    pub reports_accepted: u64,
    pub reports_late: u64,
    pub idle_expiry_s: f64,
    pub retire_after_s: f64,
    pub history_instants: u32,
    pub method: String,
    pub nodes: Vec<SessionNode>,
    pub pairs: Vec<PairResult>,
    pub system_tracks: Vec<SystemTrack>,
    /// Size of the stored session.
    pub encoded_bytes: usize,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SessionSummary {
    pub id: String,
    /// The session's kind.
    pub kind: String,
    pub version: u64,
    pub encoded_bytes: usize,
    pub expires_in_s: f64,
}

#[derive(Debug, Serialize, ToSchema)]
pub struct SessionList {
    pub sessions: Vec<SessionSummary>,
}

fn correlation_spec_in(req: CreateSessionRequest) -> Spec<domain::SessionSpec> {
    let nodes = req
        .nodes
        .into_iter()
        .map(|id| corr::NodeInput {
            id: Some(id),
            tracks: Vec::new(),
        })
        .collect();
    Spec {
        idle_expiry_s: req.idle_expiry_s,
        body: domain::SessionSpec {
            config: config_in(
                req.state_layout,
                req.method,
                req.motion_model,
                req.alignment,
                req.measurement_matrix,
                nodes,
                req.pruning,
                req.fuse,
            ),
            retire_after_s: req.retire_after_s,
            history_instants: req.history_instants,
        },
    }
}

fn batch_in(req: PushBatchRequest) -> Batch<domain::BatchInput> {
    Batch {
        sequence: req.sequence,
        body: domain::BatchInput {
            flush: req.flush,
            reports: req
                .reports
                .into_iter()
                .map(|r| domain::ReportInput {
                    node: Some(r.node),
                    track: Some(r.track),
                    sample: sample_in(TrackSample {
                        t: r.t,
                        state: r.state,
                        covariance: r.covariance,
                        gain: r.gain,
                    }),
                })
                .collect(),
        },
    }
}

fn update_out(u: Update<domain::BatchUpdate>) -> BatchUpdate {
    let b = u.body;
    BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        instants: b.instants,
        pending_reports: b.pending_reports,
        changes: b
            .changes
            .into_iter()
            .map(|c| PairChange {
                a: track_ref(c.a),
                b: track_ref(c.b),
                change: change_name(c.change),
            })
            .collect(),
        pairs: b.pairs.into_iter().map(pair_result).collect(),
        system_tracks: b.system_tracks.into_iter().map(system_track).collect(),
        retired: b.retired.into_iter().map(track_ref).collect(),
        warnings: u.warnings,
    }
}

fn view_out(v: AnyView) -> SessionState {
    match v {
        AnyView::Correlation(v) => correlation_view_out(v),
    }
}

fn correlation_view_out(v: View<domain::SessionView>) -> SessionState {
    let b = v.body;
    SessionState {
        id: v.id,
        kind: v.kind,
        version: v.version,
        created_unix_ms: v.created_unix_ms,
        last_sequence: v.last_sequence,
        batches: v.batches,
        instants_processed: b.instants_processed,
        last_instant_t: b.last_instant.and_then(finite),
        pending_reports: b.pending_reports,
        reports_accepted: b.reports_accepted,
        reports_late: b.reports_late,
        idle_expiry_s: v.idle_expiry_s,
        retire_after_s: b.retire_after_s,
        history_instants: b.history_instants,
        method: b.method,
        nodes: b
            .nodes
            .into_iter()
            .map(|n| SessionNode {
                id: n.id,
                tracks: n
                    .tracks
                    .into_iter()
                    .map(|t| SessionTrack {
                        id: t.id,
                        last_t: t.last_t,
                    })
                    .collect(),
            })
            .collect(),
        pairs: b.pairs.into_iter().map(pair_result).collect(),
        system_tracks: b.system_tracks.into_iter().map(system_track).collect(),
        encoded_bytes: v.encoded_bytes,
    }
}

/// Creates a session.
#[utoipa::path(post, path = "/v1/sessions", tag = "sessions",
    request_body = CreateSessionRequest,
    responses(
        (status = 201, description = "Created; Location names the session", body = SessionState),
        (status = 422, description = "Invalid field values", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many sessions for the tenant", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn create(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    ApiJson(req): ApiJson<CreateSessionRequest>,
) -> Result<impl IntoResponse, Problem> {
    let view = match KindName::parse(req.kind.as_deref(), "kind")? {
        KindName::Correlation => AnyView::Correlation(
            state
                .sessions()
                .create::<CorrelationSession>(&tenant.0, correlation_spec_in(req))
                .await?,
        ),
    };
    let view = view_out(view);
    let location = format!("/v1/sessions/{}", view.id);
    Ok((
        StatusCode::CREATED,
        [(header::LOCATION, location)],
        Json(view),
    ))
}

/// Lists the tenant's sessions.
#[utoipa::path(get, path = "/v1/sessions", tag = "sessions",
    responses(
        (status = 200, description = "The tenant's live sessions", body = SessionList),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn list(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
) -> Result<Json<SessionList>, Problem> {
    let metas = state.sessions().list(&tenant.0).await?;
    Ok(Json(SessionList {
        sessions: metas
            .into_iter()
            .map(|m| SessionSummary {
                id: m.id,
                kind: m.kind,
                version: m.version,
                encoded_bytes: m.bytes,
                expires_in_s: m.ttl_remaining.as_secs_f64(),
            })
            .collect(),
    }))
}

/// Reads a session's whole state.
#[utoipa::path(get, path = "/v1/sessions/{id}", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    responses(
        (status = 200, description = "The session", body = SessionState),
        (status = 404, description = "No such session for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn get(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
) -> Result<Json<SessionState>, Problem> {
    let view = state.sessions().get(&tenant.0, &id).await?;
    Ok(Json(view_out(view)))
}

/// Deletes a session.
#[utoipa::path(delete, path = "/v1/sessions/{id}", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such session for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn delete(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
) -> Result<StatusCode, Problem> {
    state.sessions().delete(&tenant.0, &id).await?;
    Ok(StatusCode::NO_CONTENT)
}

/// Pushes a batch of track reports; answers what changed.
#[utoipa::path(post, path = "/v1/sessions/{id}/batches", tag = "sessions",
    params(("id" = String, Path, description = "Session id")),
    request_body = PushBatchRequest,
    responses(
        (status = 200, description = "Applied (or acknowledged again: `duplicate`)", body = BatchUpdate),
        (status = 404, description = "No such session for this tenant", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The sequence number skips ahead", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Too many reports in the batch", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "Invalid reports, or a batch of another kind than the session's", body = Problem, content_type = "application/problem+json"),
        (status = 429, description = "Too many tracks in the session", body = Problem, content_type = "application/problem+json"),
        (status = 503, description = "Session store unreachable", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn push(
    State(state): State<AppState>,
    Extension(tenant): Extension<Tenant>,
    Path(id): Path<String>,
    ApiJson(req): ApiJson<PushBatchRequest>,
) -> Result<Json<BatchUpdate>, Problem> {
    let limits = state.settings().session_limits();
    let update = state
        .sessions()
        .push::<CorrelationSession>(&tenant.0, &id, batch_in(req), limits)
        .await?;
    Ok(Json(update_out(update)))
}
