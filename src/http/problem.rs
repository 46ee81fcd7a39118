//! RFC 9457 problem details: the one error body of the REST API, the JSON
//! extractor whose rejections use it, and the middleware that gives a problem
//! body to the bare error responses of the framework and the tower layers
//! (405, 413, 504, 503).

use axum::{
    body::Bytes,
    extract::{FromRequest, Request, rejection::BytesRejection},
    http::{HeaderValue, StatusCode, header},
    middleware::Next,
    response::{IntoResponse, Response},
};
use serde::{Serialize, de::DeserializeOwned};
use utoipa::ToSchema;

use crate::auth::AuthError;
use service::{FieldViolation, ServiceError};

pub const PROBLEM_JSON: &str = "application/problem+json";

/// A problem details body (RFC 9457) with the field violations of API.md.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Problem {
    /// A URI naming the kind of problem.
    #[schema(example = "urn:radar-fusion:problem:invalid-input")]
    #[serde(rename = "type")]
    pub kind: String,
    #[schema(example = "Invalid input")]
    pub title: String,
    #[schema(example = 422)]
    pub status: u16,
    #[schema(example = "the request has 1 invalid field(s)")]
    pub detail: String,
    /// One entry per offending field, with its path in the request.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub errors: Vec<ProblemField>,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ProblemField {
    #[schema(example = "rules[0].l")]
    pub field: String,
    #[schema(example = "must be between 1 and r = 4")]
    pub message: String,
}

impl Problem {
    pub fn new(status: StatusCode, kind: &str, title: &str, detail: impl Into<String>) -> Self {
        Self {
            kind: format!("urn:radar-fusion:problem:{kind}"),
            title: title.to_string(),
            status: status.as_u16(),
            detail: detail.into(),
            errors: Vec::new(),
        }
    }

    fn invalid(status: StatusCode, detail: impl Into<String>, errors: Vec<ProblemField>) -> Self {
        Self {
            errors,
            ..Self::new(status, "invalid-input", "Invalid input", detail)
        }
    }

    /// The problem for a status the framework or a layer produced without a body.
    pub fn for_status(status: StatusCode) -> Self {
        let (kind, title, detail) = match status {
            StatusCode::UNAUTHORIZED => (
                "unauthenticated",
                "Unauthenticated",
                "a valid API key is required: send `Authorization: Bearer <key>`",
            ),
            StatusCode::NOT_FOUND => ("not-found", "Not found", "no such route"),
            StatusCode::METHOD_NOT_ALLOWED => (
                "method-not-allowed",
                "Method not allowed",
                "the route does not accept this method",
            ),
            StatusCode::PAYLOAD_TOO_LARGE => (
                "payload-too-large",
                "Payload too large",
                "the request body exceeds the configured limit (FUSION_MAX_BODY_BYTES)",
            ),
            StatusCode::GATEWAY_TIMEOUT => (
                "timeout",
                "Request timed out",
                "the request took longer than the configured limit (FUSION_REQUEST_TIMEOUT_S)",
            ),
            StatusCode::SERVICE_UNAVAILABLE => (
                "overloaded",
                "Service overloaded",
                "too many requests in flight; retry shortly",
            ),
            StatusCode::REQUEST_TIMEOUT => (
                "body-timeout",
                "Request body too slow",
                "the request body did not arrive within the configured limit \
                 (FUSION_BODY_READ_TIMEOUT_S)",
            ),
            _ => (
                "http-error",
                status.canonical_reason().unwrap_or("Error"),
                "",
            ),
        };
        Self::new(status, kind, title, detail)
    }
}

/// The 403 answer to a request whose credentials are valid but disagree
/// (an API key of another tenant than the client certificate's): a problem
/// of type `forbidden`.
pub fn forbidden(error: AuthError) -> Response {
    Problem::new(
        StatusCode::FORBIDDEN,
        "forbidden",
        "Forbidden",
        error.to_string(),
    )
    .into_response()
}

