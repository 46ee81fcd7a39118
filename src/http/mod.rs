//! The axum adapter: DTOs (serde + utoipa), routes, the OpenAPI document and
//! the mapping of service errors to problem details. It calls the `service`
//! layer and nothing else of the application.

pub mod ais_radar;
pub mod correlation;
pub mod dimension;
pub mod events;
pub mod identity;
pub mod jpda;
pub mod ops;
pub mod plot_fusion;
pub mod problem;
pub mod rules;
pub mod sessions;
pub mod view;

use std::time::Instant;

use axum::{
    Router,
    extract::{DefaultBodyLimit, MatchedPath, Request, State},
    http::{StatusCode, header},
    middleware::{self, Next},
    response::{IntoResponse, Response},
    routing::{get, post},
};
use serde::Serialize;
use tower::ServiceExt;
use tower_http::{
    compression::CompressionLayer, decompression::RequestDecompressionLayer, timeout::TimeoutLayer,
};
use utoipa::{OpenApi, ToSchema};
use utoipa_swagger_ui::SwaggerUi;

use crate::{
    auth::{AuthError, CertTenant},
    state::{AppState, BodyReadError},
};
use problem::Problem;

/// Where the time of a request went.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Timing {
    /// Microseconds spent in the numerical computation.
    #[schema(example = 3.2)]
    pub compute_us: f64,
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "Radar fusion service",
        description = "Fusion centre of a radar network: track-to-track correlation, JPDA, \
            multi-radar plot-fusion tracking, 2D/3D dimension fusion and AIS–radar bias estimation. Errors are RFC 9457 \
            problem details naming the offending field. The same operations are served \
            over gRPC (package radar.fusion.v1)."
    ),
    paths(correlation::correlate, sessions::create, sessions::list, sessions::get, sessions::delete, sessions::push, events::events, jpda::update, plot_fusion::track, dimension::fuse, ais_radar::associate, rules::evaluate, rules::recommend, ops::healthz, ops::store_health, ops::readyz, ops::metrics),
    components(schemas(Problem, problem::ProblemField, events::WatchEnd, events::SessionStreamEvent)),
    modifiers(&BearerAuth, &Version32),
    tags(
        (name = "correlation", description = "Track-to-track correlation (seed 000)"),
        (name = "sessions", description = "Streaming correlation sessions: state carried across batches"),
        (name = "jpda", description = "Joint probabilistic data association (seed 002)"),
        (name = "plot-fusion", description = "Multi-radar plot fusion tracker (seed 001)"),
        (name = "dimension", description = "Fusion of 2D and 3D radar tracks (seed 003)"),
        (name = "ais-radar", description = "AIS–radar association and radar bias estimation (seed 004)"),
        (name = "operations", description = "Health, readiness and metrics"),
    )
)]
pub struct ApiDoc;

/// Serialises the document as OpenAPI 3.2, whose sequential media types let
/// `text/event-stream` describe each event with an `itemSchema` (the events
/// route); everything else reads as it did in 3.1.
struct Version32;

impl utoipa::Modify for Version32 {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        openapi.openapi = utoipa::openapi::OpenApiVersion::Version32;
    }
}

/// The name of the bearer security scheme in the OpenAPI document.
const BEARER: &str = "bearer";

