//! Connection limits of the accept loop (`radar_fusion::serve`): header-read
//! timeout, idle connections that never begin a request, connections per
//! client and in total, and unary gRPC calls that withhold their message.
//! Each fails on the `axum::serve` loop this replaced (no timer, no caps).
//!
//! The waits below are bounds on an outcome (the server closes, answers),
//! generous against the configured limits, never measurements of speed.

use std::time::Duration;

use serde_json::json;
use tokio::{
    io::{AsyncReadExt, AsyncWriteExt},
    net::TcpStream,
};

use crate::helpers::{h2_connection, spawn_app_with};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";
const BOUND: Duration = Duration::from_secs(10);

/// Reads until the server closes; panics when it does not within [`BOUND`].
async fn read_until_closed(stream: &mut TcpStream, what: &str) -> Vec<u8> {
    let mut out = Vec::new();
    match tokio::time::timeout(BOUND, stream.read_to_end(&mut out)).await {
        Ok(_) => out,
        Err(_) => panic!("{what}: the server kept the connection open"),
    }
}

/// A small valid HTTP/1.1 request on its own connection; the status line.
async fn status_line(addr: std::net::SocketAddr) -> String {
    let mut stream = TcpStream::connect(addr).await.expect("connects");
    let body = json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}).to_string();
    let request = format!(
        "POST {EVALUATE} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    );
    stream.write_all(request.as_bytes()).await.unwrap();
    let response = read_until_closed(&mut stream, "a normal request").await;
    String::from_utf8_lossy(&response)
        .lines()
        .next()
        .unwrap_or("")
        .to_string()
}

#[tokio::test]
async fn headers_that_never_finish_are_cut_at_the_header_read_timeout() {
    let app = spawn_app_with(|s| s.header_read_timeout_s = 0.3).await;
    let mut stream = TcpStream::connect(app.http_addr).await.unwrap();
    stream
        .write_all(b"POST /v1/correlation/rules/evaluate HTTP/1.1\r\nHost: te")
        .await
        .unwrap();
    read_until_closed(&mut stream, "half-sent headers").await;
    // The server still serves others.
    assert_eq!(status_line(app.http_addr).await, "HTTP/1.1 200 OK");
}

#[tokio::test]
async fn a_connection_that_sends_nothing_is_closed() {
    let app = spawn_app_with(|s| s.header_read_timeout_s = 0.3).await;
    for addr in [app.http_addr, app.grpc_addr] {
        let mut stream = TcpStream::connect(addr).await.unwrap();
        let got = read_until_closed(&mut stream, "a silent connection").await;
        assert!(got.is_empty(), "nothing is sent to a silent connection");
    }
    // A part of the HTTP/2 preface, then silence: closed as well.
    let mut stream = TcpStream::connect(app.grpc_addr).await.unwrap();
    stream.write_all(b"PRI * HTTP/2.0\r\n").await.unwrap();
    read_until_closed(&mut stream, "a partial HTTP/2 preface").await;
}

#[tokio::test]
async fn an_idle_keep_alive_connection_is_closed_after_the_timeout() {
    let app = spawn_app_with(|s| s.header_read_timeout_s = 0.3).await;
    let mut stream = TcpStream::connect(app.http_addr).await.unwrap();
    let body = json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}).to_string();
    let request = format!(
        "POST {EVALUATE} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\n\r\n{body}",
        body.len()
    );
    stream.write_all(request.as_bytes()).await.unwrap();
    let response = read_until_closed(&mut stream, "a kept-alive connection").await;
    let text = String::from_utf8_lossy(&response);
    assert!(text.starts_with("HTTP/1.1 200"), "{text}");
}