/// The 401 answer to a request without valid credentials: a problem of type
/// `unauthenticated` and a `WWW-Authenticate: Bearer` challenge (RFC 6750 §3).
pub fn unauthenticated(error: AuthError) -> Response {
    let challenge = match error {
        AuthError::Missing => r#"Bearer realm="radar-fusion""#,
        AuthError::Malformed => r#"Bearer realm="radar-fusion", error="invalid_request""#,
        AuthError::UnknownKey => r#"Bearer realm="radar-fusion", error="invalid_token""#,
        // Answered by `forbidden`; should it come here, still a challenge.
        AuthError::TenantMismatch => r#"Bearer realm="radar-fusion", error="invalid_token""#,
    };
    let problem = Problem::new(
        StatusCode::UNAUTHORIZED,
        "unauthenticated",
        "Unauthenticated",
        error.to_string(),
    );
    let mut response = problem.into_response();
    response.headers_mut().insert(
        header::WWW_AUTHENTICATE,
        HeaderValue::from_static(challenge),
    );
    response
}

impl IntoResponse for Problem {
    fn into_response(self) -> Response {
        let status = StatusCode::from_u16(self.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        let retry = status == StatusCode::SERVICE_UNAVAILABLE;
        let mut response = (status, axum::Json(self)).into_response();
        let headers = response.headers_mut();
        headers.insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
        if retry {
            headers.insert(header::RETRY_AFTER, HeaderValue::from_static("1"));
        }
        response
    }
}

impl From<ServiceError> for Problem {
    fn from(e: ServiceError) -> Self {
        match e {
            ServiceError::InvalidInput(violations) => Problem::invalid(
                StatusCode::UNPROCESSABLE_ENTITY,
                format!("the request has {} invalid field(s)", violations.len()),
                violations.into_iter().map(ProblemField::from).collect(),
            ),
            ServiceError::Internal(detail) => {
                // Logged once here, never sent.
                tracing::error!(%detail, "internal error");
                Problem::new(
                    StatusCode::INTERNAL_SERVER_ERROR,
                    "internal",
                    "Internal error",
                    "the service failed unexpectedly; the incident is logged",
                )
            }
            ServiceError::NotFound(detail) => {
                Problem::new(StatusCode::NOT_FOUND, "not-found", "Not found", detail)
            }
            ServiceError::Conflict(detail) => Problem::new(
                StatusCode::CONFLICT,
                "sequence-conflict",
                "Batch out of sequence",
                detail,
            ),
            ServiceError::QuotaExceeded(detail) => Problem::new(
                StatusCode::TOO_MANY_REQUESTS,
                "quota-exceeded",
                "Quota exceeded",
                detail,
            ),
            ServiceError::TooLarge(detail) => Problem::new(
                StatusCode::PAYLOAD_TOO_LARGE,
                "too-large",
                "Request too large",
                detail,
            ),
            ServiceError::Unavailable(detail) => Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "store-unavailable",
                "Session store unavailable",
                detail,
            ),
            ServiceError::Overloaded(detail) => Problem::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "overloaded",
                "Service overloaded",
                detail,
            ),
            ServiceError::Cancelled => Problem::for_status(StatusCode::GATEWAY_TIMEOUT),
        }
    }
}

impl From<FieldViolation> for ProblemField {
    fn from(v: FieldViolation) -> Self {
        Self {
            field: v.field,
            message: v.message,
        }
    }
}

/// A JSON body whose every rejection is a problem naming the field:
/// 415 without a JSON content type, 413 over the body limit, 400 for JSON that
/// does not parse, 422 for a value of the wrong type or a missing field.
/// Parsed on the async worker; the compute endpoints take a [`JsonBody`]
/// instead, parsed on the compute lane with the rest of the request.
pub struct ApiJson<T>(pub T);

