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
    plot_fusion::{
        AsterixIn, AsterixSummary, Cat062Options, FusedTrack, GeoPoint, NmeaIn, PlotIn, PlotRadar,
        RadarBiasOut, ReportIn, TrackerCounters, TrackerOptions, accuracy_out, asterix_in,
        asterix_out, bias_out, cat062_out, counters_out, nmea_in, plots_in, spec_in, track_out,
    },
    problem::{ApiJson, Problem},
};
use crate::{auth::Tenant, state::AppState};
use service::{
    Rows, ServiceError, Violations, correlation as corr,
    session::{
        Batch, Spec, Update, View,
        correlation::{self as domain, CorrelationSession, change_name},
        plot_fusion::{self as pf, PlotFusionSession, track_change_name},
        registry::{AnyView, KindName, refuse_foreign_fields},
    },
};

/// A streaming session. `kind` names what it does: `correlation` (the
/// default: the batch correlation's configuration, the node ids, and the
/// session's own settings) or `plot_fusion` (the plot-fusion tracker's
/// `origin`, `radars` and `tracker`, as in `POST /v1/plot-fusion/track`).
/// Fields of the other kind are refused.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateSessionRequest {
    /// `correlation` (default) or `plot_fusion`.
    #[schema(example = "correlation")]
    pub kind: Option<String>,
    /// Correlation sessions.
    #[schema(example = json!(["x", "vx", "y", "vy"]))]
    #[serde(default)]
    pub state_layout: Vec<String>,
    /// Correlation sessions: required.
    pub method: Option<CorrelationMethod>,
    pub motion_model: Option<MotionModel>,
    /// `predict` (default with a motion model) or `nearest`; `tolerance_s` as
    /// in the batch endpoint.
    pub alignment: Option<Alignment>,
    pub measurement_matrix: Option<Vec<Vec<f64>>>,
    /// Correlation sessions: the ids of the radar nodes (at least two).
    #[schema(example = json!(["radar-1", "radar-2"]))]
    #[serde(default)]
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
    #[schema(minimum = 1, maximum = 1024)]
    pub history_instants: Option<u32>,
    /// Plot-fusion sessions: the fusion centre (see the batch endpoint).
    pub origin: Option<GeoPoint>,
    /// Plot-fusion sessions: the radars (required).
    pub radars: Option<Vec<PlotRadar>>,
    /// Plot-fusion sessions: the tracker's options.
    pub tracker: Option<TrackerOptions>,
    /// Plot-fusion sessions: each update also carries its tracks as CAT062
    /// records (see the batch endpoint's `cat062`).
    pub cat062: Option<Cat062Options>,
}

/// One batch of track reports.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct PushBatchRequest {
    /// The client's sequence number: the first sequenced batch carries 1, each
    /// later one the previous + 1; a number already applied is acknowledged
    /// again without being applied (safe retries); one that skips ahead gets 409.
    pub sequence: Option<u64>,
    /// Correlation sessions: track reports.
    #[serde(default)]
    pub reports: Vec<TrackReport>,
    /// Plot-fusion sessions: radar plots, in any order.
    #[serde(default)]
    pub plots: Vec<PlotIn>,
    /// Plot-fusion sessions: cooperative reports (ADS-B, multilateration,
    /// AIS), in any order.
    #[serde(default)]
    pub cooperative: Vec<ReportIn>,
    /// Plot-fusion sessions: raw ASTERIX (its plots follow `plots`). Without
    /// `date`/`day_start_t` the times of day are taken nearest the session's
    /// last processed frame.
    pub asterix: Option<AsterixIn>,
    /// Plot-fusion sessions: AIS over NMEA 0183 (its reports follow the
    /// ASTERIX plots).
    pub nmea: Option<NmeaIn>,
    /// Close the open alignment instant (correlation) or frame (plot
    /// fusion) now. Default false: it closes when a later report or plot
    /// arrives.
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
    #[schema(value_type = Vec<Vec<f64>>)]
    pub covariance: Rows,
    /// The local filter's gain K (state × measurement), optional.
    #[schema(value_type = Option<Vec<Vec<f64>>>)]
    pub gain: Option<Rows>,
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
    /// Correlation: instants closed and correlated by this batch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instants: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pending_reports: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub changes: Option<Vec<PairChange>>,
    /// Correlation: pairs whose quality counters moved in this batch.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<PairResult>>,
    /// Correlation: every current system track, fused at its latest instant.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub system_tracks: Option<Vec<SystemTrack>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub retired: Option<Vec<TrackRef>>,
    /// Plot-fusion sessions: what the batch did to the tracks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plot_fusion: Option<PlotFusionBatchUpdate>,
    pub warnings: Vec<String>,
}