/// Declares the bearer (API key) security scheme and applies it, with its 401
/// answer, to every `/v1/` operation; the operational routes stay open.
struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{
            HttpAuthScheme, HttpBuilder, SecurityRequirement, SecurityScheme,
        };
        openapi
            .components
            .get_or_insert_with(Default::default)
            .add_security_scheme(
                BEARER,
                SecurityScheme::Http(
                    HttpBuilder::new()
                        .scheme(HttpAuthScheme::Bearer)
                        .description(Some(
                            "An API key configured with --api-keys or --api-keys-file, sent as \
                             `Authorization: Bearer <key>`. Not required when the service runs \
                             without keys (every request is then tenant `default`).",
                        ))
                        .build(),
                ),
            );
        let unauthorized = unauthorized_response();
        let (common, with_body) = problem_responses();
        for (path, item) in &mut openapi.paths.paths {
            if !path.starts_with("/v1/") {
                continue;
            }
            if let (Some(post), Some(example)) = (&mut item.post, request_example(path))
                && let Some(utoipa::openapi::RefOr::T(body)) = &mut post.request_body
                && let Some(utoipa::openapi::RefOr::T(content)) =
                    body.content.get_mut("application/json")
            {
                content.example = Some(example);
            }
            if let Some(post) = &mut item.post {
                for (status, response) in &with_body {
                    add_response(&mut post.responses, status, response);
                }
            }
            let operations = [
                &mut item.get,
                &mut item.put,
                &mut item.post,
                &mut item.delete,
                &mut item.patch,
            ];
            for operation in operations.into_iter().flatten() {
                operation.security =
                    Some(vec![SecurityRequirement::new(BEARER, Vec::<String>::new())]);
                operation
                    .responses
                    .responses
                    .insert("401".to_string(), unauthorized.clone().into());
                for (status, response) in &common {
                    add_response(&mut operation.responses, status, response);
                }
            }
        }
    }
}

/// The 401 of every API operation: a problem body and the challenge.
fn unauthorized_response() -> utoipa::openapi::Response {
    use utoipa::openapi::{
        ContentBuilder, HeaderBuilder, ObjectBuilder, Ref, ResponseBuilder, Type,
    };
    ResponseBuilder::new()
        .description("Missing, malformed or unknown API key")
        .content(
            problem::PROBLEM_JSON,
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Problem")))
                .build(),
        )
        .header(
            "WWW-Authenticate",
            HeaderBuilder::new()
                .schema(Some(ObjectBuilder::new().schema_type(Type::String)))
                .description(Some(
                    "`Bearer realm=\"radar-fusion\"`, with `error` for a bad key",
                ))
                .build(),
        )
        .build()
}

/// A status and the response documented for it.
type Answer = (&'static str, utoipa::openapi::Response);

/// The answers every API operation can give besides its own, and those of
/// every operation with a body, each with an example of its problem body.
fn problem_responses() -> ([Answer; 2], [Answer; 4]) {
    use utoipa::openapi::{ContentBuilder, Ref, ResponseBuilder};
    let problem = |status: u16, description: &str| {
        let code = StatusCode::from_u16(status).expect("a status");
        let body = Problem::for_status(code);
        let example = serde_json::to_value(&body).expect("a problem serialises");
        ResponseBuilder::new()
            .description(description)
            .content(
                problem::PROBLEM_JSON,
                ContentBuilder::new()
                    .schema(Some(Ref::from_schema_name("Problem")))
                    .example(Some(example))
                    .build(),
            )
            .build()
    };
    let common = [
        (
            "503",
            problem(
                503,
                "Shed (too many requests in flight, the request bodies being read hold \
                     FUSION_MAX_BUFFERED_BODY_BYTES, or every compute lane is busy and \
                     FUSION_MAX_BLOCKING_JOBS computations wait for the blocking pool; \
                     `Retry-After`), or a session store that \
                     does not answer (`Retry-After`; for a session write the outcome is unknown: \
                     retry with the same sequence number)",
            ),
        ),
        (
            "504",
            problem(
                504,
                "The request ran past FUSION_REQUEST_TIMEOUT_S (its computation stops at its \
                 next checkpoint)",
            ),
        ),
    ];
    let with_body = [
        (
            "400",
            problem(400, "The body is not JSON, or not the expected JSON object"),
        ),
        (
            "408",
            problem(
                408,
                "The body did not arrive within FUSION_BODY_READ_TIMEOUT_S (the connection \
                     is closed)",
            ),
        ),
        (
            "413",
            problem(
                413,
                "The body exceeds FUSION_MAX_BODY_BYTES, or a count limit",
            ),
        ),
        (
            "415",
            problem(415, "The Content-Type is not application/json"),
        ),
    ];
    (common, with_body)
}

/// A working request for each POST operation ("Try it out" on the docs
/// page sends it; a test posts each and expects success), the docs'
/// examples in full.
fn request_example(path: &str) -> Option<serde_json::Value> {
    let text = request_example_text(path)?;
    Some(serde_json::from_str(text).expect("the checked-in examples are JSON"))
}

/// The text of [`request_example`]'s example for `path`.
fn request_example_text(path: &str) -> Option<&'static str> {
    Some(match path {
        "/v1/correlation/rules/evaluate" => {
            include_str!("../../openapi/examples/rules_evaluate.json")
        }
        "/v1/correlation/rules/recommend" => {
            include_str!("../../openapi/examples/rules_recommend.json")
        }
        "/v1/correlation/tracks" => include_str!("../../openapi/examples/correlation_tracks.json"),
        "/v1/ais-radar/associate" => {
            include_str!("../../openapi/examples/ais_radar_associate.json")
        }
        "/v1/jpda/update" => include_str!("../../openapi/examples/jpda_update.json"),
        "/v1/dimension/fuse" => include_str!("../../openapi/examples/dimension_fuse.json"),
        "/v1/plot-fusion/track" => include_str!("../../openapi/examples/plot_fusion_track.json"),
        "/v1/sessions" => include_str!("../../openapi/examples/sessions_create.json"),
        "/v1/sessions/{id}/batches" => include_str!("../../openapi/examples/sessions_batch.json"),
        _ => return None,
    })
}