#[tokio::test]
async fn connections_per_client_are_bounded() {
    let app = spawn_app_with(|s| {
        s.max_connections_per_client = 2;
        s.header_read_timeout_s = 30.0;
    })
    .await;
    let first = TcpStream::connect(app.http_addr).await.unwrap();
    let _second = TcpStream::connect(app.http_addr).await.unwrap();
    // Both are counted once the server has accepted them; a third from the
    // same address is closed at once, whatever it sends.
    let mut third = None;
    for _ in 0..100 {
        let mut stream = TcpStream::connect(app.http_addr).await.unwrap();
        let mut buf = Vec::new();
        let read = tokio::time::timeout(Duration::from_millis(500), stream.read_to_end(&mut buf));
        // Closed by the server (end of stream, or a reset): refused. Still
        // open after 500 ms: it was served a slot, so try again.
        if let Ok(Ok(0) | Err(_)) = read.await {
            third = Some(());
            break;
        }
    }
    assert!(
        third.is_some(),
        "a third connection of one client was refused"
    );
    // Closing one frees its slot: a request is served again.
    drop(first);
    let mut served = false;
    for _ in 0..100 {
        if status_line(app.http_addr).await == "HTTP/1.1 200 OK" {
            served = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    assert!(served, "a freed slot serves the client again");
    let refused = app.metrics_text().await;
    assert!(
        refused.contains("connections_refused_total{server=\"http\",reason=\"per_client\"}"),
        "{refused}"
    );
}

#[tokio::test]
async fn beyond_the_total_cap_connections_wait_for_a_free_slot() {
    let app = spawn_app_with(|s| {
        s.max_connections = 2;
        s.max_connections_per_client = 0;
        s.header_read_timeout_s = 30.0;
    })
    .await;
    let first = TcpStream::connect(app.http_addr).await.unwrap();
    let _second = TcpStream::connect(app.http_addr).await.unwrap();
    // The third waits in the backlog: no answer while both slots are held.
    let waiting = tokio::spawn(status_line(app.http_addr));
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(!waiting.is_finished(), "served beyond the connection cap");
    drop(first);
    let line = tokio::time::timeout(BOUND, waiting)
        .await
        .expect("served once a slot is free")
        .unwrap();
    assert_eq!(line, "HTTP/1.1 200 OK");
}

/// A unary gRPC call whose message never comes holds no in-flight slot: with
/// one slot, five such calls leave a normal call served, and each is
/// answered DEADLINE_EXCEEDED when the body-read timeout passes.
#[tokio::test]
async fn grpc_calls_that_withhold_their_message_hold_no_slot() {
    let app = spawn_app_with(|s| {
        s.max_in_flight = 1;
        s.body_read_timeout_s = 0.5;
    })
    .await;
    let sender = h2_connection::<Withheld>(app.grpc_addr).await;
    let mut calls = Vec::new();
    for _ in 0..5 {
        let request = hyper::Request::post(format!(
            "http://{}/radar.fusion.v1.CorrelationService/EvaluateRules",
            app.grpc_addr
        ))
        .header("content-type", "application/grpc")
        .header("te", "trailers")
        .body(Withheld)
        .unwrap();
        let mut sender = sender.clone();
        calls.push(tokio::spawn(async move {
            sender.ready().await.unwrap();
            sender.send_request(request).await
        }));
    }
    tokio::time::sleep(Duration::from_millis(100)).await;
    let served = app
        .correlation()
        .await
        .evaluate_rules(radar_fusion::proto::EvaluateRulesRequest {
            alpha: Some(0.05),
            rules: vec![radar_fusion::proto::LrRule {
                l: Some(1),
                r: Some(1),
            }],
        })
        .await;
    assert!(
        served.is_ok(),
        "a withheld message holds the only slot: {served:?}"
    );
    for call in calls {
        let response = tokio::time::timeout(BOUND, call)
            .await
            .expect("the withheld call is answered")
            .unwrap()
            .expect("a response");
        assert_eq!(
            response
                .headers()
                .get("grpc-status")
                .map(|v| v.to_str().unwrap().to_string()),
            Some("4".to_string()),
            "DEADLINE_EXCEEDED: {:?}",
            response.headers()
        );
    }
}

/// A request body that never sends a byte.
struct Withheld;

impl http_body::Body for Withheld {
    type Data = axum::body::Bytes;
    type Error = std::convert::Infallible;

    fn poll_frame(
        self: std::pin::Pin<&mut Self>,
        _cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<Option<Result<http_body::Frame<Self::Data>, Self::Error>>> {
        std::task::Poll::Pending
    }

    fn is_end_stream(&self) -> bool {
        false
    }
}