/// A track a plot-fusion batch touched.
#[derive(Debug, Serialize, ToSchema)]
pub struct ChangedTrack {
    /// `initiated`, `confirmed`, `updated` or `corrected` (recomputed
    /// because the batch held late plots from before the track's last
    /// update; see `corrected_from_t`).
    pub change: &'static str,
    pub track: FusedTrack,
}

/// What a plot-fusion batch did.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlotFusionBatchUpdate {
    /// Frames (scan groups or fusion instants) processed by this batch.
    pub frames: u32,
    /// Plots of the open frame (in the tracks already; processed again
    /// when more of the frame arrives).
    pub pending_plots: u32,
    /// Indices of the batch's plots late beyond the lag (older than the
    /// newest plot received minus `tracker.max_lag_s`), dropped.
    pub late_plots: Vec<u32>,
    /// Plots of the batch older than the newest plot received before it
    /// but within the lag: used, the tracks corrected for them.
    pub late_within_lag: u32,
    /// The earliest time of those plots: the tracks were recomputed from
    /// it (`change: corrected`).
    pub corrected_from_t: Option<f64>,
    /// Every live track, when a frame was processed.
    pub tracks: Vec<ChangedTrack>,
    /// Confirmed tracks deleted, as they were when deleted.
    pub deleted: Vec<FusedTrack>,
    /// Tentative tracks dropped without being confirmed.
    pub dropped: Vec<u64>,
    pub counters: TrackerCounters,
    /// What the batch's ASTERIX gave, when it had some.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub asterix: Option<AsterixSummary>,
    /// A session created with `cat062`: base64 of CAT062 data blocks, one
    /// record per entry of `tracks` in order (the first of a track flagged
    /// TSB), then a track-end record (TSE) per entry of `deleted`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cat062: Option<String>,
    /// Each radar's bias as applied after the batch.
    pub registration: Vec<RadarBiasOut>,
    /// Each radar's σ after the batch: declared, learnt, applied.
    pub accuracy: Vec<super::plot_fusion::RadarAccuracyOut>,
    /// Events only (`GET /v1/sessions/{id}/events`): where the batch's
    /// plots are (late plots left out), for display.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plots: Option<Vec<PlotPosition>>,
}

/// A plot of a batch, placed for display.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlotPosition {
    /// Index of its radar in the session's `radars`; a cooperative
    /// report's is past them (radars' count + 0 ADS-B, 1 MLAT, 2 AIS).
    pub radar: u32,
    pub t: f64,
    /// In the fusion ENU frame (m); a 2D plot at its slant range on the
    /// horizontal plane.
    #[schema(example = json!([1200.0, 35000.0, 9000.0]))]
    pub position_m: [f64; 3],
}

/// A radar of a plot-fusion session.
#[derive(Debug, Serialize, ToSchema)]
pub struct RadarSiteState {
    pub id: String,
    /// `2d` or `3d`.
    pub kind: &'static str,
    /// Whether it measures radial velocity.
    pub doppler: bool,
    /// In the fusion ENU frame (m).
    pub position_m: [f64; 3],
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lat_deg: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lon_deg: Option<f64>,
}

/// The fusion frame's origin.
#[derive(Debug, Serialize, ToSchema)]
pub struct OriginState {
    pub lat_deg: f64,
    pub lon_deg: f64,
    pub height_m: f64,
}

