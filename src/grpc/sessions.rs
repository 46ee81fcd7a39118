//! gRPC `SessionService`: the unary session calls and the bidirectional
//! batch stream, over the same service layer as `/v1/sessions`.

use std::pin::Pin;

use tokio_stream::{Stream, StreamExt};
use tonic::{Request, Response, Status, Streaming};

use super::{
    correlation::{correlate_input, finite, pair_result, system_track, track_ref},
    error::to_status,
    rows,
};
use crate::{
    auth::{DEFAULT_TENANT, Tenant},
    proto::{self as pb, session_service_server::SessionService, stream_request::Kind},
    service::{
        ServiceError, Violations, correlation as corr,
        session::{self as domain, change_name},
        sessions,
    },
    state::AppState,
};

#[derive(Clone)]
pub struct SessionGrpc {
    pub state: AppState,
}

fn tenant<T>(request: &Request<T>) -> String {
    request
        .extensions()
        .get::<Tenant>()
        .map_or_else(|| DEFAULT_TENANT.to_string(), |t| t.0.clone())
}

fn spec_in(req: pb::CreateSessionRequest) -> Result<domain::SessionSpec, ServiceError> {
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
    Ok(domain::SessionSpec {
        config,
        idle_expiry_s: req.idle_expiry_s,
        retire_after_s: req.retire_after_s,
        history_instants: req.history_instants,
    })
}

fn batch_in(req: pb::PushBatchRequest) -> Result<domain::BatchInput, ServiceError> {
    let mut v = Violations::new();
    let reports = req
        .reports
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            let field = format!("reports[{i}]");
            let s = r.sample.unwrap_or_default();
            let covariance = match &s.covariance {
                Some(m) => rows(&mut v, &format!("{field}.covariance"), m),
                None => {
                    v.add(format!("{field}.covariance"), "is required");
                    None
                }
            };
            let gain = s
                .gain
                .as_ref()
                .and_then(|m| rows(&mut v, &format!("{field}.gain"), m));
            domain::ReportInput {
                node: (!r.node.is_empty()).then_some(r.node),
                track: (!r.track.is_empty()).then_some(r.track),
                sample: corr::SampleInput {
                    t: s.t,
                    state: s.state,
                    covariance: covariance.unwrap_or_default(),
                    gain,
                },
            }
        })
        .collect();
    v.finish()?;
    Ok(domain::BatchInput {
        sequence: req.sequence,
        reports,
        flush: req.flush,
    })
}

fn update_out(u: domain::BatchUpdate) -> pb::BatchUpdate {
    pb::BatchUpdate {
        session_id: u.session_id,
        sequence: u.sequence,
        version: u.version,
        duplicate: u.duplicate,
        instants: u.instants,
        pending_reports: u.pending_reports,
        changes: u
            .changes
            .into_iter()
            .map(|c| pb::PairChange {
                a: Some(track_ref(c.a)),
                b: Some(track_ref(c.b)),
                change: change_name(c.change).into(),
            })
            .collect(),
        pairs: u.pairs.into_iter().map(pair_result).collect(),
        system_tracks: u.system_tracks.into_iter().map(system_track).collect(),
        retired: u.retired.into_iter().map(track_ref).collect(),
        warnings: u.warnings,
    }
}

fn view_out(v: domain::SessionView) -> pb::SessionState {
    pb::SessionState {
        id: v.id,
        version: v.version,
        created_unix_ms: v.created_unix_ms,
        last_sequence: v.last_sequence,
        batches: v.batches,
        instants_processed: v.instants_processed,
        last_instant_t: v.last_instant.and_then(finite),
        pending_reports: v.pending_reports,
        reports_accepted: v.reports_accepted,
        reports_late: v.reports_late,
        idle_expiry_s: v.idle_expiry_s,
        retire_after_s: v.retire_after_s,
        history_instants: v.history_instants,
        method: v.method,
        nodes: v
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
        pairs: v.pairs.into_iter().map(pair_result).collect(),
        system_tracks: v.system_tracks.into_iter().map(system_track).collect(),
        encoded_bytes: v.encoded_bytes as u64,
    }
}

/// The acknowledgement of opening or attaching a stream.
fn opened(view: &domain::SessionView) -> pb::BatchUpdate {
    pb::BatchUpdate {
        session_id: view.id.clone(),
        sequence: view.last_sequence,
        version: view.version,
        pending_reports: view.pending_reports,
        ..Default::default()
    }
}

