//! Compressed request bodies (issue 18): REST `Content-Encoding: gzip` and
//! gRPC `grpc-encoding: gzip` are accepted, the body limit applies to the
//! decompressed size, and a body that does not decompress is the client's
//! error (400 / INVALID_ARGUMENT), never a 500.

use radar_fusion::proto as pb;
use serde_json::json;
use tonic::{Code, codec::CompressionEncoding};

use crate::helpers::{assert_problem, gzip, h2_connection, spawn_app, spawn_app_with};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";

async fn post_encoded(
    app: &crate::helpers::TestApp,
    encoding: &str,
    body: Vec<u8>,
) -> reqwest::Response {
    app.client
        .post(app.url(EVALUATE))
        .header("content-type", "application/json")
        .header("content-encoding", encoding)
        .body(body)
        .send()
        .await
        .unwrap()
}

#[tokio::test]
async fn a_gzip_body_is_answered_as_the_plain_one() {
    let app = spawn_app().await;
    let body = json!({"alpha": 0.05, "rules": [{"l": 3, "r": 4}, {"l": 6, "r": 8}]});
    let plain: serde_json::Value = app.post_ok(EVALUATE, &body).await;
    let response = post_encoded(&app, "gzip", gzip(body.to_string().as_bytes())).await;
    assert_eq!(response.status(), 200);
    let compressed: serde_json::Value = response.json().await.unwrap();
    assert_eq!(compressed["evaluations"], plain["evaluations"]);
}

#[tokio::test]
async fn the_body_limit_applies_to_the_decompressed_size() {
    let app = spawn_app_with(|s| s.max_body_bytes = 4096).await;
    // 100 kB of JSON (a long run of spaces is valid JSON whitespace) that
    // compresses to a few hundred bytes: under the limit on the wire, over
    // it decompressed.
    let mut text = String::from("{\"alpha\": 0.05, ");
    text.push_str(&" ".repeat(100_000));
    text.push_str("\"rules\": [{\"l\": 1, \"r\": 1}]}");
    let compressed = gzip(text.as_bytes());
    assert!(compressed.len() < 4096, "{} bytes", compressed.len());
    let response = post_encoded(&app, "gzip", compressed).await;
    assert_problem(response, 413).await;
}

#[tokio::test]
async fn a_body_that_is_not_gzip_is_a_400_and_another_encoding_a_415() {
    let app = spawn_app().await;
    let response = post_encoded(&app, "gzip", b"{\"alpha\": 0.05}".to_vec()).await;
    let problem = assert_problem(response, 400).await;
    assert!(
        problem["detail"].as_str().unwrap().contains("decompress"),
        "{problem}"
    );
    let mut truncated = gzip(br#"{"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}"#);
    truncated.truncate(truncated.len() / 2);
    let response = post_encoded(&app, "gzip", truncated).await;
    assert_problem(response, 400).await;
    let response = post_encoded(&app, "br", b"anything".to_vec()).await;
    assert_problem(response, 415).await;
}

fn evaluate_request() -> pb::EvaluateRulesRequest {
    pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![pb::LrRule {
            l: Some(3),
            r: Some(4),
        }],
    }
}

#[tokio::test]
async fn a_gzip_grpc_message_is_answered_as_the_plain_one() {
    let app = spawn_app().await;
    let plain = app
        .correlation()
        .await
        .evaluate_rules(evaluate_request())
        .await
        .unwrap()
        .into_inner();
    let compressed = app
        .correlation()
        .await
        .send_compressed(CompressionEncoding::Gzip)
        .accept_compressed(CompressionEncoding::Gzip)
        .evaluate_rules(evaluate_request())
        .await
        .unwrap()
        .into_inner();
    assert_eq!(compressed.evaluations, plain.evaluations);
}

#[tokio::test]
async fn a_grpc_message_over_the_limit_once_decompressed_is_resource_exhausted() {
    let app = spawn_app_with(|s| s.max_body_bytes = 4096).await;
    // 2,000 rules of a few bytes each: about 14 kB decoded, far less gzip.
    let request = pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![
            pb::LrRule {
                l: Some(1),
                r: Some(1),
            };
            2000
        ],
    };
    let status = app
        .correlation()
        .await
        .send_compressed(CompressionEncoding::Gzip)
        .evaluate_rules(request)
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
}

/// A gRPC frame flagged compressed whose bytes are not gzip: INVALID_ARGUMENT
/// (tonic's own answer would be INTERNAL).
#[tokio::test]
async fn a_grpc_message_that_does_not_decompress_is_invalid_argument() {
    let app = spawn_app().await;
    let payload = b"definitely not gzip";
    let mut frame = vec![1u8];
    frame.extend_from_slice(&(payload.len() as u32).to_be_bytes());
    frame.extend_from_slice(payload);
    let mut sender = h2_connection(app.grpc_addr).await;
    let request = hyper::Request::post(format!(
        "http://{}/radar.fusion.v1.CorrelationService/EvaluateRules",
        app.grpc_addr
    ))
    .header("content-type", "application/grpc")
    .header("grpc-encoding", "gzip")
    .header("te", "trailers")
    .body(http_body_util::Full::new(axum::body::Bytes::from(frame)))
    .unwrap();
    let response = sender.send_request(request).await.unwrap();
    let status = grpc_status(response).await;
    assert_eq!(status.as_deref(), Some("3"), "INVALID_ARGUMENT");
}

/// The `grpc-status` of a response, from its headers (trailers-only) or
/// its trailers.
async fn grpc_status(response: hyper::Response<hyper::body::Incoming>) -> Option<String> {
    use http_body_util::BodyExt;
    if let Some(v) = response.headers().get("grpc-status") {
        return Some(v.to_str().unwrap().to_string());
    }
    let collected = response.into_body().collect().await.unwrap();
    collected
        .trailers()
        .and_then(|t| t.get("grpc-status"))
        .map(|v| v.to_str().unwrap().to_string())
}