/// The tracker of a plot-fusion session.
#[derive(Debug, Serialize, ToSchema)]
pub struct PlotFusionSessionState {
    /// `parallel` or `serial`.
    pub mode: &'static str,
    pub state_layout: Vec<&'static str>,
    pub radars: Vec<String>,
    /// The fusion frame's origin, when it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub origin: Option<OriginState>,
    /// The radars' sites, in the order of `radars`.
    pub sites: Vec<RadarSiteState>,
    /// Time of the last processed frame.
    pub last_frame_t: Option<f64>,
    /// Plots of the open frame (in the tracks already).
    pub pending_plots: u32,
    /// The lag (s): plots are taken in any order within it.
    pub max_lag_s: f64,
    /// How a plot older than the newest received is taken: `reprocess`
    /// (exact) or `retrodict` (`tracker.late_plots`; a parallel-mode
    /// session reprocesses).
    #[schema(example = "auto")]
    pub late_plots: String,
    /// Under `auto`: the tracks are approximate from this time (a late
    /// plot was taken by retrodiction because replaying it would have
    /// exceeded `tracker.max_replay_plots`; late plots are retrodicted
    /// from then on); null when exact.
    pub approximate_from: Option<f64>,
    /// Plots older than this are late beyond the lag (dropped); null
    /// before the first plot.
    pub late_before_t: Option<f64>,
    pub counters: TrackerCounters,
    /// Confirmed then tentative tracks.
    pub tracks: Vec<FusedTrack>,
    /// Each radar's bias as applied now.
    pub registration: Vec<RadarBiasOut>,
    /// Each radar's σ now: declared, learnt, applied.
    pub accuracy: Vec<super::plot_fusion::RadarAccuracyOut>,
    /// The pressure offset a 3D tracker applies to Mode C.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pressure_offset: Option<super::plot_fusion::PressureOffsetOut>,
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
    pub idle_expiry_s: f64,
    /// Size of the stored session.
    pub encoded_bytes: usize,
    /// Correlation sessions: their state (the fields below, present only
    /// for this kind).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub instants_processed: Option<u64>,
    pub last_instant_t: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pending_reports: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reports_accepted: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reports_late: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub retire_after_s: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub history_instants: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub method: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nodes: Option<Vec<SessionNode>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pairs: Option<Vec<PairResult>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub system_tracks: Option<Vec<SystemTrack>>,
    /// Plot-fusion sessions: the tracker.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plot_fusion: Option<PlotFusionSessionState>,
    /// In the answer to a create request: what was decided for the caller
    /// (a mode chosen, a missing origin). Empty otherwise.
    pub warnings: Vec<String>,
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

/// Refuses the fields of the other kind, naming each.
fn only_fields_of(kind: KindName, req: &CreateSessionRequest) -> Result<(), ServiceError> {
    use KindName::{Correlation as C, PlotFusion as P};
    refuse_foreign_fields(
        kind,
        &[
            ("state_layout", !req.state_layout.is_empty(), C),
            ("method", req.method.is_some(), C),
            ("motion_model", req.motion_model.is_some(), C),
            ("alignment", req.alignment.is_some(), C),
            ("measurement_matrix", req.measurement_matrix.is_some(), C),
            ("nodes", !req.nodes.is_empty(), C),
            ("pruning", req.pruning.is_some(), C),
            ("fuse", req.fuse.is_some(), C),
            ("retire_after_s", req.retire_after_s.is_some(), C),
            ("history_instants", req.history_instants.is_some(), C),
            ("origin", req.origin.is_some(), P),
            ("radars", req.radars.is_some(), P),
            ("tracker", req.tracker.is_some(), P),
            ("cat062", req.cat062.is_some(), P),
        ],
    )
}

fn plot_fusion_spec_in(req: CreateSessionRequest) -> Spec<service::plot_fusion::SpecInput> {
    Spec {
        idle_expiry_s: req.idle_expiry_s,
        body: spec_in(
            req.origin,
            req.radars.unwrap_or_default(),
            req.tracker,
            req.cat062,
        ),
    }
}

/// A `plot_fusion` session's configuration from the JSON body of a create
/// request (the ASTERIX UDP listener's `--asterix-session-spec` file).
pub fn plot_fusion_spec_from_json(
    json: &str,
) -> Result<Spec<service::plot_fusion::SpecInput>, String> {
    let req: CreateSessionRequest = serde_json::from_str(json).map_err(|e| e.to_string())?;
    let kind = KindName::parse(req.kind.as_deref(), "kind").map_err(|e| e.to_string())?;
    if kind != KindName::PlotFusion {
        return Err("\"kind\" must be \"plot_fusion\"".into());
    }
    only_fields_of(kind, &req).map_err(|e| match e {
        ServiceError::InvalidInput(v) => v
            .iter()
            .map(|f| format!("{}: {}", f.field, f.message))
            .collect::<Vec<_>>()
            .join("; "),
        other => other.to_string(),
    })?;
    Ok(plot_fusion_spec_in(req))
}

fn correlation_spec_in(
    req: CreateSessionRequest,
) -> Result<Spec<domain::SessionSpec>, ServiceError> {
    let Some(method) = req.method else {
        return Err(Violations::single(
            "method",
            "is required for a correlation session",
        ));
    };
    let nodes = req
        .nodes
        .into_iter()
        .map(|id| corr::NodeInput {
            id: Some(id),
            tracks: Vec::new(),
        })
        .collect();
    Ok(Spec {
        idle_expiry_s: req.idle_expiry_s,
        body: domain::SessionSpec {
            config: config_in(
                req.state_layout,
                method,
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
    })
}

fn plot_batch_in(req: PushBatchRequest) -> Result<Batch<pf::BatchInput>, Problem> {
    Ok(Batch {
        sequence: req.sequence,
        body: pf::BatchInput {
            flush: req.flush,
            plots: plots_in(req.plots, req.cooperative),
            asterix: asterix_in(req.asterix)?,
            nmea: nmea_in(req.nmea),
        },
    })
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

pub(super) fn update_out(u: Update<domain::BatchUpdate>) -> BatchUpdate {
    let b = u.body;
    BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        instants: Some(b.instants),
        pending_reports: Some(b.pending_reports),
        changes: Some(
            b.changes
                .into_iter()
                .map(|c| PairChange {
                    a: track_ref(c.a),
                    b: track_ref(c.b),
                    change: change_name(c.change),
                })
                .collect(),
        ),
        pairs: Some(b.pairs.into_iter().map(pair_result).collect()),
        system_tracks: Some(b.system_tracks.into_iter().map(system_track).collect()),
        retired: Some(b.retired.into_iter().map(track_ref).collect()),
        plot_fusion: None,
        warnings: u.warnings,
    }
}

pub(super) fn plot_update_out(u: Update<pf::BatchUpdate>) -> BatchUpdate {
    let b = u.body;
    BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        instants: None,
        pending_reports: None,
        changes: None,
        pairs: None,
        system_tracks: None,
        retired: None,
        plot_fusion: Some(PlotFusionBatchUpdate {
            frames: b.frames,
            pending_plots: b.pending_plots,
            late_plots: b.late_plots,
            late_within_lag: b.late_within_lag,
            corrected_from_t: b.corrected_from_t,
            tracks: b
                .tracks
                .into_iter()
                .map(|c| ChangedTrack {
                    change: track_change_name(c.change),
                    track: track_out(c.track),
                })
                .collect(),
            deleted: b.deleted.into_iter().map(track_out).collect(),
            dropped: b.dropped,
            counters: counters_out(b.counters),
            asterix: b.asterix.map(asterix_out),
            cat062: cat062_out(b.cat062),
            registration: b.registration.into_iter().map(bias_out).collect(),
            accuracy: b.accuracy.into_iter().map(accuracy_out).collect(),
            plots: None,
        }),
        warnings: u.warnings,
    }
}

pub(super) fn view_out(v: AnyView) -> SessionState {
    match v {
        AnyView::Correlation(v) => correlation_view_out(v),
        AnyView::PlotFusion(v) => plot_view_out(v),
    }
}

fn plot_view_out(v: View<pf::SessionView>) -> SessionState {
    let b = v.body;
    SessionState {
        id: v.id,
        kind: v.kind,
        version: v.version,
        created_unix_ms: v.created_unix_ms,
        last_sequence: v.last_sequence,
        batches: v.batches,
        idle_expiry_s: v.idle_expiry_s,
        encoded_bytes: v.encoded_bytes,
        warnings: v.warnings,
        instants_processed: None,
        last_instant_t: None,
        pending_reports: None,
        reports_accepted: None,
        reports_late: None,
        retire_after_s: None,
        history_instants: None,
        method: None,
        nodes: None,
        pairs: None,
        system_tracks: None,
        plot_fusion: Some(PlotFusionSessionState {
            mode: b.mode,
            state_layout: b.state_layout.to_vec(),
            origin: b.origin.map(|[lat_deg, lon_deg, height_m]| OriginState {
                lat_deg,
                lon_deg,
                height_m,
            }),
            sites: b
                .radars
                .iter()
                .zip(b.sites)
                .map(|(id, s)| RadarSiteState {
                    id: id.clone(),
                    kind: if s.three_d { "3d" } else { "2d" },
                    doppler: s.doppler,
                    position_m: s.position,
                    lat_deg: s.lat_lon_deg.map(|l| l[0]),
                    lon_deg: s.lat_lon_deg.map(|l| l[1]),
                })
                .collect(),
            radars: b.radars,
            last_frame_t: b.last_frame_t,
            pending_plots: b.pending_plots,
            max_lag_s: b.max_lag_s,
            late_plots: b.late_plots.to_string(),
            approximate_from: b.approximate_from,
            late_before_t: b.late_before_t,
            counters: counters_out(b.counters),
            tracks: b.tracks.into_iter().map(track_out).collect(),
            registration: b.registration.into_iter().map(bias_out).collect(),
            accuracy: b.accuracy.into_iter().map(accuracy_out).collect(),
            pressure_offset: b
                .pressure_offset
                .map(|o| super::plot_fusion::pressure_offset_out(*o)),
        }),
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
        idle_expiry_s: v.idle_expiry_s,
        encoded_bytes: v.encoded_bytes,
        warnings: v.warnings,
        instants_processed: Some(b.instants_processed),
        last_instant_t: b.last_instant.and_then(finite),
        pending_reports: Some(b.pending_reports),
        reports_accepted: Some(b.reports_accepted),
        reports_late: Some(b.reports_late),
        retire_after_s: Some(b.retire_after_s),
        history_instants: Some(b.history_instants),
        method: Some(b.method),
        nodes: Some(
            b.nodes
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
        ),
        pairs: Some(b.pairs.into_iter().map(pair_result).collect()),
        system_tracks: Some(b.system_tracks.into_iter().map(system_track).collect()),
        plot_fusion: None,
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
    let kind = KindName::parse(req.kind.as_deref(), "kind")?;
    only_fields_of(kind, &req)?;
    let view = match kind {
        KindName::Correlation => AnyView::Correlation(
            state
                .sessions()
                .create::<CorrelationSession>(&tenant.0, correlation_spec_in(req)?)
                .await?,
        ),
        KindName::PlotFusion => AnyView::PlotFusion(
            state
                .sessions()
                .create::<PlotFusionSession>(&tenant.0, plot_fusion_spec_in(req))
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

/// Pushes a batch (track reports to a correlation session, plots to a
/// plot-fusion session); answers what changed.
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
    let sessions = state.sessions();
    // The batch's items say its kind; an empty batch (a flush, a sequence
    // number) asks the stored session.
    let kind = match (
        req.reports.is_empty(),
        req.plots.is_empty() && req.asterix.is_none(),
    ) {
        (false, false) => {
            return Err(Violations::single(
                "plots",
                "a batch carries reports (correlation) or plots (plot_fusion), not both",
            )
            .into());
        }
        (false, true) => KindName::Correlation,
        (true, false) => KindName::PlotFusion,
        (true, true) => sessions.kind_of(&tenant.0, &id).await?,
    };
    Ok(Json(match kind {
        KindName::Correlation => update_out(
            sessions
                .push::<CorrelationSession>(&tenant.0, &id, batch_in(req), limits)
                .await?,
        ),
        KindName::PlotFusion => plot_update_out(
            sessions
                .push::<PlotFusionSession>(&tenant.0, &id, plot_batch_in(req)?, limits)
                .await?,
        ),
    }))
}