impl<S, T> FromRequest<S> for ApiJson<T>
where
    S: Send + Sync,
    T: DeserializeOwned,
{
    type Rejection = Problem;

    async fn from_request(req: Request, state: &S) -> Result<Self, Problem> {
        let body = JsonBody::<T>::from_request(req, state).await?;
        parse_json(&body.bytes).map(ApiJson)
    }
}

/// The JSON body of a compute endpoint, its media type checked (415) and its
/// bytes read within the limit (413), not yet parsed: [`JsonBody::compute`]
/// parses it (400, 422 as [`ApiJson`]), runs the endpoint and encodes the
/// answer as one job on a compute lane. Parsing and encoding a large request
/// cost as much as its algorithm; on one thread they stay off the async
/// workers, and the request's memory is allocated and freed where it is used
/// (docs/RESULTS.md, "Request path").
pub struct JsonBody<T> {
    bytes: Bytes,
    request: std::marker::PhantomData<fn() -> T>,
}

impl<T: DeserializeOwned + 'static> JsonBody<T> {
    /// Parses the body into `T`, answers it with `work` and encodes the
    /// answer as a JSON response, on a compute lane.
    pub async fn compute<R, F>(self, work: F) -> Result<Response, Problem>
    where
        R: Serialize,
        F: FnOnce(T) -> Result<R, Problem> + Send + 'static,
    {
        let bytes = self.bytes;
        let encoded = service::lanes::run(move || answer_json(&bytes, work)).await??;
        Ok((
            [(
                header::CONTENT_TYPE,
                HeaderValue::from_static("application/json"),
            )],
            encoded,
        )
            .into_response())
    }
}

/// A compute endpoint's job: `bytes` parsed into `T` (400, 422 as
/// [`ApiJson`]), answered by `work`, the answer encoded as JSON.
pub fn answer_json<T, R, F>(bytes: &[u8], work: F) -> Result<Vec<u8>, Problem>
where
    T: DeserializeOwned,
    R: Serialize,
    F: FnOnce(T) -> Result<R, Problem>,
{
    // Between the steps, so that an abandoned request (its timeout
    // passed, or its client left) stops: after its JSON is parsed and
    // before its answer is encoded. Only stateless endpoints answer here.
    let request = parse_json(bytes)?;
    service::lanes::checkpoint()?;
    let answer = work(request)?;
    service::lanes::checkpoint()?;
    // Answers are up to a few times their requests (a JPDA update returns
    // each track it was given, 1.9×; AIS–radar every compensated sample,
    // 2.2×): sized once, the buffer is not copied through doublings on the
    // way (a 6.5 MB answer's one realloc was 15 % of its request's time,
    // issue 54). Capacity never written costs address space, not memory.
    let mut encoded = Vec::with_capacity((3 * bytes.len()).clamp(1 << 10, 1 << 26));
    serde_json::to_writer(&mut encoded, &answer)
        .map_err(|e| Problem::from(ServiceError::Internal(format!("response encoding: {e}"))))?;
    Ok(encoded)
}

impl<S, T> FromRequest<S> for JsonBody<T>
where
    S: Send + Sync,
{
    type Rejection = Problem;

    async fn from_request(req: Request, state: &S) -> Result<Self, Problem> {
        let is_json = req
            .headers()
            .get(header::CONTENT_TYPE)
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split(';').next())
            .map(|mime| {
                let mime = mime.trim().to_ascii_lowercase();
                mime == "application/json" || mime.ends_with("+json")
            })
            .unwrap_or(false);
        if !is_json {
            return Err(Problem::new(
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Unsupported media type",
                "send the body as application/json",
            ));
        }
        let bytes = Bytes::from_request(req, state)
            .await
            .map_err(|rejection| match rejection {
                BytesRejection::FailedToBufferBody(e)
                    if e.status() == StatusCode::PAYLOAD_TOO_LARGE =>
                {
                    Problem::for_status(StatusCode::PAYLOAD_TOO_LARGE)
                }
                other => Problem::new(
                    StatusCode::BAD_REQUEST,
                    "malformed-body",
                    "Malformed body",
                    other.body_text(),
                ),
            })?;
        Ok(JsonBody {
            bytes,
            request: std::marker::PhantomData,
        })
    }
}

