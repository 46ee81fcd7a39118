//! The tonic adapter: gRPC services over the `service` layer, plus the
//! standard health and reflection services. The router it builds is served on
//! the dedicated gRPC port and, by content type, on the REST port too.

pub mod ais_radar;
pub mod correlation;
pub mod dimension;
pub mod error;
pub mod jpda;
pub mod plot_fusion;
pub mod sessions;
mod stream_budget;

use std::time::Instant;

use axum::{
    Router,
    extract::{MatchedPath, Request, State},
    middleware::{self, Next},
    response::Response,
};
use tonic::{Code, Status, codec::CompressionEncoding, service::Routes};
use tonic_health::server::HealthReporter;

use crate::{
    auth::{AuthError, CertTenant},
    proto::{
        ais_radar_service_server::AisRadarServiceServer,
        correlation_service_server::CorrelationServiceServer,
        dimension_service_server::DimensionServiceServer, jpda_service_server::JpdaServiceServer,
        plot_fusion_service_server::PlotFusionServiceServer,
        session_service_server::SessionServiceServer,
    },
    state::{AppState, BodyReadError},
};
use ais_radar::AisRadarGrpc;
use correlation::CorrelationGrpc;
use dimension::DimensionGrpc;
use jpda::JpdaGrpc;
use plot_fusion::PlotFusionGrpc;
use sessions::SessionGrpc;

/// Whether a `Matrix`'s values fill its rows × cols (both > 0); otherwise
/// a violation naming `field`.
fn fills_shape(
    v: &mut service::Violations,
    field: impl service::validate::Field,
    m: &crate::proto::Matrix,
) -> bool {
    let (r, c) = (m.rows as usize, m.cols as usize);
    let fills = r > 0 && c > 0 && r.checked_mul(c) == Some(m.values.len());
    if !fills {
        v.add(
            field,
            format!(
                "rows × cols = {} × {} does not match {} values",
                m.rows,
                m.cols,
                m.values.len()
            ),
        );
    }
    fills
}

/// A row-major `Matrix` as nested rows; `None` (with a violation naming
/// `field`) when its values do not fill rows × cols.
pub(crate) fn rows(
    v: &mut service::Violations,
    field: &str,
    m: &crate::proto::Matrix,
) -> Option<Vec<Vec<f64>>> {
    fills_shape(v, field, m).then(|| {
        m.values
            .chunks(m.cols as usize)
            .map(<[f64]>::to_vec)
            .collect()
    })
}

/// A `Matrix` as request [`Rows`], its values moved, not copied; `None`
/// (with a violation naming `field`) when they do not fill rows × cols.
pub(crate) fn flat_rows(
    v: &mut service::Violations,
    field: impl service::validate::Field,
    m: crate::proto::Matrix,
) -> Option<service::Rows> {
    if !fills_shape(v, field, &m) {
        return None;
    }
    let (r, c) = (m.rows as usize, m.cols as usize);
    service::Rows::from_flat(m.values, r, c)
}

/// Answer [`Rows`] as a row-major `Matrix`, the values moved.
pub(crate) fn flat_matrix(rows: service::Rows) -> crate::proto::Matrix {
    let (r, c) = rows.shape().unwrap_or((rows.nrows(), 0));
    crate::proto::Matrix {
        rows: r as u32,
        cols: c as u32,
        values: rows.into_values(),
    }
}

/// Nested rows as a row-major `Matrix`.
pub(crate) fn matrix(rows: &[Vec<f64>]) -> crate::proto::Matrix {
    crate::proto::Matrix {
        rows: rows.len() as u32,
        cols: rows.first().map_or(0, Vec::len) as u32,
        values: rows.iter().flatten().copied().collect(),
    }
}

/// The gRPC services with their health reporter (kept to mark the services
/// not serving while the process drains).
pub struct GrpcServices {
    pub router: Router,
    pub health: HealthReporter,
}

