//! Hostile clients (issue 53, second part): memory before admission. A
//! compressed body counts decompressed against `FUSION_MAX_BODY_BYTES`, the
//! bodies being read at once share the budget of
//! `FUSION_MAX_BUFFERED_BODY_BYTES` (beyond it: 503 + `Retry-After`, or
//! UNAVAILABLE; the message of a gRPC stream too), and an HTTP/2 connection carries at most
//! `FUSION_H2_MAX_CONCURRENT_STREAMS` requests at once.
//!
//! The waits below are bounds on an outcome (the server has read a body,
//! given its bytes back), never measurements of speed.

use std::time::Duration;

use radar_fusion::proto as pb;
use tokio::{io::AsyncWriteExt, net::TcpStream};
use tonic::Code;

use crate::helpers::{TestApp, assert_problem, gzip, spawn_app_with};
use crate::sessions::data::{open_stream, pb_open, pb_report, scenario};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";
const BOUND: Duration = Duration::from_secs(10);

/// A valid rules request padded with `pad` spaces (JSON whitespace): its
/// size is `pad` plus 43 bytes.
fn padded_request(pad: usize) -> String {
    let text = format!(
        "{{\"alpha\": 0.05,{}\"rules\": [{{\"l\": 1, \"r\": 1}}]}}",
        " ".repeat(pad)
    );
    assert_eq!(text.len(), pad + 43);
    text
}

async fn post_gzip(app: &TestApp, body: Vec<u8>) -> reqwest::Response {
    app.client
        .post(app.url(EVALUATE))
        .header("content-type", "application/json")
        .header("content-encoding", "gzip")
        .body(body)
        .send()
        .await
        .unwrap()
}

/// Waits until the bodies being read hold `at_least` bytes of the budget
/// (or, with `at_least` 0, until they hold none); panics after [`BOUND`].
async fn wait_for_buffered(app: &TestApp, at_least: usize) {
    let reached = |n: usize| {
        if at_least == 0 { n == 0 } else { n >= at_least }
    };
    let waited = tokio::time::timeout(BOUND, async {
        while !reached(app.state.buffered_body_bytes()) {
            tokio::time::sleep(Duration::from_millis(5)).await;
        }
    })
    .await;
    assert!(
        waited.is_ok(),
        "the budget holds {} bytes, waited for {at_least}",
        app.state.buffered_body_bytes()
    );
}

/// Opens an HTTP/1.1 request whose gzip body (inflating to `inflated`
/// bytes) arrives all but its last 8 bytes (the gzip trailer), and holds it
/// open: the probe, one connection of it.
async fn held_gzip_bomb(app: &TestApp, inflated: &[u8]) -> TcpStream {
    let body = gzip(inflated);
    let mut stream = TcpStream::connect(app.http_addr).await.unwrap();
    let head = format!(
        "POST {EVALUATE} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
         Content-Encoding: gzip\r\nContent-Length: {}\r\n\r\n",
        body.len()
    );
    stream.write_all(head.as_bytes()).await.unwrap();
    stream.write_all(&body[..body.len() - 8]).await.unwrap();
    stream
}

#[tokio::test]
async fn a_body_over_the_limit_once_decompressed_is_a_413_naming_the_limit() {
    let app = spawn_app_with(|s| s.max_body_bytes = 65_536).await;
    // 1 MiB of JSON that gzips to about 1 kB: far under the limit on the
    // wire, 16 times over it decompressed.
    let compressed = gzip(padded_request(1 << 20).as_bytes());
    assert!(compressed.len() < 4_096, "{} bytes", compressed.len());
    let problem = assert_problem(post_gzip(&app, compressed).await, 413).await;
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("65536 bytes") && detail.contains("FUSION_MAX_BODY_BYTES"),
        "{detail}"
    );
    // Refused bytes are given back at once.
    wait_for_buffered(&app, 0).await;
    // At the limit it is served: 65,493 spaces + 43 = 65,536 bytes.
    let response = post_gzip(&app, gzip(padded_request(65_493).as_bytes())).await;
    assert_eq!(response.status(), 200);
}

