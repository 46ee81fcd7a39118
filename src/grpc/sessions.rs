//! gRPC `SessionService`: the unary session calls and the bidirectional
//! batch stream, over the same service layer as `/v1/sessions`. Each batch
//! of a stream is held to the limits of a unary call (an in-flight slot, the
//! request timeout) and a failed batch is answered inside the stream.

use std::pin::Pin;

use tokio_stream::{Stream, StreamExt};
use tonic::{Code, Request, Response, Status, Streaming};

use super::{
    correlation::{correlate_input, finite, pair_result, sample_in, system_track, track_ref},
    error::to_status,
    plot_fusion::{
        accuracy_out, asterix_in, asterix_out, bias_out, counters_out, nmea_in, plots_in,
        spec_in as plot_spec_in, track_out,
    },
};
use crate::{
    auth::Tenant,
    proto::{self as pb, session_service_server::SessionService, stream_request::Kind},
    state::AppState,
};
use service::{
    ServiceError, Violations, correlation as corr,
    session::{
        Batch, Spec, Update, View,
        correlation::{self as domain, CorrelationSession, change_name},
        events::WatchItem,
        plot_fusion::{self as pf, PlotFusionSession, track_change_name},
        registry::{AnyView, EventBody, KindName, refuse_foreign_fields},
    },
};

#[derive(Clone)]
pub struct SessionGrpc {
    pub state: AppState,
}

/// The tenant the authentication layer resolved for the call. It puts one
/// into every call it lets through (open mode's is `default`), so a call
/// without one did not pass it: UNAUTHENTICATED, never another tenant's
/// sessions.
fn tenant<T>(request: &Request<T>) -> Result<String, Status> {
    request
        .extensions()
        .get::<Tenant>()
        .map(|t| t.0.clone())
        .ok_or_else(|| Status::unauthenticated("no tenant was resolved for this call"))
}

/// A create request: the kind it names and its configuration (boxed: the
/// plot-fusion spec is the larger by far).
enum KindSpec {
    Correlation(Box<Spec<domain::SessionSpec>>),
    PlotFusion(Box<Spec<service::plot_fusion::SpecInput>>),
}

fn spec_in(req: pb::CreateSessionRequest) -> Result<KindSpec, ServiceError> {
    let kind = KindName::parse(Some(&req.kind), "kind")?;
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
            ("plot_fusion", req.plot_fusion.is_some(), P),
        ],
    )?;
    match kind {
        KindName::Correlation => Ok(KindSpec::Correlation(Box::new(correlation_spec_in(req)?))),
        KindName::PlotFusion => {
            let Some(c) = req.plot_fusion else {
                return Err(Violations::single(
                    "plot_fusion",
                    "is required for a plot_fusion session",
                ));
            };
            Ok(KindSpec::PlotFusion(Box::new(Spec {
                idle_expiry_s: req.idle_expiry_s,
                body: plot_spec_in(c.origin, c.radars, c.tracker, c.cat062),
            })))
        }
    }
}

fn correlation_spec_in(
    req: pb::CreateSessionRequest,
) -> Result<Spec<domain::SessionSpec>, ServiceError> {
    let mut config = correlate_input(pb::CorrelateTracksRequest {
        state_layout: req.state_layout,
        method: req.method,
        motion_model: req.motion_model,
        alignment: req.alignment,
        measurement_matrix: req.measurement_matrix,
        nodes: Vec::new(),
        pruning: req.pruning,
        fuse: req.fuse,
    })?;
    config.nodes = req
        .nodes
        .into_iter()
        .map(|id| corr::NodeInput {
            id: (!id.is_empty()).then_some(id),
            tracks: Vec::new(),
        })
        .collect();
    Ok(Spec {
        idle_expiry_s: req.idle_expiry_s,
        body: domain::SessionSpec {
            config,
            retire_after_s: req.retire_after_s,
            history_instants: req.history_instants,
        },
    })
}

