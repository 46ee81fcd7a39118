//! API keys: with keys configured, the `/v1/` routes and the fusion gRPC
//! services need a valid key on both ports, and `/metrics` a tenant's key
//! or the metrics key; probes, health checks and reflection do not. Open
//! mode (no keys) is what every other test runs.

use radar_fusion::proto as pb;
use serde_json::json;
use tonic::{Code, metadata::MetadataValue};
use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};

use crate::helpers::{TestApp, assert_problem, grpc_client, spawn_app_with};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";
const ACME_KEY: &str = "acme-key-0123456789";
const GLOBEX_KEY: &str = "globex-key-0123456789";

async fn spawn_with_keys() -> TestApp {
    spawn_app_with(|s| {
        s.api_keys = Some(
            format!("{ACME_KEY}=acme,{GLOBEX_KEY}=globex")
                .as_str()
                .into(),
        );
    })
    .await
}

fn evaluate_body() -> serde_json::Value {
    json!({"alpha": 0.05, "rules": [{"l": 3, "r": 4}]})
}

async fn post_evaluate(app: &TestApp, authorization: Option<&str>) -> reqwest::Response {
    let mut request = app
        .client
        .post(app.url(EVALUATE))
        .header("content-type", "application/json")
        .body(evaluate_body().to_string());
    if let Some(value) = authorization {
        request = request.header("authorization", value);
    }
    request.send().await.expect("request sent")
}

async fn assert_unauthenticated(response: reqwest::Response) -> String {
    let challenge = response
        .headers()
        .get("www-authenticate")
        .expect("a WWW-Authenticate challenge")
        .to_str()
        .unwrap()
        .to_string();
    assert!(challenge.starts_with("Bearer"), "{challenge}");
    // The body was not read: the connection is closed, and said so.
    assert_eq!(
        response
            .headers()
            .get("connection")
            .map(|v| v.to_str().unwrap()),
        Some("close")
    );
    let body = assert_problem(response, 401).await;
    assert_eq!(body["type"], "urn:radar-fusion:problem:unauthenticated");
    challenge
}

