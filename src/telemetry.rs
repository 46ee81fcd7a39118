//! Logs and metrics: the `tracing` subscriber (text or JSON lines) and the
//! process-wide Prometheus recorder behind `/metrics`.

use std::{io::IsTerminal, sync::OnceLock, time::Duration};

use axum::{Router, extract::Request, http::HeaderName, response::Response};
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};
use tower_http::{
    classify::ServerErrorsFailureClass,
    request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer},
    trace::{DefaultOnRequest, TraceLayer},
};
use tracing::{Level, Span};
use tracing_subscriber::{EnvFilter, fmt, prelude::*};

use crate::config::{AccessLog, LogFormat};

/// Latency buckets in seconds, from 50 µs to 30 s.
const LATENCY_BUCKETS: &[f64] = &[
    0.000_05, 0.000_1, 0.000_25, 0.000_5, 0.001, 0.002_5, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5,
    1.0, 2.5, 5.0, 10.0, 30.0,
];

/// Buckets of `fusion_asterix_latency_seconds` (a datagram's receipt to
/// its batch's applied update), 1 ms to 30 s, a tenth of a second apart
/// up to 1 s so that the quantiles about a 1-s budget are read closely.
const ASTERIX_LATENCY_BUCKETS: &[f64] = &[
    0.001, 0.002_5, 0.005, 0.01, 0.025, 0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0,
    1.5, 2.0, 3.0, 5.0, 10.0, 30.0,
];

/// Installs the global log subscriber. Calling it again is harmless (tests
/// start several servers in one process).
pub fn init_logging(filter: &str, format: LogFormat) {
    let filter = EnvFilter::try_new(filter).unwrap_or_else(|_| EnvFilter::new("info"));
    let registry = tracing_subscriber::registry().with(filter);
    // Colour codes only for a terminal: never in files or log collectors.
    let ansi = std::io::stdout().is_terminal();
    let _ = match format {
        LogFormat::Text => registry
            .with(fmt::layer().with_target(false).with_ansi(ansi))
            .try_init(),
        LogFormat::Json => registry
            .with(
                fmt::layer()
                    .json()
                    .flatten_event(true)
                    .with_current_span(true),
            )
            .try_init(),
    };
}

/// The process-wide metrics recorder, installed on first use.
pub fn metrics_handle() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            let recorder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("duration_seconds".into()), LATENCY_BUCKETS)
                .expect("the bucket list is not empty")
                .set_buckets_for_metric(
                    Matcher::Full("fusion_asterix_latency_seconds".into()),
                    ASTERIX_LATENCY_BUCKETS,
                )
                .expect("the bucket list is not empty")
                .build_recorder();
            let handle = recorder.handle();
            // Fails only when another recorder is installed already, in which
            // case ours just stays empty.
            let _ = metrics::set_global_recorder(recorder);
            handle
        })
        .clone()
}

/// Wraps a router so that every request has an `x-request-id` (generated when
/// the client sends none, echoed in the response) and runs in a span that
/// carries it, so every log line of the request names it. Each response is
/// logged at the `access` level with its status and latency (or not at
/// all); a 5xx other than 503 and 504 at ERROR; shed (503) and timed-out
/// (504) requests at DEBUG only (they are counted in the metrics: a flood
/// of them must not flood the log).
pub fn with_request_tracing(router: Router, access: AccessLog) -> Router {
    let x_request_id = HeaderName::from_static("x-request-id");
    router
        .layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(
            TraceLayer::new_for_http()
                .make_span_with(|req: &Request| {
                    let id = req
                        .headers()
                        .get("x-request-id")
                        .and_then(|v| v.to_str().ok())
                        .unwrap_or("-");
                    tracing::info_span!(
                        "request",
                        request_id = %id,
                        method = %req.method(),
                        uri = %req.uri()
                    )
                })
                .on_request(DefaultOnRequest::new().level(Level::DEBUG))
                .on_response(move |res: &Response, latency: Duration, _: &Span| {
                    let status = res.status().as_u16();
                    let micros = latency.as_micros();
                    match access {
                        AccessLog::Off => {}
                        AccessLog::Debug => tracing::debug!(status, latency_us = micros, "response"),
                        AccessLog::Info => tracing::info!(status, latency_us = micros, "response"),
                    }
                })
                .on_failure(
                    |class: ServerErrorsFailureClass, latency: Duration, _: &Span| {
                        let micros = latency.as_micros();
                        match class {
                            ServerErrorsFailureClass::StatusCode(s)
                                if s.as_u16() == 503 || s.as_u16() == 504 =>
                            {
                                tracing::debug!(status = s.as_u16(), latency_us = micros, "shed or timed out")
                            }
                            other => tracing::error!(failure = %other, latency_us = micros, "server error"),
                        }
                    },
                ),
        )
        .layer(SetRequestIdLayer::new(x_request_id, MakeRequestUuid))
}