/// Parses a JSON body, naming the field of a type error by its path. Every
/// request body of the API is a JSON object: other JSON (an array, which
/// serde would otherwise read as the fields in declaration order, a number,
/// a string, null) is a 422 on `body`, and text that is not JSON (a
/// truncated `[1,2` included) a 400.
pub fn parse_json<T: DeserializeOwned>(bytes: &[u8]) -> Result<T, Problem> {
    if let Some(&first) = bytes.iter().find(|b| !b.is_ascii_whitespace())
        && first != b'{'
    {
        if let Err(e) = serde_json::from_slice::<serde::de::IgnoredAny>(bytes) {
            return Err(malformed(&e));
        }
        let message = "must be a JSON object ({ … }), not an array, a number, a string or null";
        return Err(Problem::invalid(
            StatusCode::UNPROCESSABLE_ENTITY,
            format!("body: {message}"),
            vec![ProblemField {
                field: "body".into(),
                message: message.into(),
            }],
        ));
    }
    // The fast path: plain serde_json. Tracking the path of every value
    // (serde_path_to_error) cost about a third of the server's time on a
    // 500-track JPDA body; it is only needed to name the field of an error,
    // so a body that fails is parsed again with tracking (deterministic:
    // the same error, now with its path).
    if let Ok(value) = serde_json::from_slice(bytes) {
        return Ok(value);
    }
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let value = serde_path_to_error::deserialize(&mut de).map_err(|err| {
        let path = err.path().to_string();
        let inner = err.into_inner();
        match inner.classify() {
            serde_json::error::Category::Data => {
                let message = strip_position(&inner.to_string());
                let field = field_of(&path, &message);
                Problem::invalid(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    format!("{field}: {message}"),
                    vec![ProblemField { field, message }],
                )
            }
            // Valid JSON whose number no f64 holds (1e400): a value error
            // of that field, not malformed text.
            serde_json::error::Category::Syntax
                if inner.to_string().starts_with("number out of range") =>
            {
                let message = "number out of range: must be a finite number of magnitude \
                               below 1.8e308"
                    .to_string();
                let field = field_of(&path, &message);
                Problem::invalid(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    format!("{field}: {message}"),
                    vec![ProblemField { field, message }],
                )
            }
            _ => malformed(&inner),
        }
    })?;
    de.end().map_err(|e| malformed(&e))?;
    Ok(value)
}

fn malformed(e: &serde_json::Error) -> Problem {
    Problem::new(
        StatusCode::BAD_REQUEST,
        "malformed-json",
        "Malformed JSON",
        format!(
            "the body is not valid JSON ({}, line {}, column {}); note that JSON has no NaN or Infinity",
            strip_position(&e.to_string()),
            e.line(),
            e.column()
        ),
    )
}

/// The field a serde data error is about: its path, extended by the field
/// name for a missing field (serde reports that one at the parent).
fn field_of(path: &str, message: &str) -> String {
    let parent = if path == "." { "" } else { path };
    let named = message
        .strip_prefix("missing field `")
        .and_then(|rest| rest.split('`').next());
    match (parent, named) {
        ("", Some(name)) => name.to_string(),
        (parent, Some(name)) => format!("{parent}.{name}"),
        ("", None) => "body".to_string(),
        (parent, None) => parent.to_string(),
    }
}

/// serde_json appends " at line L column C"; the problem says it separately.
fn strip_position(message: &str) -> String {
    match message.rfind(" at line ") {
        Some(i) => message[..i].to_string(),
        None => message.to_string(),
    }
}