/// Adds `response` under `status`; an operation's own response for that
/// status keeps its description and gains the problem example if it has
/// none (the schema's own example is a 422's).
fn add_response(
    responses: &mut utoipa::openapi::Responses,
    status: &str,
    response: &utoipa::openapi::Response,
) {
    use utoipa::openapi::RefOr;
    match responses.responses.get_mut(status) {
        None => {
            responses
                .responses
                .insert(status.to_string(), response.clone().into());
        }
        Some(RefOr::T(own)) => {
            let example = match response.content.get(problem::PROBLEM_JSON) {
                Some(RefOr::T(c)) => c.example.clone(),
                _ => None,
            };
            if let Some(RefOr::T(content)) = own.content.get_mut(problem::PROBLEM_JSON)
                && content.example.is_none()
            {
                content.example = example;
            }
        }
        Some(RefOr::Ref(_)) => {}
    }
}

/// The OpenAPI document as checked in at `openapi/openapi.json`.
pub fn openapi_json() -> String {
    let mut json = ApiDoc::openapi()
        .to_pretty_json()
        .expect("the OpenAPI document serialises");
    json.push('\n');
    json
}

/// The start-up warm-up, before the service reports ready: on every
/// compute lane, `touch_mib` MiB of memory touched and given back to the
/// allocator (the kernel zeroes fresh pages on their first touch, which a
/// profile put at 80 % of a fresh lane's first dimension fusion), then the
/// dimension route's job on its example (the lane thread, its allocator
/// heap, code and tables met for the first time). Returns the lanes warmed
/// and the time taken; a lane whose warm-up failed is logged and serves
/// anyway.
pub async fn warm_up(touch_mib: usize) -> (usize, std::time::Duration) {
    let start = std::time::Instant::now();
    let answers = service::lanes::on_every_lane(move || {
        service::lanes::touch_memory(touch_mib);
        dimension::warm_up()
    })
    .await;
    for answer in &answers {
        if let Err(problem) = answer {
            tracing::warn!(?problem, "the start-up warm-up of a compute lane failed");
        }
    }
    (answers.len(), start.elapsed())
}