/// Builds the gRPC router: the fusion services behind authentication, the
/// in-flight limit and the timeout, health and reflection outside them, all
/// counted in metrics.
/// Unknown services and methods answer UNIMPLEMENTED.
pub fn services(state: &AppState) -> Result<GrpcServices, tonic_reflection::server::Error> {
    let limit = state.settings().max_body_bytes;
    // Every fusion service: messages up to the body limit (after
    // decompression), `grpc-encoding: gzip` accepted, and responses sent
    // gzip to clients whose `grpc-accept-encoding` names it.
    macro_rules! configured {
        ($server:expr) => {
            $server
                .max_decoding_message_size(limit)
                .max_encoding_message_size(usize::MAX)
                .accept_compressed(CompressionEncoding::Gzip)
                .send_compressed(CompressionEncoding::Gzip)
        };
    }
    let correlation = configured!(CorrelationServiceServer::new(CorrelationGrpc));
    let ais_radar = configured!(AisRadarServiceServer::new(AisRadarGrpc));
    let jpda = configured!(JpdaServiceServer::new(JpdaGrpc));
    let plot_fusion = configured!(PlotFusionServiceServer::new(PlotFusionGrpc));
    let dimension = configured!(DimensionServiceServer::new(DimensionGrpc));
    let sessions = configured!(SessionServiceServer::new(SessionGrpc {
        state: state.clone(),
    }));
    let (health, health_service) = tonic_health::server::health_reporter();
    let reflection_v1 = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(crate::proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()?;
    let reflection_v1alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(crate::proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1alpha()?;
    let router = Routes::new(correlation)
        .add_service(ais_radar)
        .add_service(jpda)
        .add_service(plot_fusion)
        .add_service(dimension)
        .add_service(sessions)
        .add_service(health_service)
        .add_service(reflection_v1)
        .add_service(reflection_v1alpha)
        .prepare()
        .into_axum_router()
        .layer(middleware::from_fn(on_lane))
        .layer(middleware::from_fn_with_state(state.clone(), admit))
        .layer(middleware::from_fn_with_state(state.clone(), authenticate))
        .layer(middleware::from_fn(record_metrics));
    Ok(GrpcServices { router, health })
}

/// Names of the services whose health is reported (besides the overall "").
/// The service that needs the session store.
pub const SESSION_SERVICE: &str = "radar.fusion.v1.SessionService";

pub const SERVICE_NAMES: &[&str] = &[
    "radar.fusion.v1.CorrelationService",
    "radar.fusion.v1.AisRadarService",
    "radar.fusion.v1.JpdaService",
    "radar.fusion.v1.PlotFusionService",
    "radar.fusion.v1.DimensionService",
    "radar.fusion.v1.SessionService",
];

/// Sheds a call with UNAVAILABLE when `max_in_flight` requests are being
/// served, and bounds its duration with DEADLINE_EXCEEDED. Health checks and
/// reflection pass freely, so that probes answer under load.
async fn admit(State(state): State<AppState>, req: Request, next: Next) -> Response {
    if is_health_or_reflection(req.uri().path()) {
        return next.run(req).await;
    }
    let (req, _charge) = if is_streaming(req.uri().path()) {
        // Read message by message by the call: its incomplete message is
        // charged to the budget as it arrives.
        (req.map(|body| stream_budget::budgeted(&state, body)), None)
    } else {
        match read_unary_body(&state, req).await {
            Ok((req, charge)) => (req, Some(charge)),
            Err(status) => return status.into_http(),
        }
    };
    let Some(admission) = state.try_admit() else {
        metrics::counter!("requests_shed_total", "transport" => "grpc").increment(1);
        return Status::unavailable("too many requests in flight; retry shortly").into_http();
    };
    let timeout = state.settings().request_timeout();
    let call = service::lanes::admitted(admission, next.run(req));
    match tokio::time::timeout(timeout, call).await {
        Ok(response) => remap_client_error_statuses(response),
        Err(_) => Status::deadline_exceeded(format!(
            "the call took longer than the configured limit of {} s (FUSION_REQUEST_TIMEOUT_S)",
            timeout.as_secs_f64()
        ))
        .into_http(),
    }
}

/// The stateless fusion services' calls run whole on a compute lane:
/// decoding the message, the computation and encoding the answer are one job
/// there, as REST's `JsonBody::compute` makes parsing, computation and
/// encoding one job. Decoded on an async worker and freed on a lane, a
/// request's thousands of small allocations cost the lane a cross-thread
/// collection, and its answer was encoded on the worker while the response
/// streamed, outside the call's measured time (docs/RESULTS.md, "gRPC calls
/// on the lanes").
///
/// The message is already in memory (`admit` read it), so the call's awaits
/// complete without the reactor ([`service::lanes::block_on`]), and
/// its compute, offloaded from within the job, runs in place. The answer's
/// frames are collected on the lane and replayed. The session service, whose
/// calls await the store, stays on the async workers.
async fn on_lane(req: Request, next: Next) -> Response {
    if !runs_on_lane(req.uri().path()) {
        return next.run(req).await;
    }
    let answered = service::lanes::run(move || {
        service::lanes::block_on(async move { buffered(next.run(req).await).await })
    })
    .await;
    answered.unwrap_or_else(|e| error::to_status(e).into_http())
}

/// The stateless services, whose unary calls [`on_lane`] runs on a lane.
fn runs_on_lane(path: &str) -> bool {
    let Some((service, _method)) = path.trim_start_matches('/').split_once('/') else {
        return false;
    };
    service != SESSION_SERVICE && SERVICE_NAMES.contains(&service)
}

/// A response with its body read into memory: its data frames, then its
/// trailers (the gRPC status), replayed as they came.
async fn buffered(response: Response) -> Response {
    use http_body_util::BodyExt;
    let (parts, mut body) = response.into_parts();
    let mut frames = Vec::new();
    while let Some(frame) = body.frame().await {
        let end = frame.is_err();
        frames.push(frame);
        if end {
            break;
        }
    }
    let replay = http_body_util::StreamBody::new(tokio_stream::iter(frames));
    Response::from_parts(parts, axum::body::Body::new(replay))
}

/// The streaming methods: their body is the stream, read batch by batch
/// (each batch takes its own in-flight slot, `sessions::stream_batch`).
fn is_streaming(path: &str) -> bool {
    path == "/radar.fusion.v1.SessionService/Stream"
}

/// Reads a unary call's whole body (its one message) within the body-read
/// timeout, the message limit and the budget of buffered body bytes before
/// the call takes an in-flight slot, as the REST side does: a client that
/// sends its headers and then trickles or withholds its message holds no
/// slot, and is answered DEADLINE_EXCEEDED; a message the budget cannot
/// take is shed with UNAVAILABLE. The bytes stay charged until the call is
/// answered (the returned charge).
async fn read_unary_body(
    state: &AppState,
    req: Request,
) -> Result<(Request, crate::state::BodyCharge), Status> {
    let limit = state.settings().max_body_bytes;
    let (parts, body) = req.into_parts();
    // The 5-byte gRPC frame header (compression flag, length) rides on the
    // message: a body over limit + 5 carries a message over the limit.
    match state.read_body(body, limit.saturating_add(5)).await {
        Ok((bytes, charge)) => Ok((
            Request::from_parts(parts, axum::body::Body::from(bytes)),
            charge,
        )),
        Err(BodyReadError::TooLarge) => Err(Status::resource_exhausted(format!(
            "the request message is larger than {limit} bytes (FUSION_MAX_BODY_BYTES)"
        ))),
        Err(BodyReadError::OverBudget) => Err(Status::unavailable(format!(
            "the request bodies being read hold the budget of {} buffered bytes \
             (FUSION_MAX_BUFFERED_BODY_BYTES); retry shortly",
            state.settings().max_buffered_body_bytes
        ))),
        Err(BodyReadError::Undecodable(e)) => Err(Status::invalid_argument(format!(
            "the request body could not be read: {e}"
        ))),
        Err(BodyReadError::Failed(e)) => Err(Status::cancelled(format!(
            "the request body could not be read: {e}"
        ))),
        Err(BodyReadError::TimedOut) => Err(Status::deadline_exceeded(format!(
            "the request message did not arrive within {} s (FUSION_BODY_READ_TIMEOUT_S)",
            state.settings().body_read_timeout().as_secs_f64()
        ))),
    }
}

/// Health checks and reflection: outside authentication and the in-flight limit.
fn is_health_or_reflection(path: &str) -> bool {
    path.starts_with("/grpc.health.") || path.starts_with("/grpc.reflection.")
}

/// Answers UNAUTHENTICATED to a call without a valid key (when keys are
/// configured) in the metadata `authorization: Bearer <key>` or, failing that,
/// `x-api-key: <key>`, and without a client certificate that stands for a
/// tenant; PERMISSION_DENIED to a key of another tenant than the
/// certificate's; otherwise puts its `Tenant` into the request extensions,
/// which tonic hands to the service (`request.extensions().get::<Tenant>()`).
/// Health checks and reflection need no key.
async fn authenticate(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    if is_health_or_reflection(req.uri().path()) {
        return next.run(req).await;
    }
    let keys = state.api_keys();
    let headers = req.headers();
    // A value that is not visible ASCII is malformed, as an empty one is.
    let text = |name: &str| headers.get(name).map(|v| v.to_str().unwrap_or(""));
    let cert = req.extensions().get::<CertTenant>();
    let authenticated = keys.authenticate_request(cert, text("authorization"), text("x-api-key"));
    match authenticated {
        Ok(tenant) => {
            req.extensions_mut().insert(tenant);
            next.run(req).await
        }
        Err(error) => {
            metrics::counter!("auth_failures_total", "transport" => "grpc").increment(1);
            let message = match error {
                AuthError::Missing => {
                    "an API key is required: send the metadata `authorization: Bearer <key>` \
                     or `x-api-key: <key>`"
                }
                AuthError::Malformed => {
                    "malformed credentials: expected the metadata `authorization: Bearer <key>` \
                     or `x-api-key: <key>`"
                }
                AuthError::UnknownKey => "the API key is not valid",
                AuthError::TenantMismatch => {
                    return Status::permission_denied(
                        "the API key belongs to another tenant than the client certificate",
                    )
                    .into_http();
                }
            };
            Status::unauthenticated(message).into_http()
        }
    }
}

/// tonic answers a message over `max_decoding_message_size` with OUT_OF_RANGE;
/// the gRPC status-code guide (and grpc-go, grpc-java) use RESOURCE_EXHAUSTED
/// for it, as our REST side uses 413. The status arrives in the headers of a
/// trailers-only response or in the trailers, so both are rewritten.
fn remap_client_error_statuses(response: Response) -> Response {
    let (mut parts, body) = response.into_parts();
    remap_client_error_status(&mut parts.headers);
    Response::from_parts(parts, axum::body::Body::new(RemapTrailers(body)))
}

///
/// A request message that does not decompress as its `grpc-encoding` says
/// is the client's error, not INTERNAL as tonic answers it: INVALID_ARGUMENT.
fn remap_client_error_status(headers: &mut axum::http::HeaderMap) {
    let status = headers.get("grpc-status").map(|v| v.as_bytes().to_vec());
    // grpc-message is percent-encoded on the wire.
    let contains = |needle: &str| {
        headers.get("grpc-message").is_some_and(|v| {
            let m = v.as_bytes();
            let encoded = needle.replace(' ', "%20");
            [needle.as_bytes(), encoded.as_bytes()]
                .iter()
                .any(|n| m.windows(n.len()).any(|w| w == *n))
        })
    };
    match status.as_deref() {
        Some(b"11") if contains("too large") => {
            headers.insert("grpc-status", axum::http::HeaderValue::from_static("8"));
        }
        Some(b"13") if contains("Error decompressing") => {
            headers.insert("grpc-status", axum::http::HeaderValue::from_static("3"));
        }
        _ => {}
    }
}

/// A response body whose trailers go through [`remap_client_error_status`].
struct RemapTrailers(axum::body::Body);

impl http_body::Body for RemapTrailers {
    type Data = axum::body::Bytes;
    type Error = axum::Error;

    fn poll_frame(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        let polled = std::pin::Pin::new(&mut self.0).poll_frame(cx);
        polled.map(|frame| {
            frame.map(|frame| {
                frame.map(|frame| match frame.into_trailers() {
                    Ok(mut trailers) => {
                        remap_client_error_status(&mut trailers);
                        http_body::Frame::trailers(trailers)
                    }
                    Err(frame) => frame,
                })
            })
        })
    }

    fn is_end_stream(&self) -> bool {
        self.0.is_end_stream()
    }

    fn size_hint(&self) -> http_body::SizeHint {
        self.0.size_hint()
    }
}

/// Counts calls and records latency per gRPC method. The status is read from
/// the response headers, where tonic puts it for every unary error
/// (trailers-only response); a call without one there completed with OK.
async fn record_metrics(req: Request, next: Next) -> Response {
    let start = Instant::now();
    let known = req.extensions().get::<MatchedPath>().is_some();
    let path = req.uri().path().to_string();
    let response = next.run(req).await;
    let code = response
        .headers()
        .get("grpc-status")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.parse::<i32>().ok())
        .map_or(Code::Ok, Code::from_i32);
    // Unknown services and methods share one label so the label set stays bounded.
    let method = if known && code != Code::Unimplemented {
        path
    } else {
        "unknown".to_string()
    };
    metrics::counter!("grpc_requests_total", "method" => method.clone(), "code" => format!("{code:?}"))
        .increment(1);
    metrics::histogram!("grpc_request_duration_seconds", "method" => method)
        .record(start.elapsed().as_secs_f64());
    response
}

#[cfg(test)]
mod tests {
    use axum::{body::Body, routing::post};
    use tower::ServiceExt;

    use super::*;
    use crate::{auth::Tenant, config::Settings};

    /// The tenant a tonic service would see: tonic builds its `Request` from
    /// the http request, extensions included.
    async fn tenant_seen(metadata: &[(&str, &str)]) -> Result<String, String> {
        let mut settings = Settings::for_tests();
        settings.api_keys = Some("k1secret=acme,k2secret=globex".into());
        let state = AppState::for_tests(settings);
        let app = Router::new()
            .route(
                "/radar.fusion.v1.CorrelationService/EvaluateRules",
                post(|req: Request| async move {
                    let request = tonic::Request::from_http(req);
                    request
                        .extensions()
                        .get::<Tenant>()
                        .map_or_else(String::new, |t| t.0.clone())
                }),
            )
            .layer(middleware::from_fn_with_state(state, authenticate));
        let mut request = axum::http::Request::builder()
            .method("POST")
            .uri("/radar.fusion.v1.CorrelationService/EvaluateRules");
        for (name, value) in metadata {
            request = request.header(*name, *value);
        }
        let response = app
            .oneshot(request.body(Body::empty()).unwrap())
            .await
            .unwrap();
        if let Some(code) = response.headers().get("grpc-status") {
            return Err(code.to_str().unwrap().to_string());
        }
        let body = axum::body::to_bytes(response.into_body(), 1 << 16)
            .await
            .unwrap();
        Ok(String::from_utf8(body.to_vec()).unwrap())
    }

    #[test]
    fn the_stateless_services_run_on_the_lanes_and_the_sessions_do_not() {
        for path in [
            "/radar.fusion.v1.JpdaService/Update",
            "/radar.fusion.v1.CorrelationService/CorrelateTracks",
            "/radar.fusion.v1.DimensionService/Fuse",
        ] {
            assert!(runs_on_lane(path), "{path}");
        }
        for path in [
            "/radar.fusion.v1.SessionService/PushBatch",
            "/radar.fusion.v1.SessionService/Stream",
            "/grpc.health.v1.Health/Check",
            "/radar.fusion.v1.JpdaServiceX/Update",
            "/radar.fusion.v1.JpdaService",
            "/",
        ] {
            assert!(!runs_on_lane(path), "{path}");
        }
    }

    #[tokio::test]
    async fn services_see_the_tenant_of_the_key() {
        let bearer = tenant_seen(&[("authorization", "Bearer k1secret")]).await;
        assert_eq!(bearer.as_deref(), Ok("acme"));
        let api_key = tenant_seen(&[("x-api-key", "k2secret")]).await;
        assert_eq!(api_key.as_deref(), Ok("globex"));
        // `authorization` wins over `x-api-key`.
        let both = tenant_seen(&[
            ("authorization", "Bearer k1secret"),
            ("x-api-key", "k2secret"),
        ])
        .await;
        assert_eq!(both.as_deref(), Ok("acme"));
        // 16 = UNAUTHENTICATED.
        assert_eq!(tenant_seen(&[]).await, Err("16".to_string()));
    }
}