fn batch_in(req: pb::PushBatchRequest) -> Result<Batch<domain::BatchInput>, ServiceError> {
    let mut v = Violations::new();
    let reports = req
        .reports
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            let s = r.sample.unwrap_or_default();
            domain::ReportInput {
                node: (!r.node.is_empty()).then_some(r.node),
                track: (!r.track.is_empty()).then_some(r.track),
                sample: sample_in(&mut v, &|| format!("reports[{i}]"), s),
            }
        })
        .collect();
    v.finish()?;
    Ok(Batch {
        sequence: req.sequence,
        body: domain::BatchInput {
            reports,
            flush: req.flush,
        },
    })
}

fn plot_batch_in(req: pb::PushBatchRequest) -> Batch<pf::BatchInput> {
    Batch {
        sequence: req.sequence,
        body: pf::BatchInput {
            plots: plots_in(req.plots, req.cooperative),
            asterix: req.asterix.map(asterix_in),
            nmea: req.nmea.map(nmea_in),
            flush: req.flush,
        },
    }
}

fn plot_update_out(u: Update<pf::BatchUpdate>) -> pb::BatchUpdate {
    let b = u.body;
    pb::BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        plot_fusion: Some(pb::PlotFusionBatchUpdate {
            frames: b.frames,
            pending_plots: b.pending_plots,
            late_plots: b.late_plots,
            late_within_lag: b.late_within_lag,
            corrected_from_t: b.corrected_from_t,
            registration: b.registration.into_iter().map(bias_out).collect(),
            accuracy: b.accuracy.into_iter().map(accuracy_out).collect(),
            tracks: b
                .tracks
                .into_iter()
                .map(|c| pb::ChangedTrack {
                    change: track_change_name(c.change).into(),
                    track: Some(track_out(c.track)),
                })
                .collect(),
            deleted: b.deleted.into_iter().map(track_out).collect(),
            dropped: b.dropped,
            counters: Some(counters_out(b.counters)),
            asterix: b.asterix.map(asterix_out),
            cat062: b.cat062.map(|c| c.data),
            plots: Vec::new(),
        }),
        warnings: u.warnings,
        ..Default::default()
    }
}

fn update_out(u: Update<domain::BatchUpdate>) -> pb::BatchUpdate {
    let (b, warnings) = (u.body, u.warnings);
    pb::BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        error: None,
        instants: b.instants,
        pending_reports: b.pending_reports,
        changes: b
            .changes
            .into_iter()
            .map(|c| pb::PairChange {
                a: Some(track_ref(c.a)),
                b: Some(track_ref(c.b)),
                change: change_name(c.change).into(),
            })
            .collect(),
        pairs: b.pairs.into_iter().map(pair_result).collect(),
        system_tracks: b.system_tracks.into_iter().map(system_track).collect(),
        retired: b.retired.into_iter().map(track_ref).collect(),
        plot_fusion: None,
        warnings,
    }
}

fn view_out(v: AnyView) -> pb::SessionState {
    match v {
        AnyView::Correlation(v) => correlation_view_out(v),
        AnyView::PlotFusion(v) => plot_view_out(v),
    }
}

fn plot_view_out(v: View<pf::SessionView>) -> pb::SessionState {
    let b = v.body;
    pb::SessionState {
        id: v.id,
        kind: v.kind.into(),
        version: v.version,
        created_unix_ms: v.created_unix_ms,
        last_sequence: v.last_sequence,
        batches: v.batches,
        idle_expiry_s: v.idle_expiry_s,
        encoded_bytes: v.encoded_bytes as u64,
        warnings: v.warnings,
        plot_fusion: Some(pb::PlotFusionSessionState {
            mode: b.mode.into(),
            state_layout: b.state_layout.iter().map(|s| s.to_string()).collect(),
            radars: b.radars.clone(),
            last_frame_t: b.last_frame_t,
            pending_plots: b.pending_plots,
            max_lag_s: b.max_lag_s,
            late_plots: b.late_plots.to_string(),
            approximate_from: b.approximate_from,
            late_before_t: b.late_before_t,
            registration: b.registration.into_iter().map(bias_out).collect(),
            accuracy: b.accuracy.into_iter().map(accuracy_out).collect(),
            pressure_offset: b
                .pressure_offset
                .map(|o| super::plot_fusion::pressure_offset_out(*o)),
            counters: Some(counters_out(b.counters)),
            tracks: b.tracks.into_iter().map(track_out).collect(),
            origin: b.origin.map(|[lat, lon, h]| pb::GeoPoint {
                lat_deg: Some(lat),
                lon_deg: Some(lon),
                height_m: Some(h),
            }),
            sites: b
                .radars
                .iter()
                .zip(b.sites)
                .map(|(id, s)| pb::RadarSiteState {
                    id: id.clone(),
                    kind: if s.three_d { "3d" } else { "2d" }.into(),
                    doppler: s.doppler,
                    position_m: s.position.to_vec(),
                    lat_deg: s.lat_lon_deg.map(|l| l[0]),
                    lon_deg: s.lat_lon_deg.map(|l| l[1]),
                })
                .collect(),
        }),
        ..Default::default()
    }
}