/// The REST router: API routes behind authentication, the in-flight limit,
/// the timeout and the body limit; operational routes and the docs outside them; requests with a
/// gRPC content type handed to `grpc`, so one port serves both.
pub fn router(state: AppState, grpc: Router) -> Router {
    let settings = state.settings().clone();
    let api = Router::new()
        .route("/v1/correlation/rules/evaluate", post(rules::evaluate))
        .route("/v1/correlation/rules/recommend", post(rules::recommend))
        .route("/v1/correlation/tracks", post(correlation::correlate))
        .route("/v1/ais-radar/associate", post(ais_radar::associate))
        .route("/v1/jpda/update", post(jpda::update))
        .route("/v1/plot-fusion/track", post(plot_fusion::track))
        .route("/v1/sessions", post(sessions::create).get(sessions::list))
        .route(
            "/v1/sessions/{id}",
            get(sessions::get).delete(sessions::delete),
        )
        .route("/v1/sessions/{id}/batches", post(sessions::push))
        .route("/v1/dimension/fuse", post(dimension::fuse))
        .layer(DefaultBodyLimit::max(settings.max_body_bytes))
        .layer(TimeoutLayer::with_status_code(
            StatusCode::GATEWAY_TIMEOUT,
            settings.request_timeout(),
        ))
        .layer(middleware::from_fn_with_state(state.clone(), admit))
        // Outside `admit`, so the body limit applies to the decompressed
        // body (a gzip bomb is a 413); another encoding is a 415.
        .layer(RequestDecompressionLayer::new())
        .layer(middleware::from_fn_with_state(state.clone(), authenticate));

    // Long-lived streams: authenticated, but outside the in-flight limit
    // and the request timeout (a watch holds no compute slot; its own
    // bounds are the watcher caps).
    let streams = Router::new()
        .route("/v1/sessions/{id}/events", get(events::events))
        .layer(middleware::from_fn_with_state(state.clone(), authenticate));

    let router = Router::new()
        .merge(api)
        .merge(streams)
        .route("/view/", get(view::page))
        .route("/view/view.js", get(view::script))
        .route("/view/view.css", get(view::style))
        .route("/view", get(view::redirect))
        .route("/healthz", get(ops::healthz))
        .route("/readyz", get(ops::readyz))
        .route("/healthz/store", get(ops::store_health))
        .route("/metrics", get(ops::metrics))
        .merge(SwaggerUi::new("/docs").url("/openapi.json", ApiDoc::openapi()))
        .fallback(not_found)
        .method_not_allowed_fallback(method_not_allowed)
        .layer(middleware::from_fn(record_metrics))
        .with_state(state)
        .layer(CompressionLayer::new())
        .layer(middleware::from_fn(problem::problem_for_bare_errors))
        .layer(middleware::from_fn_with_state(grpc, dispatch_grpc));
    crate::telemetry::with_request_tracing(router, settings.access_log)
}

/// Answers 401 to an API request without a valid `Authorization: Bearer <key>`
/// (when keys are configured) and no client certificate that stands for a
/// tenant, 403 to a key of another tenant than the certificate's, before it
/// takes an in-flight slot; otherwise puts its `Tenant` into the request
/// extensions (`Extension<Tenant>`).
async fn authenticate(State(state): State<AppState>, mut req: Request, next: Next) -> Response {
    // A value that is not visible ASCII is malformed, as an empty one is.
    let authorization = req
        .headers()
        .get(header::AUTHORIZATION)
        .map(|v| v.to_str().unwrap_or(""));
    let cert = req.extensions().get::<CertTenant>();
    let authenticated = state
        .api_keys()
        .authenticate_request(cert, authorization, None);
    match authenticated {
        Ok(tenant) => {
            req.extensions_mut().insert(tenant);
            next.run(req).await
        }
        Err(error) => {
            metrics::counter!("auth_failures_total", "transport" => "http").increment(1);
            // The body is not read: say that the connection closes, so a
            // keep-alive client opens a new one instead of meeting a reset.
            let mut response = match error {
                AuthError::TenantMismatch => problem::forbidden(error),
                AuthError::Missing | AuthError::Malformed | AuthError::UnknownKey => {
                    problem::unauthenticated(error)
                }
            };
            response.headers_mut().insert(
                header::CONNECTION,
                header::HeaderValue::from_static("close"),
            );
            response
        }
    }
}

