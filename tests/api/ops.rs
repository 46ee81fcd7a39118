//! Operations: health, readiness, metrics, the OpenAPI document and docs page,
//! compression, request ids, load shedding and graceful shutdown.

use radar_fusion::{http::openapi_json, proto as pb};
use serde_json::json;
use tonic::Code;

use crate::helpers::{assert_problem, spawn_app, spawn_app_with};

#[tokio::test]
async fn liveness_and_readiness() {
    let app = spawn_app().await;
    let r = app.client.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.json::<serde_json::Value>().await.unwrap(),
        json!({"status": "ok"})
    );
    let r = app.client.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    app.state.set_ready(false);
    let r = app.client.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 503);
}

#[tokio::test]
async fn metrics_count_routes_and_grpc_methods() {
    let app = spawn_app().await;
    app.post_json(
        "/v1/correlation/rules/evaluate",
        &json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}),
    )
    .await;
    let _ = app
        .correlation()
        .await
        .evaluate_rules(pb::EvaluateRulesRequest {
            alpha: None,
            rules: vec![],
        })
        .await;
    let text = app.metrics_text().await;
    assert!(
        text.contains(r#"http_requests_total{method="POST",route="/v1/correlation/rules/evaluate",status="200"}"#),
        "{text}"
    );
    assert!(
        text.contains("http_request_duration_seconds_bucket"),
        "{text}"
    );
    assert!(
        text.contains(r#"grpc_requests_total{method="/radar.fusion.v1.CorrelationService/EvaluateRules",code="InvalidArgument"}"#),
        "{text}"
    );
    assert!(
        text.contains("grpc_request_duration_seconds_bucket"),
        "{text}"
    );
    // The requests ran on the compute lanes (none long enough to send
    // work to the blocking pool).
    assert!(
        text.contains(r#"compute_jobs_total{lane="compute"}"#),
        "{text}"
    );
}

/// Every POST operation's example request (what "Try it out" sends) works.
#[tokio::test]
async fn every_example_request_of_the_document_succeeds() {
    let app = spawn_app().await;
    let doc: serde_json::Value = app.get_ok("/openapi.json").await;
    let example = |path: &str| -> serde_json::Value {
        doc["paths"][path]["post"]["requestBody"]["content"]["application/json"]["example"].clone()
    };
    let mut posted = 0;
    let mut session_id = None;
    for (path, item) in doc["paths"].as_object().unwrap() {
        if item.get("post").is_none() || path.contains('{') {
            continue;
        }
        let body = example(path);
        assert!(body.is_object(), "{path} has no example request");
        let r = app.post_json(path, &body).await;
        let status = r.status();
        let answer: serde_json::Value = r.json().await.unwrap();
        assert!(status.is_success(), "{path}: {status} {answer}");
        if path == "/v1/sessions" {
            session_id = answer["id"].as_str().map(String::from);
        }
        posted += 1;
    }
    assert_eq!(posted, 8);
    let id = session_id.expect("a session was created");
    let batch = example("/v1/sessions/{id}/batches");
    let r = app
        .post_json(&format!("/v1/sessions/{id}/batches"), &batch)
        .await;
    assert_eq!(r.status(), 200);
}

#[tokio::test]
async fn invented_methods_and_routes_fold_into_one_label_each() {
    let app = spawn_app().await;
    for i in 0..50 {
        let method = reqwest::Method::from_bytes(format!("INVENTED{i}").as_bytes()).unwrap();
        app.client
            .request(method, app.url(&format!("/no/such/route/{i}")))
            .send()
            .await
            .unwrap();
    }
    let text = app.metrics_text().await;
    assert!(
        !text.contains("INVENTED"),
        "an invented method became a label"
    );
    assert!(
        !text.contains("/no/such/route"),
        "an unknown route became a label"
    );
    let series = text
        .lines()
        .filter(|l| l.starts_with("http_requests_total{") && l.contains(r#"method="other""#))
        .count();
    assert_eq!(series, 1, "{text}");
}

#[tokio::test]
async fn openapi_is_served_and_the_checked_in_copy_is_current() {
    let app = spawn_app().await;
    let served: serde_json::Value = app
        .client
        .get(app.url("/openapi.json"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let generated: serde_json::Value = serde_json::from_str(&openapi_json()).unwrap();
    assert_eq!(served, generated);
    assert!(served["openapi"].as_str().unwrap().starts_with("3."));
    assert!(served["paths"]["/v1/correlation/rules/evaluate"]["post"].is_object());
    // Every API operation lists the answers the layers in front of it give.
    for (path, item) in served["paths"].as_object().unwrap() {
        if !path.starts_with("/v1/") {
            continue;
        }
        for (method, op) in item.as_object().unwrap() {
            let mut want = vec!["401", "503", "504"];
            if method == "post" {
                want.extend(["400", "408", "413", "415"]);
            }
            for status in want {
                let r = &op["responses"][status];
                assert!(r.is_object(), "{method} {path} lacks {status}");
                if status != "401" {
                    let example = &r["content"]["application/problem+json"]["example"];
                    assert_eq!(example["status"], status.parse::<u16>().unwrap());
                }
            }
        }
    }

    let checked_in =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/openapi/openapi.json"))
            .expect("openapi/openapi.json exists");
    assert!(
        checked_in == openapi_json(),
        "openapi/openapi.json is stale: regenerate it with \
         `cargo run -- openapi > openapi/openapi.json`"
    );
}

#[tokio::test]
async fn docs_page_is_served() {
    let app = spawn_app().await;
    let r = app.client.get(app.url("/docs/")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    let html = r.text().await.unwrap();
    assert!(html.contains("swagger-ui"), "{html}");
    let r = app
        .client
        .get(app.url("/docs/swagger-initializer.js"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert!(r.text().await.unwrap().contains("/openapi.json"));
}

#[tokio::test]
async fn responses_are_gzipped_on_request_and_carry_a_request_id() {
    let app = spawn_app().await;
    let r = app
        .client
        .get(app.url("/openapi.json"))
        .header("accept-encoding", "gzip")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["content-encoding"], "gzip");
    assert!(!r.headers()["x-request-id"].is_empty());

    let r = app
        .client
        .get(app.url("/healthz"))
        .header("x-request-id", "trace-me-42")
        .send()
        .await
        .unwrap();
    assert_eq!(r.headers()["x-request-id"], "trace-me-42");
}

#[tokio::test]
async fn excess_requests_are_shed_with_503_and_unavailable() {
    let app = spawn_app_with(|s| s.max_in_flight = 1).await;
    let held = app.state.try_admit().expect("the only slot");
    let r = app
        .post_json(
            "/v1/correlation/rules/evaluate",
            &json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}),
        )
        .await;
    assert_eq!(r.headers()["retry-after"], "1");
    assert_problem(r, 503).await;
    let status = app
        .correlation()
        .await
        .evaluate_rules(pb::EvaluateRulesRequest {
            alpha: Some(0.05),
            rules: vec![pb::LrRule {
                l: Some(1),
                r: Some(1),
            }],
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::Unavailable);
    // Probes are not shed.
    let r = app.client.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);

    drop(held);
    let r = app
        .post_json(
            "/v1/correlation/rules/evaluate",
            &json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}),
        )
        .await;
    assert_eq!(r.status(), 200);
}

#[tokio::test]
async fn graceful_shutdown_stops_serving_and_reports_not_ready() {
    let app = spawn_app().await;
    let (addr, state) = (app.http_addr, app.state.clone());
    app.stop().await.expect("clean shutdown");
    assert!(!state.is_ready());
    assert!(tokio::net::TcpStream::connect(addr).await.is_err());
}

#[tokio::test]
async fn a_store_outage_degrades_sessions_only() {
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};

    // A port nobody listens on: connecting still works (Redis is lazy).
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let app = spawn_app_with(|s| {
        s.session_store = format!("redis://127.0.0.1:{port}/0");
        s.store_timeout_s = 0.3;
    })
    .await;
    assert_eq!(app.state.store().backend(), "redis");
    // In rotation: the stateless endpoints work without the store.
    let r = app.client.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.json::<serde_json::Value>().await.unwrap(),
        json!({"status": "ready", "reason": "session store unavailable", "store": "degraded",
               "failing_over": false})
    );
    let r = app
        .post_json(
            "/v1/correlation/rules/evaluate",
            &json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}),
        )
        .await;
    assert_eq!(r.status(), 200);
    // The store's own check says it is down.
    let r = app
        .client
        .get(app.url("/healthz/store"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 503);
    assert_eq!(
        r.json::<serde_json::Value>().await.unwrap(),
        json!({"status": "degraded", "reason": "session store unavailable",
               "failing_over": false})
    );
    // Liveness does not depend on the store.
    let r = app.client.get(app.url("/healthz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    // gRPC health: the server and the stateless services serve (1), the
    // session service does not (2).
    let mut health = HealthClient::new(app.channel().await);
    for (service, want) in [
        ("", 1),
        ("radar.fusion.v1.CorrelationService", 1),
        ("radar.fusion.v1.SessionService", 2),
    ] {
        let status = health
            .check(HealthCheckRequest {
                service: service.into(),
            })
            .await
            .expect("health check answers")
            .into_inner()
            .status;
        assert_eq!(status, want, "{service}");
    }
}

#[tokio::test]
async fn ready_with_the_memory_store() {
    let app = spawn_app().await;
    assert_eq!(app.state.store().backend(), "memory");
    let r = app.client.get(app.url("/readyz")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.json::<serde_json::Value>().await.unwrap(),
        json!({"status": "ready", "store": "ok"})
    );
    let r = app
        .client
        .get(app.url("/healthz/store"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
}

#[test]
fn the_cli_survives_a_closed_pipe_and_names_the_address_it_probes() {
    use std::io::Read;
    use std::process::{Command, Stdio};
    let bin = env!("CARGO_BIN_EXE_radar-fusion");
    // `radar-fusion openapi | head -c 10`: the reader leaves early.
    let mut child = Command::new(bin)
        .arg("openapi")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = [0u8; 10];
    child.stdout.take().unwrap().read_exact(&mut first).unwrap();
    // stdout is dropped (closed) here.
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(out.status.success(), "{stderr}");
    // Each command lists its own flags: eval's help has no server flags,
    // serve's has them; a server flag before a subcommand is refused.
    let help = |args: &[&str]| {
        let out = Command::new(bin).args(args).output().unwrap();
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    assert!(!help(&["eval", "--help"]).contains("--http-addr"));
    assert!(help(&["serve", "--help"]).contains("--http-addr"));
    let out = Command::new(bin)
        .args(["--log", "warn", "eval", "--list"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    // A probe of a port where nothing listens fails and says where it looked.
    let out = Command::new(bin)
        .args(["healthcheck", "--addr", "127.0.0.1:1"])
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("http://127.0.0.1:1/healthz"), "{stderr}");
}

/// `radar-fusion eval` moved to the `eval` crate's binary: the server says
/// where in one line on stderr and exits 2, whatever the arguments.
#[test]
fn eval_points_to_its_own_binary() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_radar-fusion"))
        .args(["eval", "seed000-correlation", "--runs", "3"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("radar-fusion-eval --list"), "{err}");
    assert!(out.stdout.is_empty());
}

/// Runs the server binary with these environment variables until its HTTP
/// port opens, it exits, or `wait` passes (then it is killed): whether the
/// port opened, and everything it printed.
fn run_server(env: &[(&str, String)], http: u16, wait: std::time::Duration) -> (bool, String) {
    use std::process::{Command, Stdio};
    let mut child = Command::new(env!("CARGO_BIN_EXE_radar-fusion"))
        .args([
            "serve",
            "--http-addr",
            &format!("127.0.0.1:{http}"),
            "--grpc-addr",
            "127.0.0.1:0",
        ])
        .envs(env.iter().map(|(k, v)| (*k, v.as_str())))
        .env("RUST_BACKTRACE", "0")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + wait;
    let mut served = false;
    while std::time::Instant::now() < deadline {
        if let Ok(Some(_)) = child.try_wait() {
            break;
        }
        if std::net::TcpStream::connect(("127.0.0.1", http)).is_ok() {
            served = true;
            // Time for this server to say so (below) before it is killed.
            std::thread::sleep(std::time::Duration::from_millis(1500));
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let _ = child.kill();
    let out = child.wait_with_output().unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    // The port answered, and it was this server: another test's server can
    // have been given the port between `free_port` and the bind (seen on
    // a full run: "started with a wrong password" from a foreign server).
    let served = served && text.contains("serving REST");
    (served, text)
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[tokio::test]
async fn bad_redis_settings_stop_the_start_naming_them_and_never_showing_the_password() {
    let secret = "hunter2-Pa55";
    let wait = std::time::Duration::from_secs(20);
    let missing =
        std::env::temp_dir().join(format!("fusion-missing-ca-{}.pem", std::process::id()));
    // A CA file that does not exist, with a password in the URL.
    let (served, out) = tokio::task::spawn_blocking(move || {
        run_server(
            &[
                (
                    "FUSION_SESSION_STORE",
                    format!("rediss://app:{secret}@127.0.0.1:1/0"),
                ),
                ("FUSION_REDIS_CA", missing.display().to_string()),
            ],
            free_port(),
            wait,
        )
    })
    .await
    .unwrap();
    assert!(!served, "started with a missing CA: {out}");
    assert!(out.contains("FUSION_REDIS_CA"), "{out}");
    assert!(!out.contains(secret) && !out.contains("panicked"), "{out}");

    // FUSION_REDIS_PASSWORD against a redis-server with --requirepass.
    if std::process::Command::new("redis-server")
        .arg("--version")
        .output()
        .is_err()
    {
        let _ = std::io::Write::write_all(
            &mut std::io::stderr(),
            b"\n!!!!!!!! SKIPPED: FUSION_REDIS_PASSWORD against redis-server: not on PATH\n",
        );
        return;
    }
    let port = free_port();
    let dir = std::env::temp_dir().join(format!("fusion-requirepass-{port}"));
    std::fs::create_dir_all(&dir).unwrap();
    let mut redis = std::process::Command::new("redis-server")
        .args([
            "--port",
            &port.to_string(),
            "--bind",
            "127.0.0.1",
            "--save",
            "",
            "--appendonly",
            "no",
        ])
        .args(["--dir", dir.to_str().unwrap(), "--requirepass", secret])
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let url = format!("redis://127.0.0.1:{port}/0");
    let (wrong_url, right_url) = (url.clone(), url);
    let (served, out) = tokio::task::spawn_blocking(move || {
        run_server(
            &[
                ("FUSION_SESSION_STORE", wrong_url),
                ("FUSION_REDIS_PASSWORD", "not-it-0".into()),
            ],
            free_port(),
            wait,
        )
    })
    .await
    .unwrap();
    assert!(!served, "started with a wrong password: {out}");
    assert!(out.contains("FUSION_REDIS_PASSWORD"), "{out}");
    assert!(!out.contains("not-it-0") && !out.contains(secret), "{out}");
    let http = free_port();
    let (served, out) = tokio::task::spawn_blocking(move || {
        run_server(
            &[
                ("FUSION_SESSION_STORE", right_url),
                ("FUSION_REDIS_PASSWORD", secret.into()),
            ],
            http,
            wait,
        )
    })
    .await
    .unwrap();
    assert!(served, "did not start with the right password: {out}");
    assert!(!out.contains(secret), "{out}");
    let _ = redis.kill();
    let _ = redis.wait();
    let _ = std::fs::remove_dir_all(&dir);
}