type UpdateStream = Pin<Box<dyn Stream<Item = Result<pb::BatchUpdate, Status>> + Send>>;

#[tonic::async_trait]
impl SessionService for SessionGrpc {
    async fn create_session(
        &self,
        request: Request<pb::CreateSessionRequest>,
    ) -> Result<Response<pb::SessionState>, Status> {
        let tenant = tenant(&request);
        let spec = spec_in(request.into_inner()).map_err(to_status)?;
        let view = sessions::create(self.state.store(), &tenant, spec)
            .await
            .map_err(to_status)?;
        Ok(Response::new(view_out(view)))
    }

    async fn get_session(
        &self,
        request: Request<pb::GetSessionRequest>,
    ) -> Result<Response<pb::SessionState>, Status> {
        let tenant = tenant(&request);
        let id = request.into_inner().session_id;
        let view = sessions::get(self.state.store(), &tenant, &id)
            .await
            .map_err(to_status)?;
        Ok(Response::new(view_out(view)))
    }

    async fn list_sessions(
        &self,
        request: Request<pb::ListSessionsRequest>,
    ) -> Result<Response<pb::ListSessionsResponse>, Status> {
        let tenant = tenant(&request);
        let metas = sessions::list(self.state.store(), &tenant)
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::ListSessionsResponse {
            sessions: metas
                .into_iter()
                .map(|m| pb::SessionSummary {
                    id: m.id,
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
        let tenant = tenant(&request);
        let id = request.into_inner().session_id;
        sessions::delete(self.state.store(), &tenant, &id)
            .await
            .map_err(to_status)?;
        Ok(Response::new(pb::DeleteSessionResponse {}))
    }

    async fn push_batch(
        &self,
        request: Request<pb::PushBatchRequest>,
    ) -> Result<Response<pb::BatchUpdate>, Status> {
        let tenant = tenant(&request);
        let req = request.into_inner();
        let id = req.session_id.clone();
        let batch = batch_in(req).map_err(to_status)?;
        let limits = self.state.settings().session_limits();
        let update = sessions::push(self.state.store(), &tenant, &id, batch, limits)
            .await
            .map_err(to_status)?;
        Ok(Response::new(update_out(update)))
    }

    type StreamStream = UpdateStream;

    async fn stream(
        &self,
        request: Request<Streaming<pb::StreamRequest>>,
    ) -> Result<Response<Self::StreamStream>, Status> {
        let tenant = tenant(&request);
        let mut inbound = request.into_inner();
        let state = self.state.clone();
        let (tx, rx) = tokio::sync::mpsc::channel::<Result<pb::BatchUpdate, Status>>(4);
        tokio::spawn(async move {
            let mut session: Option<String> = None;
            while let Some(message) = inbound.next().await {
                let result = match message {
                    // The client went away or sent garbage: stop; every
                    // applied batch is already stored whole.
                    Err(_) => break,
                    Ok(m) => handle(&state, &tenant, &mut session, m).await,
                };
                let failed = result.is_err();
                if tx.send(result).await.is_err() || failed {
                    break;
                }
            }
        });
        let out = tokio_stream::wrappers::ReceiverStream::new(rx);
        Ok(Response::new(Box::pin(out) as UpdateStream))
    }
}

async fn handle(
    state: &AppState,
    tenant: &str,
    session: &mut Option<String>,
    m: pb::StreamRequest,
) -> Result<pb::BatchUpdate, Status> {
    match (m.kind, session.as_ref()) {
        (Some(Kind::Open(req)), None) => {
            let spec = spec_in(req).map_err(to_status)?;
            let view = sessions::create(state.store(), tenant, spec)
                .await
                .map_err(to_status)?;
            *session = Some(view.id.clone());
            Ok(opened(&view))
        }
        (Some(Kind::Attach(id)), None) => {
            let view = sessions::get(state.store(), tenant, &id)
                .await
                .map_err(to_status)?;
            *session = Some(view.id.clone());
            Ok(opened(&view))
        }
        (Some(Kind::Batch(req)), Some(id)) => {
            let batch = batch_in(req).map_err(to_status)?;
            let update = sessions::push(
                state.store(),
                tenant,
                id,
                batch,
                state.settings().session_limits(),
            )
            .await
            .map_err(to_status)?;
            Ok(update_out(update))
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
