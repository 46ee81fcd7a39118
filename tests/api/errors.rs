//! Bad input over both transports: every kind gets a clear 4xx (or
//! INVALID_ARGUMENT) naming the field, never a panic or a 500.

use radar_fusion::proto as pb;
use serde_json::json;
use tonic::Code;

use crate::helpers::{assert_problem, grpc_fields, problem_fields, spawn_app, spawn_app_with};

const EVALUATE: &str = "/v1/correlation/rules/evaluate";
const RECOMMEND: &str = "/v1/correlation/rules/recommend";

#[tokio::test]
async fn malformed_json_is_400() {
    let app = spawn_app().await;
    for body in [
        r#"{"alpha": 0.05, "rules": [{"l": 3, "r": 4}"#,
        r#"{"alpha": NaN, "rules": [{"l": 3, "r": 4}]}"#,
        r#"{"alpha": Infinity, "rules": [{"l": 3, "r": 4}]}"#,
        r#"{"alpha": -Infinity, "rules": [{"l": 3, "r": 4}]}"#,
        r#"{"alpha": 0.05, "rules": []} {}"#,
        "",
        "not json",
    ] {
        let body_json = assert_problem(app.post_raw(EVALUATE, body).await, 400).await;
        assert!(
            body_json["type"]
                .as_str()
                .unwrap()
                .ends_with("malformed-json"),
            "{body}"
        );
    }
}

#[tokio::test]
async fn wrong_types_and_missing_fields_name_the_field() {
    let app = spawn_app().await;
    let cases = [
        (
            json!({"alpha": "0.05", "rules": [{"l": 3, "r": 4}]}),
            "alpha",
        ),
        (json!({"rules": [{"l": 3, "r": 4}]}), "alpha"),
        (json!({"alpha": 0.05}), "rules"),
        (
            json!({"alpha": 0.05, "rules": [{"l": 3, "r": 4}, {"r": 4}]}),
            "rules[1].l",
        ),
        (
            json!({"alpha": 0.05, "rules": [{"l": -3, "r": 4}]}),
            "rules[0].l",
        ),
        (
            json!({"alpha": 0.05, "rules": [{"l": 3.5, "r": 4}]}),
            "rules[0].l",
        ),
        (json!({"alpha": 0.05, "rules": {"l": 3}}), "rules"),
        (json!({"alpha": 0.05, "rules": [], "alhpa": 1}), "alhpa"),
        (json!("a string"), "body"),
        (json!(null), "body"),
    ];
    for (body, field) in cases {
        let problem = assert_problem(app.post_json(EVALUATE, &body).await, 422).await;
        assert_eq!(problem_fields(&problem), vec![field.to_string()], "{body}");
    }
}

#[tokio::test]
async fn out_of_range_values_are_422_with_every_field_named() {
    let app = spawn_app().await;
    let body = json!({"alpha": 1.5, "rules": [{"l": 3, "r": 4}, {"l": 5, "r": 4}, {"l": 0, "r": 2}, {"l": 1, "r": 129}]});
    let problem = assert_problem(app.post_json(EVALUATE, &body).await, 422).await;
    assert_eq!(
        problem_fields(&problem),
        vec!["alpha", "rules[1].l", "rules[2].l", "rules[3].r"]
    );

    for (body, field) in [
        (json!({"alpha": 0.0, "rules": [{"l": 1, "r": 1}]}), "alpha"),
        (json!({"alpha": 0.05, "rules": []}), "rules"),
        (
            json!({"alpha": 0.05, "max_miss_probability": 0.0}),
            "max_miss_probability",
        ),
        (
            json!({"alpha": 0.05, "max_miss_probability": 0.01, "min_l_over_r": 1.5}),
            "min_l_over_r",
        ),
        (
            json!({"alpha": 0.05, "max_miss_probability": 0.01, "max_r": 0}),
            "max_r",
        ),
        (
            json!({"alpha": 0.05, "max_miss_probability": 0.01, "max_r": 1000}),
            "max_r",
        ),
    ] {
        let path = if body.get("rules").is_some() {
            EVALUATE
        } else {
            RECOMMEND
        };
        let problem = assert_problem(app.post_json(path, &body).await, 422).await;
        assert_eq!(problem_fields(&problem), vec![field.to_string()], "{body}");
    }
}

#[tokio::test]
async fn too_many_rules_is_422() {
    let app = spawn_app().await;
    let rules: Vec<_> = (0..1025).map(|_| json!({"l": 1, "r": 1})).collect();
    let problem = assert_problem(
        app.post_json(EVALUATE, &json!({"alpha": 0.05, "rules": rules}))
            .await,
        422,
    )
    .await;
    assert_eq!(problem_fields(&problem), vec!["rules"]);
}