fn correlation_view_out(v: View<domain::SessionView>) -> pb::SessionState {
    let b = v.body;
    pb::SessionState {
        id: v.id,
        kind: v.kind.into(),
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
            .map(|n| pb::SessionNode {
                id: n.id,
                tracks: n
                    .tracks
                    .into_iter()
                    .map(|t| pb::SessionTrack {
                        id: t.id,
                        last_t: t.last_t,
                    })
                    .collect(),
            })
            .collect(),
        pairs: b.pairs.into_iter().map(pair_result).collect(),
        system_tracks: b.system_tracks.into_iter().map(system_track).collect(),
        encoded_bytes: v.encoded_bytes as u64,
        plot_fusion: None,
        warnings: v.warnings,
    }
}

/// The acknowledgement of opening or attaching a stream.
fn opened(view: &AnyView) -> pb::BatchUpdate {
    match view {
        AnyView::Correlation(v) => pb::BatchUpdate {
            session_id: v.id.clone(),
            sequence: v.last_sequence,
            version: v.version,
            pending_reports: v.body.pending_reports,
            warnings: v.warnings.clone(),
            ..Default::default()
        },
        AnyView::PlotFusion(v) => pb::BatchUpdate {
            session_id: v.id.clone(),
            sequence: v.last_sequence,
            version: v.version,
            plot_fusion: Some(pb::PlotFusionBatchUpdate {
                pending_plots: v.body.pending_plots,
                counters: Some(counters_out(v.body.counters)),
                ..Default::default()
            }),
            warnings: v.warnings.clone(),
            ..Default::default()
        },
    }
}

async fn create(state: &AppState, tenant: &str, spec: KindSpec) -> Result<AnyView, ServiceError> {
    let sessions = state.sessions();
    Ok(match spec {
        KindSpec::Correlation(spec) => {
            AnyView::Correlation(sessions.create::<CorrelationSession>(tenant, *spec).await?)
        }
        KindSpec::PlotFusion(spec) => {
            AnyView::PlotFusion(sessions.create::<PlotFusionSession>(tenant, *spec).await?)
        }
    })
}

async fn push(
    state: &AppState,
    tenant: &str,
    id: &str,
    req: pb::PushBatchRequest,
) -> Result<pb::BatchUpdate, ServiceError> {
    let limits = state.settings().session_limits();
    let sessions = state.sessions();
    // The batch's items say its kind; an empty batch asks the stored session.
    let kind = match (
        req.reports.is_empty(),
        req.plots.is_empty() && req.asterix.is_none(),
    ) {
        (false, false) => {
            return Err(Violations::single(
                "plots",
                "a batch carries reports (correlation) or plots (plot_fusion), not both",
            ));
        }
        (false, true) => KindName::Correlation,
        (true, false) => KindName::PlotFusion,
        (true, true) => sessions.kind_of(tenant, id).await?,
    };
    // The stores' pushes boxed: inline, their state (tens of kB each)
    // was copied into every layer above (admission, timeout, lanes).
    Ok(match kind {
        KindName::Correlation => update_out(
            Box::pin(sessions.push::<CorrelationSession>(tenant, id, batch_in(req)?, limits))
                .await?,
        ),
        KindName::PlotFusion => plot_update_out(
            Box::pin(sessions.push::<PlotFusionSession>(tenant, id, plot_batch_in(req), limits))
                .await?,
        ),
    })
}