/// Reads an API request's whole body first, within the body limit, the
/// body-read timeout (`FUSION_BODY_READ_TIMEOUT_S`) and the global budget of
/// buffered body bytes (`FUSION_MAX_BUFFERED_BODY_BYTES`), and only then
/// takes an in-flight slot: a client that sends its headers and then
/// trickles or withholds its body holds no slot, and is answered 408 when
/// the timeout passes; bodies that would take the buffered bytes over the
/// budget are shed with 503 as they arrive. Sheds the request with 503 when
/// `max_in_flight` are being served. The body's bytes stay charged to the
/// budget until the request is answered.
async fn admit(State(state): State<AppState>, req: Request, next: Next) -> Response {
    let (parts, body) = req.into_parts();
    let limit = state.settings().max_body_bytes;
    let (bytes, _charge) = match state.read_body(body, limit).await {
        Ok(read) => read,
        Err(e) => return body_error(e, &state),
    };
    let req = Request::from_parts(parts, axum::body::Body::from(bytes));
    match state.try_admit() {
        Some(admission) => service::lanes::admitted(admission, next.run(req)).await,
        None => {
            metrics::counter!("requests_shed_total", "transport" => "http").increment(1);
            Problem::for_status(StatusCode::SERVICE_UNAVAILABLE).into_response()
        }
    }
}

/// The answer to a body that could not be read: over the limit (after
/// decompression) a 413 naming it; over the budget of buffered bytes a 503
/// with `Retry-After`; a body that does not decompress as its
/// `Content-Encoding` says a 400; the connection failed mid-body a 400 that
/// nobody may read; too slow a 408. Every answer but the 400 of a body that
/// does not decompress leaves the rest of the body unread, so it closes the
/// connection.
fn body_error(e: BodyReadError, state: &AppState) -> Response {
    let malformed = |detail: String| {
        Problem::new(
            StatusCode::BAD_REQUEST,
            "malformed-body",
            "Malformed body",
            detail,
        )
        .into_response()
    };
    let mut response = match e {
        BodyReadError::TooLarge => Problem::new(
            StatusCode::PAYLOAD_TOO_LARGE,
            "payload-too-large",
            "Payload too large",
            format!(
                "the request body exceeds {} bytes (FUSION_MAX_BODY_BYTES; a compressed body \
                 counts decompressed)",
                state.settings().max_body_bytes
            ),
        )
        .into_response(),
        BodyReadError::OverBudget => Problem::new(
            StatusCode::SERVICE_UNAVAILABLE,
            "overloaded",
            "Service overloaded",
            format!(
                "the request bodies being read hold the budget of {} buffered bytes \
                 (FUSION_MAX_BUFFERED_BODY_BYTES); retry shortly",
                state.settings().max_buffered_body_bytes
            ),
        )
        .into_response(),
        BodyReadError::Undecodable(io) => {
            return malformed(format!(
                "the body does not decompress as its Content-Encoding says: {io}"
            ));
        }
        BodyReadError::Failed(e) => malformed(format!("the body could not be read: {e}")),
        BodyReadError::TimedOut => Problem::for_status(StatusCode::REQUEST_TIMEOUT).into_response(),
    };
    response.headers_mut().insert(
        header::CONNECTION,
        header::HeaderValue::from_static("close"),
    );
    response
}

/// Hands requests with a gRPC content type to the gRPC router.
async fn dispatch_grpc(State(grpc): State<Router>, req: Request, next: Next) -> Response {
    let is_grpc = req
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/grpc"));
    if is_grpc {
        match grpc.oneshot(req).await {
            Ok(response) => response,
            Err(never) => match never {},
        }
    } else {
        next.run(req).await
    }
}