#[tokio::test]
async fn bodies_over_the_buffered_budget_are_shed_with_503_and_retry_after() {
    let app = spawn_app_with(|s| {
        s.max_body_bytes = 65_536;
        s.max_buffered_body_bytes = 65_536;
    })
    .await;
    // A held bomb inflating to 60,043 bytes takes all but 5,493 bytes of
    // the budget while it waits for its last 8 bytes.
    let held = held_gzip_bomb(&app, padded_request(60_000).as_bytes()).await;
    wait_for_buffered(&app, 60_043).await;

    // A 20,043-byte body does not fit: 503, Retry-After, the budget named.
    let response = app.post_raw(EVALUATE, &padded_request(20_000)).await;
    assert!(response.headers().contains_key("retry-after"));
    let problem = assert_problem(response, 503).await;
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains("65536 buffered bytes")
            && detail.contains("FUSION_MAX_BUFFERED_BODY_BYTES"),
        "{detail}"
    );
    // A gRPC message of 1,000 rules (6 bytes each: 6 kB) does not fit either.
    let request = pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![
            pb::LrRule {
                l: Some(1),
                r: Some(1),
            };
            1000
        ],
    };
    let status = app
        .correlation()
        .await
        .evaluate_rules(request.clone())
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::Unavailable, "{status:?}");
    assert!(
        status.message().contains("FUSION_MAX_BUFFERED_BODY_BYTES"),
        "{status:?}"
    );
    // A small request still fits in what is left.
    let response = app.post_raw(EVALUATE, &padded_request(1_000)).await;
    assert_eq!(response.status(), 200);

    // The held body's bytes come back when its client goes, and the large
    // requests are served again.
    drop(held);
    wait_for_buffered(&app, 0).await;
    let response = app.post_raw(EVALUATE, &padded_request(20_000)).await;
    assert_eq!(response.status(), 200);
    let answered = app.correlation().await.evaluate_rules(request).await;
    assert!(answered.is_ok(), "{answered:?}");
}

#[tokio::test]
async fn an_http2_connection_is_announced_the_configured_stream_cap() {
    let app = spawn_app_with(|s| s.h2_max_concurrent_streams = 7).await;
    for addr in [app.http_addr, app.grpc_addr] {
        let tcp = TcpStream::connect(addr).await.unwrap();
        let (client, connection) = h2::client::handshake(tcp).await.unwrap();
        tokio::spawn(connection);
        let mut client = client.ready().await.unwrap();
        // The server's SETTINGS arrive with the handshake; until then the
        // client assumes no cap.
        let announced = tokio::time::timeout(BOUND, async {
            loop {
                let n = client.current_max_send_streams();
                if n != usize::MAX {
                    return n;
                }
                client = client.ready().await.unwrap();
                tokio::time::sleep(Duration::from_millis(5)).await;
            }
        })
        .await
        .expect("the server's SETTINGS arrive");
        assert_eq!(announced, 7, "{addr}");
    }
}

#[tokio::test]
async fn a_stream_message_over_the_buffered_budget_ends_the_stream_unavailable() {
    let app = spawn_app_with(|s| {
        s.max_body_bytes = 65_536;
        s.max_buffered_body_bytes = 65_536;
    })
    .await;
    let (_, reports) = scenario();
    let batch = pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
            sequence: Some(1),
            reports: reports.iter().map(pb_report).collect(),
            ..Default::default()
        })),
    };
    let open = pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Open(pb_open())),
    };
    let (batch_len, open_len) = (
        prost::Message::encoded_len(&batch),
        prost::Message::encoded_len(&open),
    );
    assert!(open_len < batch_len / 2, "{open_len} and {batch_len} bytes");
    // A held bomb leaves half the batch's size of the budget: the open
    // message fits, the batch does not.
    let inflated = 65_536 - batch_len / 2;
    let held = held_gzip_bomb(&app, padded_request(inflated - 43).as_bytes()).await;
    wait_for_buffered(&app, inflated).await;

    let mut client = pb::session_service_client::SessionServiceClient::new(app.channel().await);
    let Some(pb::stream_request::Kind::Open(first)) = open.kind.clone() else {
        unreachable!()
    };
    let (tx, mut updates) = open_stream(&mut client, pb::stream_request::Kind::Open(first)).await;
    let opened = updates
        .message()
        .await
        .unwrap()
        .expect("the open is answered");
    assert!(opened.error.is_none(), "{opened:?}");
    tx.send(batch.clone()).await.unwrap();
    let status = updates.message().await.unwrap_err();
    assert_eq!(status.code(), Code::Unavailable, "{status:?}");
    assert!(
        status.message().contains("FUSION_MAX_BUFFERED_BODY_BYTES"),
        "{status:?}"
    );

    // With the budget free again, the same batch is taken and answered.
    drop(held);
    wait_for_buffered(&app, 0).await;
    let Some(pb::stream_request::Kind::Open(first)) = open.kind else {
        unreachable!()
    };
    let (tx, mut updates) = open_stream(&mut client, pb::stream_request::Kind::Open(first)).await;
    updates
        .message()
        .await
        .unwrap()
        .expect("the open is answered");
    tx.send(batch).await.unwrap();
    let applied = updates
        .message()
        .await
        .unwrap()
        .expect("the batch is answered");
    assert!(applied.error.is_none(), "{applied:?}");
    assert_eq!(applied.sequence, Some(1));
}