/// Gives a problem body to error responses that have none: axum's 405, the
/// body limit's 413, the timeout's 504, the load shedder's 503. A JSON body
/// of our own (`/readyz`'s 503 `not_ready`) is kept.
pub async fn problem_for_bare_errors(req: Request, next: Next) -> Response {
    let response = next.run(req).await;
    let status = response.status();
    let has_problem = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| {
            v.as_bytes().starts_with(PROBLEM_JSON.as_bytes())
                || v.as_bytes().starts_with(b"application/json")
        });
    let is_grpc = response
        .headers()
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"application/grpc"));
    if (status.is_client_error() || status.is_server_error()) && !has_problem && !is_grpc {
        let mut problem = Problem::for_status(status).into_response();
        // Keep headers such as Allow (405) from the original response.
        for (name, value) in response.headers() {
            if name != header::CONTENT_TYPE && name != header::CONTENT_LENGTH {
                problem.headers_mut().insert(name.clone(), value.clone());
            }
        }
        return problem;
    }
    response
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Inner {
        l: u32,
    }

    #[derive(Debug, serde::Deserialize)]
    #[serde(deny_unknown_fields)]
    #[allow(dead_code)]
    struct Outer {
        alpha: f64,
        rules: Vec<Inner>,
    }

    fn problem(body: &str) -> Problem {
        parse_json::<Outer>(body.as_bytes()).unwrap_err()
    }

    #[test]
    fn missing_nested_field_is_named_by_its_path() {
        let p = problem(r#"{"alpha": 0.1, "rules": [{"l": 1}, {}]}"#);
        assert_eq!(p.status, 422);
        assert_eq!(p.errors[0].field, "rules[1].l");
    }

    #[test]
    fn wrong_type_and_unknown_field_are_named() {
        assert_eq!(
            problem(r#"{"alpha": "x", "rules": []}"#).errors[0].field,
            "alpha"
        );
        assert_eq!(
            problem(r#"{"alpha": 0.1, "rules": [], "beta": 1}"#).errors[0].field,
            "beta"
        );
    }

    #[test]
    fn a_body_that_is_not_an_object_is_refused() {
        // An array would otherwise fill the fields in declaration order
        // ([0.1, []] is a valid Outer for serde).
        for body in ["[0.1, []]", "[1]", "42", "\"x\"", "null"] {
            let p = problem(body);
            assert_eq!(p.status, 422, "{body}: {p:?}");
            assert_eq!(p.errors[0].field, "body");
            assert!(p.errors[0].message.contains("JSON object"), "{body}: {p:?}");
        }
        // A truncated array is malformed JSON, not a field `[0]` to blame.
        let p = problem("  [1,2");
        assert_eq!(p.status, 400, "{p:?}");
        assert!(p.kind.ends_with("malformed-json"));
    }

    #[test]
    fn a_number_beyond_f64_is_a_value_error_of_its_field() {
        // 1e400 is valid JSON (RFC 8259 sets no range) but no f64: the field
        // is named, as for any other value out of range.
        for (body, field) in [
            (r#"{"alpha": 1e400, "rules": []}"#, "alpha"),
            (r#"{"alpha": 0.05, "rules": [{"l": -1e999}]}"#, "rules[0].l"),
        ] {
            let p = problem(body);
            assert_eq!(p.status, 422, "{body}: {p:?}");
            assert_eq!(p.errors.len(), 1, "{p:?}");
            assert_eq!(p.errors[0].field, field, "{p:?}");
            assert!(p.errors[0].message.contains("out of range"), "{p:?}");
        }
    }

    #[test]
    fn syntax_errors_and_non_finite_numbers_are_malformed_json() {
        for body in [
            r#"{"alpha": NaN, "rules": []}"#,
            r#"{"alpha": Infinity, "rules": []}"#,
            r#"{"alpha": 0.1"#,
            r#"{"alpha": 0.1, "rules": []} trailing"#,
            "",
        ] {
            let p = problem(body);
            assert_eq!(p.status, 400, "{body}: {p:?}");
            assert!(p.kind.ends_with("malformed-json"));
        }
    }
}