#[tokio::test]
async fn unknown_routes_wrong_methods_and_media_types() {
    let app = spawn_app().await;
    assert_problem(
        app.client.get(app.url("/v1/nothing")).send().await.unwrap(),
        404,
    )
    .await;
    assert_problem(app.post_raw("/v1/nothing", "{}").await, 404).await;
    let response = app.client.get(app.url(EVALUATE)).send().await.unwrap();
    assert_eq!(response.headers()["allow"], "POST");
    assert_problem(response, 405).await;
    assert_problem(
        app.client.delete(app.url("/healthz")).send().await.unwrap(),
        405,
    )
    .await;
    let response = app
        .client
        .post(app.url(EVALUATE))
        .header("content-type", "text/plain")
        .body(r#"{"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}"#)
        .send()
        .await
        .unwrap();
    assert_problem(response, 415).await;
    let response = app
        .client
        .post(app.url(EVALUATE))
        .body(r#"{"alpha": 0.05, "rules": [{"l": 1, "r": 1}]}"#)
        .send()
        .await
        .unwrap();
    assert_problem(response, 415).await;
}

#[tokio::test]
async fn oversized_bodies_are_413_on_rest_and_resource_exhausted_on_grpc() {
    let app = spawn_app_with(|s| s.max_body_bytes = 2048).await;
    let rules: Vec<_> = (0..400).map(|_| json!({"l": 1, "r": 1})).collect();
    let body = json!({"alpha": 0.05, "rules": rules});
    assert!(body.to_string().len() > 2048);
    assert_problem(app.post_json(EVALUATE, &body).await, 413).await;
    // The same without a Content-Length (chunked): the limit holds while reading.
    let raw = raw_chunked_post(app.http_addr, EVALUATE, &body.to_string()).await;
    assert!(raw.starts_with("HTTP/1.1 413"), "{raw}");
    assert!(raw.contains("application/problem+json"), "{raw}");

    let request = pb::EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: (0..400)
            .map(|_| pb::LrRule {
                l: Some(1),
                r: Some(1),
            })
            .collect(),
    };
    let status = app
        .correlation()
        .await
        .evaluate_rules(request)
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::ResourceExhausted, "{status:?}");
}

/// Clients that send their headers and then withhold their bodies hold no
/// in-flight slot: with one slot, ten such clients leave a normal request
/// served, and each is answered 408 when the body-read timeout passes.
#[tokio::test]
async fn slow_clients_hold_no_slot_and_time_out() {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let app = spawn_app_with(|s| {
        s.max_in_flight = 1;
        s.body_read_timeout_s = 0.5;
    })
    .await;
    let mut slow = Vec::new();
    for _ in 0..10 {
        let mut stream = tokio::net::TcpStream::connect(app.http_addr).await.unwrap();
        stream
            .write_all(
                format!(
                    "POST {EVALUATE} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
                     Content-Length: 1000\r\n\r\n{{\"alpha\""
                )
                .as_bytes(),
            )
            .await
            .unwrap();
        slow.push(stream);
    }
    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
    let body = json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]});
    let r = app.post_json(EVALUATE, &body).await;
    assert_eq!(r.status(), 200, "a slow client holds the only slot");
    for mut stream in slow {
        let mut response = Vec::new();
        let _ = tokio::time::timeout(
            std::time::Duration::from_secs(5),
            stream.read_to_end(&mut response),
        )
        .await
        .expect("the slow client is answered and closed");
        let text = String::from_utf8_lossy(&response);
        assert!(text.starts_with("HTTP/1.1 408"), "{text}");
        assert!(
            text.to_ascii_lowercase().contains("connection: close"),
            "{text}"
        );
    }
}

/// Sends a POST with `Transfer-Encoding: chunked` (no Content-Length) over a
/// raw socket and returns the response head and body as text.
async fn raw_chunked_post(addr: std::net::SocketAddr, path: &str, body: &str) -> String {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let mut stream = tokio::net::TcpStream::connect(addr).await.unwrap();
    let mut request = format!(
        "POST {path} HTTP/1.1\r\nHost: test\r\nContent-Type: application/json\r\n\
         Transfer-Encoding: chunked\r\nConnection: close\r\n\r\n"
    );
    for chunk in body.as_bytes().chunks(500) {
        request.push_str(&format!("{:x}\r\n", chunk.len()));
        request.push_str(std::str::from_utf8(chunk).unwrap());
        request.push_str("\r\n");
    }
    request.push_str("0\r\n\r\n");
    // The server may answer and close before it has read everything.
    let _ = stream.write_all(request.as_bytes()).await;
    let mut response = Vec::new();
    let _ = stream.read_to_end(&mut response).await;
    String::from_utf8_lossy(&response).into_owned()
}