type UpdateStream = Pin<Box<dyn Stream<Item = Result<pb::BatchUpdate, Status>> + Send>>;
type WatchStream = Pin<Box<dyn Stream<Item = Result<pb::WatchEvent, Status>> + Send>>;

/// The gRPC form of one watch item (`None`: nothing to send).
fn watch_event_out(
    item: WatchItem,
    heartbeat: std::time::Duration,
    version: u64,
) -> Option<pb::WatchEvent> {
    use pb::watch_event::Event;
    let (version, event) = match item {
        WatchItem::Snapshot(view) => {
            let v = view_out(*view);
            (v.version, Event::Snapshot(v))
        }
        WatchItem::Update(e) => {
            let update = match &e.body {
                EventBody::Correlation(u) => update_out(u.clone()),
                EventBody::PlotFusion { update, plots } => {
                    let mut out = plot_update_out(update.clone());
                    if let Some(pf) = out.plot_fusion.as_mut() {
                        pf.plots = plots
                            .iter()
                            .map(|p| pb::PlotPosition {
                                radar: p.radar,
                                t: p.t,
                                east_m: p.position[0],
                                north_m: p.position[1],
                                up_m: p.position[2],
                            })
                            .collect();
                    }
                    out
                }
                EventBody::Deleted => return None,
            };
            (e.version, Event::Update(update))
        }
        WatchItem::Heartbeat => (version, Event::Heartbeat(true)),
        WatchItem::End { reason, version } => (
            version,
            Event::End(pb::WatchEnd {
                reason: reason.name().into(),
                message: reason.message(heartbeat),
            }),
        ),
    };
    Some(pb::WatchEvent {
        version,
        event: Some(event),
    })
}

#[tonic::async_trait]
impl SessionService for SessionGrpc {
    async fn create_session(
        &self,
        request: Request<pb::CreateSessionRequest>,
    ) -> Result<Response<pb::SessionState>, Status> {
        let tenant = tenant(&request)?;
        let spec = spec_in(request.into_inner()).map_err(to_status)?;
        let view = create(&self.state, &tenant, spec)
            .await
            .map_err(to_status)?;
        Ok(Response::new(view_out(view)))
    }

    async fn get_session(
        &self,
        request: Request<pb::GetSessionRequest>,
    ) -> Result<Response<pb::SessionState>, Status> {
        let tenant = tenant(&request)?;
        let id = request.into_inner().session_id;
        let view = self
            .state
            .sessions()
            .get(&tenant, &id)
            .await
            .map_err(to_status)?;
        Ok(Response::new(view_out(view)))
    }