/// Counts requests and records their latency per route (the route template,
/// so the label set stays bounded).
async fn record_metrics(req: Request, next: Next) -> Response {
    let start = Instant::now();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_string(), |p| p.as_str().to_string());
    let method = method_label(req.method());
    let response = next.run(req).await;
    let status = response.status().as_u16().to_string();
    metrics::counter!("http_requests_total", "method" => method, "route" => route.clone(), "status" => status)
        .increment(1);
    metrics::histogram!("http_request_duration_seconds", "method" => method, "route" => route)
        .record(start.elapsed().as_secs_f64());
    response
}

/// The metrics label of a method: the standard ones by name, any other
/// token (a client may send anything) folded into `other`, so that the
/// label set stays bounded.
fn method_label(m: &axum::http::Method) -> &'static str {
    use axum::http::Method;
    match *m {
        Method::GET => "GET",
        Method::POST => "POST",
        Method::PUT => "PUT",
        Method::DELETE => "DELETE",
        Method::PATCH => "PATCH",
        Method::HEAD => "HEAD",
        Method::OPTIONS => "OPTIONS",
        Method::TRACE => "TRACE",
        Method::CONNECT => "CONNECT",
        _ => "other",
    }
}

async fn not_found() -> Problem {
    Problem::for_status(StatusCode::NOT_FOUND)
}

async fn method_not_allowed() -> Problem {
    Problem::for_status(StatusCode::METHOD_NOT_ALLOWED)
}

#[cfg(test)]
mod tests {
    use axum::{Extension, body::Body};

    use super::*;
    use crate::{auth::Tenant, config::Settings};

    fn state(keys: Option<&str>) -> AppState {
        let mut settings = Settings::for_tests();
        settings.api_keys = keys.map(Into::into);
        AppState::for_tests(settings)
    }

    async fn tenant_seen(state: AppState, authorization: Option<&str>) -> (StatusCode, String) {
        let app = Router::new()
            .route(
                "/v1/whoami",
                get(|Extension(tenant): Extension<Tenant>| async move { tenant.0 }),
            )
            .layer(middleware::from_fn_with_state(state, authenticate));
        let mut request = axum::http::Request::builder().uri("/v1/whoami");
        if let Some(value) = authorization {
            request = request.header(header::AUTHORIZATION, value);
        }
        let response = app
            .oneshot(request.body(Body::empty()).unwrap())
            .await
            .unwrap();
        let status = response.status();
        let body = axum::body::to_bytes(response.into_body(), 1 << 16)
            .await
            .unwrap();
        (status, String::from_utf8(body.to_vec()).unwrap())
    }

    #[tokio::test]
    async fn the_warm_up_answers_the_dimension_example_on_every_lane() {
        // The example has a 3D and a 2D track: every method's system tracks
        // hold both, and the job (parse, fuse, encode) succeeds on each
        // lane.
        let answer = dimension::warm_up().unwrap();
        assert!(answer > 0);
        let body = dimension::warm_up_answer().unwrap();
        let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
        let results = v["results"].as_array().unwrap();
        assert_eq!(results.len(), 3);
        for r in results {
            let members: usize = r["system_tracks"]
                .as_array()
                .unwrap()
                .iter()
                .map(|t| t["members"].as_array().unwrap().len())
                .sum();
            assert_eq!(members, 2, "{r}");
        }
        let lanes = std::thread::available_parallelism().map_or(1, |n| n.get());
        assert_eq!(warm_up(1).await.0, lanes);
    }

    #[tokio::test]
    async fn handlers_see_the_tenant_of_the_key() {
        let keyed = state(Some("k1secret=acme,k2secret=globex"));
        let seen = tenant_seen(keyed.clone(), Some("Bearer k2secret")).await;
        assert_eq!(seen, (StatusCode::OK, "globex".to_string()));
        let (status, _) = tenant_seen(keyed, None).await;
        assert_eq!(status, StatusCode::UNAUTHORIZED);
        let open = tenant_seen(state(None), None).await;
        assert_eq!(open, (StatusCode::OK, "default".to_string()));
    }
}