#[tokio::test]
async fn rest_api_routes_need_a_valid_bearer_key() {
    let app = spawn_with_keys().await;

    let challenge = assert_unauthenticated(post_evaluate(&app, None).await).await;
    assert!(!challenge.contains("error="), "{challenge}");
    let challenge =
        assert_unauthenticated(post_evaluate(&app, Some("Bearer not-a-valid-key")).await).await;
    assert!(
        challenge.contains(r#"error="invalid_token""#),
        "{challenge}"
    );
    // The key alone, without the scheme, or under another scheme.
    for malformed in [ACME_KEY.to_string(), format!("Basic {ACME_KEY}")] {
        let challenge = assert_unauthenticated(post_evaluate(&app, Some(&malformed)).await).await;
        assert!(
            challenge.contains(r#"error="invalid_request""#),
            "{challenge}"
        );
    }

    for key in [ACME_KEY, GLOBEX_KEY] {
        let response = post_evaluate(&app, Some(&format!("Bearer {key}"))).await;
        assert_eq!(response.status(), 200);
        let body: serde_json::Value = response.json().await.unwrap();
        assert_eq!(body["evaluations"].as_array().unwrap().len(), 1);
    }
}

#[tokio::test]
async fn rest_operational_routes_need_no_key() {
    let app = spawn_with_keys().await;
    for path in [
        "/healthz",
        "/readyz",
        "/healthz/store",
        "/openapi.json",
        "/view/",
    ] {
        let response = app.client.get(app.url(path)).send().await.unwrap();
        assert_eq!(response.status(), 200, "{path}");
    }
    // An unknown route is still a 404, not a 401.
    let response = app.client.get(app.url("/v2/nothing")).send().await.unwrap();
    assert_problem(response, 404).await;
}

async fn get_metrics(app: &TestApp, authorization: Option<&str>) -> reqwest::Response {
    let mut request = app.client.get(app.url("/metrics"));
    if let Some(value) = authorization {
        request = request.header("authorization", value);
    }
    request.send().await.expect("request sent")
}

#[tokio::test]
async fn metrics_name_every_tenant_so_they_need_a_key_when_keys_are_on() {
    // API keys without a metrics key: any tenant's key.
    let app = spawn_with_keys().await;
    for authorization in [None, Some("Bearer wrong-key-0123456789"), Some("Basic x")] {
        let response = get_metrics(&app, authorization).await;
        let challenge = response.headers()["www-authenticate"]
            .to_str()
            .unwrap()
            .to_string();
        assert!(challenge.starts_with("Bearer"), "{challenge}");
        assert_problem(response, 401).await;
    }
    for key in [ACME_KEY, GLOBEX_KEY] {
        let response = get_metrics(&app, Some(&format!("Bearer {key}"))).await;
        assert_eq!(response.status(), 200);
        assert!(
            response
                .text()
                .await
                .unwrap()
                .contains("http_requests_total")
        );
    }

    // A metrics key: that key only, tenants' keys no longer.
    const METRICS_KEY: &str = "metrics-key-0123456789";
    let app = spawn_app_with(|s| {
        s.api_keys = Some(format!("{ACME_KEY}=acme").as_str().into());
        s.metrics_key = Some(METRICS_KEY.into());
    })
    .await;
    let response = get_metrics(&app, Some(&format!("Bearer {METRICS_KEY}"))).await;
    assert_eq!(response.status(), 200);
    for authorization in [None, Some(format!("Bearer {ACME_KEY}"))] {
        assert_problem(get_metrics(&app, authorization.as_deref()).await, 401).await;
    }
    // The metrics key is not an API key.
    let response = post_evaluate(&app, Some(&format!("Bearer {METRICS_KEY}"))).await;
    assert_problem(response, 401).await;

    // Open mode: open, unless a metrics key is given.
    let app = spawn_app_with(|_| {}).await;
    assert_eq!(get_metrics(&app, None).await.status(), 200);
    let app = spawn_app_with(|s| s.metrics_key = Some(METRICS_KEY.into())).await;
    assert_problem(get_metrics(&app, None).await, 401).await;
    let response = get_metrics(&app, Some(&format!("Bearer {METRICS_KEY}"))).await;
    assert_eq!(response.status(), 200);
}

#[tokio::test]
async fn a_short_metrics_key_stops_the_start_naming_the_option() {
    let mut settings = radar_fusion::config::Settings::for_tests();
    settings.metrics_key = Some("short".into());
    let error = radar_fusion::app::Application::build(settings)
        .await
        .err()
        .expect("refused")
        .to_string();
    assert!(
        error.contains("--metrics-key (FUSION_METRICS_KEY)"),
        "{error}"
    );
    assert!(!error.contains("short"), "the key is never shown: {error}");
}

fn evaluate_request(
    metadata: Option<(&'static str, String)>,
) -> tonic::Request<pb::EvaluateRulesRequest> {
    let mut request = tonic::Request::new(pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![pb::LrRule {
            l: Some(3),
            r: Some(4),
        }],
    });
    if let Some((name, value)) = metadata {
        let value: MetadataValue<_> = value.parse().expect("ASCII metadata");
        request.metadata_mut().insert(name, value);
    }
    request
}

#[tokio::test]
async fn grpc_services_need_a_valid_key_on_both_ports() {
    let app = spawn_with_keys().await;
    for addr in [app.grpc_addr, app.http_addr] {
        let mut client = grpc_client(addr).await;

        let denied = [
            None,
            Some(("authorization", "Bearer not-a-valid-key".to_string())),
            Some(("authorization", ACME_KEY.to_string())),
            Some(("x-api-key", "not-a-valid-key".to_string())),
        ];
        for metadata in denied {
            let status = client
                .evaluate_rules(evaluate_request(metadata.clone()))
                .await
                .expect_err("unauthenticated");
            assert_eq!(status.code(), Code::Unauthenticated, "{addr} {metadata:?}");
            assert!(!status.message().is_empty());
        }
        let missing = client
            .evaluate_rules(evaluate_request(None))
            .await
            .unwrap_err();
        assert!(
            missing.message().contains("authorization: Bearer <key>"),
            "{}",
            missing.message()
        );

        let allowed = [
            ("authorization", format!("Bearer {ACME_KEY}")),
            ("x-api-key", GLOBEX_KEY.to_string()),
        ];
        for metadata in allowed {
            let response = client
                .evaluate_rules(evaluate_request(Some(metadata.clone())))
                .await
                .unwrap_or_else(|s| panic!("{addr} {metadata:?}: {s:?}"))
                .into_inner();
            assert_eq!(response.evaluations.len(), 1);
        }
    }
}

#[tokio::test]
async fn grpc_health_needs_no_key() {
    let app = spawn_with_keys().await;
    for addr in [app.grpc_addr, app.http_addr] {
        let channel = tonic::transport::Channel::from_shared(format!("http://{addr}"))
            .unwrap()
            .connect()
            .await
            .unwrap();
        let response = HealthClient::new(channel)
            .check(HealthCheckRequest {
                service: "radar.fusion.v1.CorrelationService".into(),
            })
            .await
            .expect("health check answers without a key")
            .into_inner();
        // 1 = SERVING in grpc.health.v1.
        assert_eq!(response.status, 1, "{addr}");
    }
}

#[tokio::test]
async fn invalid_key_settings_stop_the_start_naming_the_flag() {
    let mut settings = radar_fusion::config::Settings::for_tests();
    settings.api_keys = Some("short=acme".into());
    let error = radar_fusion::app::Application::build(settings)
        .await
        .err()
        .expect("rejected");
    assert!(
        error.to_string().starts_with("--api-keys entry 1:"),
        "{error}"
    );
}