    async fn list_sessions(
        &self,
        request: Request<pb::ListSessionsRequest>,
    ) -> Result<Response<pb::ListSessionsResponse>, Status> {
        let tenant = tenant(&request)?;
        let metas = self
            .state
            .sessions()
            .list(&tenant)
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::ListSessionsResponse {
            sessions: metas
                .into_iter()
                .map(|m| pb::SessionSummary {
                    id: m.id,
                    kind: m.kind,
                    version: m.version,
                    encoded_bytes: m.bytes as u64,
                    expires_in_s: m.ttl_remaining.as_secs_f64(),
                })
                .collect(),
        }))
    }

    async fn delete_session(
        &self,
        request: Request<pb::DeleteSessionRequest>,
    ) -> Result<Response<pb::DeleteSessionResponse>, Status> {
        let tenant = tenant(&request)?;
        let id = request.into_inner().session_id;
        self.state
            .sessions()
            .delete(&tenant, &id)
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::DeleteSessionResponse {}))
    }

    async fn push_batch(
        &self,
        request: Request<pb::PushBatchRequest>,
    ) -> Result<Response<pb::BatchUpdate>, Status> {
        let tenant = tenant(&request)?;
        let req = request.into_inner();
        let id = req.session_id.clone();
        let update = push(&self.state, &tenant, &id, req)
            .await
            .map_err(to_status)?;
        Ok(Response::new(update))
    }

    type StreamStream = UpdateStream;

    async fn stream(
        &self,
        request: Request<Streaming<pb::StreamRequest>>,
    ) -> Result<Response<Self::StreamStream>, Status> {
        let tenant = tenant(&request)?;
        let mut inbound = request.into_inner();
        let state = self.state.clone();
        // A few answers ahead at most: a client that does not read makes
        // `send` wait, this task stops reading, and HTTP/2 flow control
        // holds the client's writes. Nothing buffers without bound.
        let (tx, rx) = tokio::sync::mpsc::channel::<Result<pb::BatchUpdate, Status>>(4);
        tokio::spawn(async move {
            let mut session: Option<String> = None;
            while let Some(message) = inbound.next().await {
                let result = match message {
                    // A message the budget of buffered body bytes could not
                    // take (`grpc::stream_budget`): the stream ends with it,
                    // so the client knows to retry.
                    Err(status) if status.code() == Code::Unavailable => {
                        let _ = tx.send(Err(status)).await;
                        break;
                    }
                    // The client went away or sent garbage: stop; every
                    // applied batch is already stored whole.
                    Err(_) => break,
                    Ok(m) => handle(&state, &tenant, &mut session, m).await,
                };
                // Only a failed open or attach ends the stream.
                let fatal = result.is_err();
                if tx.send(result).await.is_err() || fatal {
                    break;
                }
            }
        });
        let out = tokio_stream::wrappers::ReceiverStream::new(rx);
        Ok(Response::new(Box::pin(out) as UpdateStream))
    }

    type WatchStream = WatchStream;

    async fn watch(
        &self,
        request: Request<pb::WatchRequest>,
    ) -> Result<Response<Self::WatchStream>, Status> {
        let tenant = tenant(&request)?;
        let req = request.into_inner();
        let watch = self
            .state
            .sessions()
            .watch(&tenant, &req.session_id, req.after_version)
            .await
            .map_err(to_status)?;
        let heartbeat = watch.heartbeat();
        let (tx, rx) = tokio::sync::mpsc::channel::<Result<pb::WatchEvent, Status>>(1);
        tokio::spawn(watch.forward(tx, move |item, version| {
            watch_event_out(item, heartbeat, version).map(Ok)
        }));
        let out = tokio_stream::wrappers::ReceiverStream::new(rx);
        Ok(Response::new(Box::pin(out) as WatchStream))
    }
}

/// Answers one message of a stream: `Err` ends the stream (a failed open or
/// attach, a message out of place); a batch's own failure is an answer
/// with `error` set.
async fn handle(
    state: &AppState,
    tenant: &str,
    session: &mut Option<String>,
    m: pb::StreamRequest,
) -> Result<pb::BatchUpdate, Status> {
    // Each arm's future boxed: held inline they made this function's
    // state machine (and, unoptimised, its poll frame) the sum of all
    // three, some 400 kB of stack in a debug build.
    match (m.kind, session.as_ref()) {
        (Some(Kind::Open(req)), None) => {
            let spec = spec_in(req).map_err(to_status)?;
            let created = Box::pin(create(state, tenant, spec)).await;
            let ack = opened(&created.map_err(to_status)?);
            *session = Some(ack.session_id.clone());
            Ok(ack)
        }
        (Some(Kind::Attach(id)), None) => {
            let view = Box::pin(state.sessions().get(tenant, &id)).await;
            let ack = opened(&view.map_err(to_status)?);
            *session = Some(ack.session_id.clone());
            Ok(ack)
        }
        (Some(Kind::Batch(req)), Some(id)) => {
            Ok(Box::pin(stream_batch(state, tenant, id, req)).await)
        }
        (Some(Kind::Batch(_)), None) => Err(Status::failed_precondition(
            "the stream's first message must open or attach a session",
        )),
        (Some(Kind::Open(_) | Kind::Attach(_)), Some(_)) => Err(Status::failed_precondition(
            "the stream is already bound to a session",
        )),
        (None, _) => Err(Status::invalid_argument("kind: is required")),
    }
}