#[tokio::test]
async fn grpc_bad_input_is_invalid_argument_with_field_violations() {
    let app = spawn_app().await;
    let mut client = app.correlation().await;
    let status = client
        .evaluate_rules(pb::EvaluateRulesRequest {
            alpha: None,
            rules: vec![
                pb::LrRule {
                    l: Some(5),
                    r: Some(4),
                },
                pb::LrRule {
                    l: None,
                    r: Some(4),
                },
            ],
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    assert_eq!(
        grpc_fields(&status),
        vec!["alpha", "rules[0].l", "rules[1].l"]
    );

    for (alpha, field) in [
        (f64::NAN, "alpha"),
        (f64::INFINITY, "alpha"),
        (-0.1, "alpha"),
    ] {
        let status = client
            .evaluate_rules(pb::EvaluateRulesRequest {
                alpha: Some(alpha),
                rules: vec![pb::LrRule {
                    l: Some(1),
                    r: Some(1),
                }],
            })
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument);
        assert_eq!(grpc_fields(&status)[0], field);
    }

    let status = client
        .recommend_rule(pb::RecommendRuleRequest {
            alpha: Some(0.05),
            max_miss_probability: None,
            min_l_over_r: Some(f64::NAN),
            max_r: Some(0),
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    // Every bad field at once: the missing bound, the NaN ratio and R = 0.
    let fields = grpc_fields(&status);
    assert_eq!(
        fields,
        vec!["max_miss_probability", "min_l_over_r", "max_r"]
    );
}

#[tokio::test]
async fn grpc_unknown_method_is_unimplemented() {
    let app = spawn_app().await;
    let mut grpc = tonic::client::Grpc::new(app.channel().await);
    grpc.ready().await.unwrap();
    let codec = tonic_prost::ProstCodec::<pb::Timing, pb::Timing>::default();
    let path = tonic::codegen::http::uri::PathAndQuery::from_static(
        "/radar.fusion.v1.CorrelationService/NoSuchMethod",
    );
    let status = grpc
        .unary(tonic::Request::new(pb::Timing::default()), path, codec)
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::Unimplemented);
}

/// The messages of a problem body, by field.
fn problem_messages(problem: &serde_json::Value) -> Vec<(String, String)> {
    problem["errors"]
        .as_array()
        .expect("errors")
        .iter()
        .map(|e| {
            (
                e["field"].as_str().unwrap_or_default().to_string(),
                e["message"].as_str().unwrap_or_default().to_string(),
            )
        })
        .collect()
}

#[tokio::test]
async fn every_endpoint_words_a_kind_of_violation_alike() {
    // Each endpoint's working example with its second list element's id
    // set to the first's, and one of its named choices set to 'bogus'.
    let app = spawn_app().await;
    let cases: [(&str, &str, &str, &str, &[&str]); 5] = [
        (
            "/v1/correlation/tracks",
            include_str!("../../openapi/examples/correlation_tracks.json"),
            "nodes",
            "method.kind",
            &["method", "kind"],
        ),
        (
            "/v1/dimension/fuse",
            include_str!("../../openapi/examples/dimension_fuse.json"),
            "radars",
            "methods[0]",
            &["methods", "0"],
        ),
        (
            "/v1/jpda/update",
            include_str!("../../openapi/examples/jpda_update.json"),
            "tracks",
            "method",
            &["method"],
        ),
        (
            "/v1/plot-fusion/track",
            include_str!("../../openapi/examples/plot_fusion_track.json"),
            "radars",
            "tracker.association",
            &["tracker", "association"],
        ),
        (
            "/v1/ais-radar/associate",
            include_str!("../../openapi/examples/ais_radar_associate.json"),
            "radar_tracks",
            "ellipsoid",
            &["ellipsoid"],
        ),
    ];
    for (path, example, list, choice_field, choice_path) in cases {
        let mut body: serde_json::Value = serde_json::from_str(example).unwrap();
        let items = body[list].as_array_mut().unwrap();
        if items.len() < 2 {
            let copy = items[0].clone();
            items.push(copy);
        }
        let first = items[0]["id"].clone();
        items[1]["id"] = first.clone();
        let mut slot = &mut body;
        for (k, key) in choice_path.iter().enumerate() {
            if let Ok(i) = key.parse::<usize>() {
                slot = &mut slot[i];
            } else {
                if k + 1 < choice_path.len() && slot.get(*key).is_none() {
                    slot[*key] = serde_json::json!({});
                }
                slot = &mut slot[*key];
            }
        }
        *slot = "bogus".into();
        let problem = assert_problem(app.post_json(path, &body).await, 422).await;
        let messages = problem_messages(&problem);
        let id = first.as_str().unwrap();
        let duplicate = format!("{list}[1].id");
        assert!(
            messages
                .iter()
                .any(|(f, m)| *f == duplicate && *m == format!("duplicates {list}[0].id '{id}'")),
            "{path}: {messages:?}"
        );
        assert!(
            messages.iter().any(|(f, m)| f == choice_field
                && m.starts_with("must be one of ")
                && m.ends_with(", got 'bogus'")),
            "{path}: {messages:?}"
        );
    }
}
