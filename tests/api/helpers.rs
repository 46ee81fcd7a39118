//! `spawn_app`: the real application on port 0, with clients for both transports.

// Helpers shared by test targets: `pub` is for the modules that use them.
#![allow(unreachable_pub)]

use std::net::SocketAddr;

use radar_fusion::{
    app::Application, config::Settings,
    proto::correlation_service_client::CorrelationServiceClient, state::AppState,
};
use tokio::{sync::oneshot, task::JoinHandle};
use tonic::transport::Channel;

pub struct TestApp {
    pub base: String,
    pub http_addr: SocketAddr,
    pub grpc_addr: SocketAddr,
    pub client: reqwest::Client,
    pub state: AppState,
    shutdown: Option<oneshot::Sender<()>>,
    server: Option<JoinHandle<anyhow::Result<()>>>,
}

impl TestApp {
    pub fn url(&self, path: &str) -> String {
        format!("{}{}", self.base, path)
    }

    /// POSTs a JSON body given as text (so that malformed bodies can be sent).
    pub async fn post_raw(&self, path: &str, body: &str) -> reqwest::Response {
        self.client
            .post(self.url(path))
            .header("content-type", "application/json")
            .body(body.to_string())
            .send()
            .await
            .expect("request sent")
    }

    pub async fn post_json(&self, path: &str, body: &serde_json::Value) -> reqwest::Response {
        self.post_raw(path, &body.to_string()).await
    }

    /// POSTs a JSON body, expects 200 and returns the JSON response.
    pub async fn post_ok(&self, path: &str, body: &serde_json::Value) -> serde_json::Value {
        let response = self.post_json(path, body).await;
        let status = response.status();
        let text = response.text().await.expect("body");
        assert_eq!(status, 200, "POST {path}: {text}");
        serde_json::from_str(&text).expect("JSON response")
    }

    /// GETs `path`, expects 200 and returns the JSON response.
    pub async fn get_ok(&self, path: &str) -> serde_json::Value {
        let response = self
            .client
            .get(self.url(path))
            .send()
            .await
            .expect("request sent");
        let status = response.status();
        let text = response.text().await.expect("body");
        assert_eq!(status, 200, "GET {path}: {text}");
        serde_json::from_str(&text).expect("JSON response")
    }

    /// The Prometheus text of `/metrics`.
    pub async fn metrics_text(&self) -> String {
        self.client
            .get(self.url("/metrics"))
            .send()
            .await
            .expect("request sent")
            .text()
            .await
            .expect("metrics text")
    }

    /// A gRPC client of the dedicated gRPC port.
    pub async fn correlation(&self) -> CorrelationServiceClient<Channel> {
        grpc_client(self.grpc_addr).await
    }

    pub async fn channel(&self) -> Channel {
        Channel::from_shared(format!("http://{}", self.grpc_addr))
            .expect("valid uri")
            .connect()
            .await
            .expect("gRPC connects")
    }

    /// Stops the servers gracefully and waits for them to finish.
    pub async fn stop(mut self) -> anyhow::Result<()> {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        self.server.take().expect("running").await?
    }
}

impl Drop for TestApp {
    fn drop(&mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
    }
}

pub async fn grpc_client(addr: SocketAddr) -> CorrelationServiceClient<Channel> {
    CorrelationServiceClient::connect(format!("http://{addr}"))
        .await
        .expect("gRPC connects")
}

pub async fn spawn_app() -> TestApp {
    spawn_app_with(|_| {}).await
}

pub async fn spawn_app_with(configure: impl FnOnce(&mut Settings)) -> TestApp {
    let mut settings = Settings::for_tests();
    configure(&mut settings);
    let app = Application::build(settings).await.expect("app builds");
    let (http_addr, grpc_addr, state) = (app.http_addr(), app.grpc_addr(), app.state());
    let (tx, rx) = oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async move {
        let _ = rx.await;
    }));
    // Serving starts at once; wait until readiness is reported.
    for _ in 0..200 {
        if state.is_ready() {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(5)).await;
    }
    TestApp {
        base: format!("http://{http_addr}"),
        http_addr,
        grpc_addr,
        client: reqwest::Client::new(),
        state,
        shutdown: Some(tx),
        server: Some(server),
    }
}

/// A raw HTTP/2 (prior knowledge) connection to `addr`, for hand-made
/// gRPC requests (frames, bodies that never come).
pub async fn h2_connection<B>(addr: SocketAddr) -> hyper::client::conn::http2::SendRequest<B>
where
    B: http_body::Body + Send + Unpin + 'static,
    B::Data: Send,
    B::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    use hyper_util::rt::{TokioExecutor, TokioIo};
    let tcp = tokio::net::TcpStream::connect(addr)
        .await
        .expect("connects");
    let (sender, connection) =
        hyper::client::conn::http2::handshake(TokioExecutor::new(), TokioIo::new(tcp))
            .await
            .expect("h2 handshake");
    tokio::spawn(connection);
    sender
}

/// Asserts a problem+json response with `status`, and returns its body.
pub async fn assert_problem(response: reqwest::Response, status: u16) -> serde_json::Value {
    assert_eq!(response.status().as_u16(), status);
    let content_type = response
        .headers()
        .get("content-type")
        .expect("content type")
        .to_str()
        .unwrap()
        .to_string();
    assert_eq!(content_type, "application/problem+json");
    let body: serde_json::Value = response.json().await.expect("JSON problem body");
    assert_eq!(body["status"], status);
    assert!(
        body["type"]
            .as_str()
            .unwrap()
            .starts_with("urn:radar-fusion:problem:")
    );
    assert!(body["title"].is_string());
    assert!(body["detail"].is_string());
    body
}

/// The field paths named by a problem body.
pub fn problem_fields(body: &serde_json::Value) -> Vec<String> {
    body["errors"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|e| e["field"].as_str().unwrap().to_string())
                .collect()
        })
        .unwrap_or_default()
}

/// The field paths of a gRPC status's `BadRequest` details.
pub fn grpc_fields(status: &tonic::Status) -> Vec<String> {
    use tonic_types::StatusExt;
    status
        .get_details_bad_request()
        .expect("BadRequest details")
        .field_violations
        .into_iter()
        .map(|v| v.field)
        .collect()
}

/// The value of a session radar gauge (`fusion_session_radar_…`) of session
/// `session` and radar `radar` in a `/metrics` text, if shown.
pub fn radar_gauge(metrics: &str, name: &str, session: &str, radar: &str) -> Option<f64> {
    let labels = format!("session=\"{session}\",radar=\"{radar}\"}} ");
    metrics
        .lines()
        .find(|l| l.starts_with(&format!("{name}{{")) && l.contains(&labels))
        .map(|l| l.rsplit(' ').next().unwrap().parse().unwrap())
}

/// `bytes` gzip-compressed (the default level).
pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    use std::io::Write;
    let mut encoder = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    encoder.write_all(bytes).unwrap();
    encoder.finish().unwrap()
}