/// One batch of a stream, held to the limits of a unary call: an in-flight
/// slot (none free: UNAVAILABLE, shed, not queued) and the request timeout
/// (DEADLINE_EXCEEDED). A failure is the batch's answer, not the stream's end.
async fn stream_batch(
    state: &AppState,
    tenant: &str,
    id: &str,
    req: pb::PushBatchRequest,
) -> pb::BatchUpdate {
    let sequence = req.sequence;
    let failed = |status: Status| pb::BatchUpdate {
        session_id: id.to_string(),
        sequence,
        error: Some(stream_error(&status)),
        ..Default::default()
    };
    let Some(admission) = state.try_admit() else {
        metrics::counter!("requests_shed_total", "transport" => "grpc").increment(1);
        return failed(Status::unavailable(
            "too many requests in flight; retry this batch shortly",
        ));
    };
    let timeout = state.settings().request_timeout();
    let batch = service::lanes::admitted(admission, push(state, tenant, id, req));
    match tokio::time::timeout(timeout, batch).await {
        Ok(Ok(update)) => update,
        Ok(Err(e)) => failed(to_status(e)),
        Err(_) => failed(Status::deadline_exceeded(format!(
            "the batch took longer than the configured limit of {} s \
             (FUSION_REQUEST_TIMEOUT_S); its outcome is unknown: retry it with the same \
             sequence number",
            timeout.as_secs_f64()
        ))),
    }
}

/// A status as the stream's per-batch error, with the bad fields of a
/// `BadRequest` detail.
fn stream_error(status: &Status) -> pb::StreamError {
    use tonic_types::StatusExt;
    let violations = status
        .get_details_bad_request()
        .map(|b| {
            b.field_violations
                .into_iter()
                .map(|v| pb::FieldViolation {
                    field: v.field,
                    description: v.description,
                })
                .collect()
        })
        .unwrap_or_default();
    pb::StreamError {
        code: status.code() as i32,
        code_name: code_name(status.code()).into(),
        message: status.message().into(),
        violations,
    }
}

/// The name of a gRPC status code, as in the gRPC specification.
fn code_name(code: Code) -> &'static str {
    match code {
        Code::Ok => "OK",
        Code::Cancelled => "CANCELLED",
        Code::Unknown => "UNKNOWN",
        Code::InvalidArgument => "INVALID_ARGUMENT",
        Code::DeadlineExceeded => "DEADLINE_EXCEEDED",
        Code::NotFound => "NOT_FOUND",
        Code::AlreadyExists => "ALREADY_EXISTS",
        Code::PermissionDenied => "PERMISSION_DENIED",
        Code::ResourceExhausted => "RESOURCE_EXHAUSTED",
        Code::FailedPrecondition => "FAILED_PRECONDITION",
        Code::Aborted => "ABORTED",
        Code::OutOfRange => "OUT_OF_RANGE",
        Code::Unimplemented => "UNIMPLEMENTED",
        Code::Internal => "INTERNAL",
        Code::Unavailable => "UNAVAILABLE",
        Code::DataLoss => "DATA_LOSS",
        Code::Unauthenticated => "UNAUTHENTICATED",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Settings;

    fn open_state() -> AppState {
        AppState::for_tests(Settings::for_tests())
    }

    #[tokio::test]
    async fn a_call_without_a_resolved_tenant_is_unauthenticated_not_tenant_default() {
        let service = SessionGrpc {
            state: open_state(),
        };
        // Even in open mode: the authentication layer puts `default` into
        // every call it lets through, so a call without a tenant did not
        // pass it.
        let status = service
            .list_sessions(Request::new(pb::ListSessionsRequest {}))
            .await
            .unwrap_err();
        assert_eq!(status.code(), tonic::Code::Unauthenticated);
        let status = service
            .get_session(Request::new(pb::GetSessionRequest {
                session_id: "0123456789abcdef0123456789abcdef".into(),
            }))
            .await
            .unwrap_err();
        assert_eq!(status.code(), tonic::Code::Unauthenticated);
        // With the tenant the layer resolves, the call is served.
        let mut request = Request::new(pb::ListSessionsRequest {});
        request
            .extensions_mut()
            .insert(Tenant(crate::auth::DEFAULT_TENANT.into()));
        let listed = service.list_sessions(request).await.unwrap().into_inner();
        assert!(listed.sessions.is_empty());
    }
}
