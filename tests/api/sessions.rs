//! Streaming sessions over REST against the real server (memory store):
//! the batch endpoint's decisions from N batches, retries, sequence gaps,
//! limits, tenant isolation and deletion.

use serde_json::{Value, json};

use crate::helpers::{spawn_app, spawn_app_with};

#[path = "../common/sessions.rs"]
pub(crate) mod data;

use data::{open_stream, pb_open, pb_report, scenario, scenario_offset, session_config};

/// Radars half a scan apart (b 1 s after a, scans every 2 s), everything
/// left to its default: the session's grid (estimated from the first two
/// scans) meets them, and N batches and a flush decide as one batch call.
#[tokio::test]
async fn a_default_session_correlates_unsynchronised_radars_like_the_batch_call() {
    let app = spawn_app().await;
    let (batch, reports) = scenario_offset(1.0, None);
    let expected = app.post_ok("/v1/correlation/tracks", &batch).await;
    assert_eq!(expected["alignment"]["period_s"], 2.0);
    let decided = |pairs: &Value| {
        pairs
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["decision"] == "correlated")
            .count()
    };
    assert_eq!(decided(&expected["pairs"]), 6, "{expected}");
    let created = app.post_json("/v1/sessions", &session_config(&batch)).await;
    assert_eq!(created.status(), 201);
    let id = created.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let mut warnings = Vec::new();
    for (i, chunk) in reports.chunks(30).enumerate() {
        let u = app
            .post_ok(
                &format!("/v1/sessions/{id}/batches"),
                &json!({"sequence": i + 1, "reports": chunk}),
            )
            .await;
        warnings.extend(u["warnings"].as_array().unwrap().iter().cloned());
    }
    let n = reports.chunks(30).count();
    app.post_ok(
        &format!("/v1/sessions/{id}/batches"),
        &json!({"sequence": n + 1, "flush": true}),
    )
    .await;
    assert!(
        warnings.iter().any(|w| w
            .as_str()
            .unwrap()
            .contains("fusion period was estimated at 2 s")),
        "{warnings:?}"
    );
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(state["pairs"], expected["pairs"]);
    assert_eq!(state["system_tracks"], expected["system_tracks"]);
}

#[tokio::test]
async fn batches_over_rest_give_the_batch_endpoints_decisions() {
    let app = spawn_app().await;
    let (batch, reports) = scenario();
    let expected = app.post_ok("/v1/correlation/tracks", &batch).await;

    let created = app.post_json("/v1/sessions", &session_config(&batch)).await;
    assert_eq!(created.status(), 201);
    let location = created.headers()["location"].to_str().unwrap().to_string();
    let session: Value = created.json().await.unwrap();
    let id = session["id"].as_str().unwrap().to_string();
    assert_eq!(location, format!("/v1/sessions/{id}"));
    assert_eq!(id.len(), 32);

    let mut changes = Vec::new();
    for (i, chunk) in reports.chunks(7).enumerate() {
        let body = json!({"sequence": i + 1, "reports": chunk});
        let u = app
            .post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
        assert_eq!(u["duplicate"], false);
        changes.extend(u["changes"].as_array().unwrap().iter().cloned());
        // A retried batch is acknowledged, not applied twice.
        let again = app
            .post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
        assert_eq!(again["duplicate"], true, "{again}");
        assert_eq!(again["version"], u["version"]);
    }
    let n = reports.chunks(7).count();
    let last = app
        .post_ok(
            &format!("/v1/sessions/{id}/batches"),
            &json!({"sequence": n + 1, "flush": true}),
        )
        .await;
    changes.extend(last["changes"].as_array().unwrap().iter().cloned());

    let state: Value = app
        .client
        .get(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(state["pairs"], expected["pairs"]);
    assert_eq!(state["system_tracks"], expected["system_tracks"]);
    assert_eq!(
        state["instants_processed"].as_u64().unwrap() as usize,
        expected["instants"].as_array().unwrap().len()
    );
    let correlated: Vec<_> = changes
        .iter()
        .filter(|c| c["change"] == "correlated")
        .collect();
    let decided = expected["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["decision"] == "correlated")
        .count();
    assert!(decided >= 5, "{expected}");
    assert!(correlated.len() >= decided, "{changes:?}");

    // A batch that skips ahead is refused with 409 and changes nothing.
    let gap = app
        .post_json(
            &format!("/v1/sessions/{id}/batches"),
            &json!({"sequence": n + 5, "flush": true}),
        )
        .await;
    assert_eq!(gap.status(), 409);
    let problem: Value = gap.json().await.unwrap();
    assert!(
        problem["detail"]
            .as_str()
            .unwrap()
            .contains(&format!("{}", n + 2))
    );

    // Listing, deleting.
    let list = app.get_ok("/v1/sessions").await;
    assert_eq!(list["sessions"][0]["id"], id);
    let del = app
        .client
        .delete(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(del.status(), 204);
    let gone = app
        .client
        .get(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(gone.status(), 404);
}

#[tokio::test]
async fn bad_batches_name_the_field_and_change_nothing() {
    let app = spawn_app_with(|s| {
        s.max_batch_reports = 5;
        s.max_tracks_per_session = 3;
        s.max_sessions_per_tenant = 1;
    })
    .await;
    let (batch, reports) = scenario();
    let session: Value = app
        .post_json("/v1/sessions", &session_config(&batch))
        .await
        .json()
        .await
        .unwrap();
    let id = session["id"].as_str().unwrap();
    let url = format!("/v1/sessions/{id}/batches");

    let mut bad = reports[0].clone();
    bad["node"] = json!("nope");
    bad["covariance"][1][1] = json!(-3.0);
    let r = app.post_json(&url, &json!({"reports": [bad]})).await;
    assert_eq!(r.status(), 422);
    let p: Value = r.json().await.unwrap();
    let fields: Vec<&str> = p["errors"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["field"].as_str().unwrap())
        .collect();
    assert_eq!(fields, ["reports[0].node", "reports[0].covariance"]);

    let r = app
        .post_json(&url, &json!({"reports": &reports[..6]}))
        .await;
    assert_eq!(r.status(), 413);
    let r = app
        .post_json(&url, &json!({"reports": &reports[..5]}))
        .await;
    assert_eq!(r.status(), 429, "5 reports of 5 tracks exceed 3 tracks");
    // Sequences start at 1: 0 names its field, 2 on a new session is a gap
    // (so that a concurrent writer's batch 1 is never taken for a duplicate).
    let r = app
        .post_json(&url, &json!({"sequence": 0, "reports": &reports[..1]}))
        .await;
    assert_eq!(r.status(), 422);
    assert!(r.text().await.unwrap().contains("\"field\":\"sequence\""));
    let r = app
        .post_json(&url, &json!({"sequence": 2, "reports": &reports[..1]}))
        .await;
    assert_eq!(r.status(), 409);

    let state: Value = app
        .client
        .get(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(state["batches"], 0);
    assert_eq!(state["version"], 1);

    // One session per tenant here.
    let r = app.post_json("/v1/sessions", &session_config(&batch)).await;
    assert_eq!(r.status(), 429);
    // A bad configuration names its field.
    let mut cfg = session_config(&batch);
    cfg["nodes"] = json!(["a"]);
    cfg["alignment"]["mode"] = json!("interpolate");
    let r = app.post_json("/v1/sessions", &cfg).await;
    assert_eq!(r.status(), 422);
    let text = r.text().await.unwrap();
    assert!(
        text.contains("\"nodes\"") && text.contains("alignment.mode"),
        "{text}"
    );
    // Ids that cannot exist are 404, not 400 or 500.
    for bad_id in ["x", "../../etc", "0123456789abcdef0123456789abcdeg"] {
        let r = app
            .client
            .get(app.url(&format!("/v1/sessions/{bad_id}")))
            .send()
            .await
            .unwrap();
        assert_eq!(r.status(), 404, "{bad_id}");
    }
}

#[tokio::test]
async fn tenants_cannot_see_each_others_sessions() {
    let app = spawn_app_with(|s| {
        s.api_keys = Some("key-of-acme-1=acme,key-of-globex=globex".into());
    })
    .await;
    let (batch, reports) = scenario();
    let as_tenant = |key: &'static str, req: reqwest::RequestBuilder| req.bearer_auth(key);
    let created: Value = as_tenant("key-of-acme-1", app.client.post(app.url("/v1/sessions")))
        .json(&session_config(&batch))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = created["id"].as_str().unwrap();
    let path = format!("/v1/sessions/{id}");
    for (method, url) in [
        (reqwest::Method::GET, path.clone()),
        (reqwest::Method::DELETE, path.clone()),
        (reqwest::Method::POST, format!("{path}/batches")),
    ] {
        let r = as_tenant(
            "key-of-globex",
            app.client.request(method.clone(), app.url(&url)),
        )
        .json(&json!({"reports": &reports[..2]}))
        .send()
        .await
        .unwrap();
        assert_eq!(r.status(), 404, "{method} {url}");
    }
    let list: Value = as_tenant("key-of-globex", app.client.get(app.url("/v1/sessions")))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    assert_eq!(list["sessions"], json!([]));
    let own = as_tenant("key-of-acme-1", app.client.get(app.url(&path)))
        .send()
        .await
        .unwrap();
    assert_eq!(own.status(), 200);
    let anonymous = app.client.get(app.url(&path)).send().await.unwrap();
    assert_eq!(anonymous.status(), 401);
}

#[tokio::test]
async fn grpc_stream_matches_rest_and_a_dropped_stream_leaves_the_session_consistent() {
    use radar_fusion::proto::{self as pb, session_service_client::SessionServiceClient};
    let app = spawn_app().await;
    let (batch, reports) = scenario();
    let mut client = SessionServiceClient::new(app.channel().await);
    let open = pb_open();
    let chunks: Vec<Vec<Value>> = reports.chunks(7).map(<[Value]>::to_vec).collect();
    let half = chunks.len() / 2;
    let (tx, mut updates) = open_stream(&mut client, pb::stream_request::Kind::Open(open)).await;
    let opened = updates.message().await.unwrap().unwrap();
    let id = opened.session_id.clone();
    assert_eq!(id.len(), 32);
    for (i, chunk) in chunks[..half].iter().enumerate() {
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
                sequence: Some(i as u64 + 1),
                reports: chunk.iter().map(pb_report).collect(),
                ..Default::default()
            })),
        })
        .await
        .unwrap();
        let u = updates.message().await.unwrap().unwrap();
        assert_eq!(u.sequence, Some(i as u64 + 1));
        assert!(!u.duplicate);
    }
    // The client disconnects mid-stream.
    drop(tx);
    drop(updates);
    let state = client
        .get_session(pb::GetSessionRequest {
            session_id: id.clone(),
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(state.batches as usize, half);
    assert_eq!(state.last_sequence, Some(half as u64));
    // The rest over REST, on the same session: the batch endpoint's result.
    for (i, chunk) in chunks.iter().enumerate().skip(half) {
        app.post_ok(
            &format!("/v1/sessions/{id}/batches"),
            &json!({"sequence": i + 1, "reports": chunk}),
        )
        .await;
    }
    app.post_ok(
        &format!("/v1/sessions/{id}/batches"),
        &json!({"sequence": chunks.len() + 1, "flush": true}),
    )
    .await;
    let expected = app.post_ok("/v1/correlation/tracks", &batch).await;
    let rest = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(rest["pairs"], expected["pairs"]);
    // Unknown session over gRPC: NOT_FOUND.
    let err = client
        .get_session(pb::GetSessionRequest {
            session_id: "0".repeat(32),
        })
        .await
        .unwrap_err();
    assert_eq!(err.code(), tonic::Code::NotFound);
}

/// Each batch of a gRPC stream is held to the limits of a unary call: with
/// `--max-in-flight 1` and the one slot taken, a batch is shed (its answer
/// carries UNAVAILABLE, nothing queues); a bad batch gets its error inside
/// the stream; the stream stays open and the next good batch is applied.
#[tokio::test]
async fn grpc_stream_batches_are_shed_and_fail_one_by_one_and_the_stream_goes_on() {
    use radar_fusion::proto::{self as pb, session_service_client::SessionServiceClient};
    let app = spawn_app_with(|s| s.max_in_flight = 1).await;
    let (_, reports) = scenario();
    let mut client = SessionServiceClient::new(app.channel().await);
    let batch = |sequence: u64, reports: &[Value]| pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
            sequence: Some(sequence),
            reports: reports.iter().map(pb_report).collect(),
            ..Default::default()
        })),
    };
    let (tx, mut updates) =
        open_stream(&mut client, pb::stream_request::Kind::Open(pb_open())).await;
    let id = updates.message().await.unwrap().unwrap().session_id;

    // Another request holds the only in-flight slot.
    let held = app.state.try_admit().expect("the slot is free");
    tx.send(batch(1, &reports[..4])).await.unwrap();
    let shed = updates
        .message()
        .await
        .unwrap()
        .expect("answered, not ended");
    let error = shed.error.expect("shed");
    assert_eq!(
        (error.code, error.code_name.as_str()),
        (tonic::Code::Unavailable as i32, "UNAVAILABLE")
    );
    assert_eq!(shed.sequence, Some(1));
    drop(held);

    // A bad batch: its error, with the field, inside the stream.
    let mut bad = batch(1, &reports[..4]);
    if let Some(pb::stream_request::Kind::Batch(b)) = &mut bad.kind {
        b.reports[2].node = "nowhere".into();
    }
    tx.send(bad).await.unwrap();
    let failed = updates.message().await.unwrap().expect("answered");
    let error = failed.error.expect("refused");
    assert_eq!(error.code_name, "INVALID_ARGUMENT");
    assert_eq!(error.violations[0].field, "reports[2].node");

    // A gap: FAILED_PRECONDITION, in the stream too.
    tx.send(batch(5, &reports[..4])).await.unwrap();
    let gap = updates.message().await.unwrap().expect("answered");
    assert_eq!(gap.error.expect("gap").code_name, "FAILED_PRECONDITION");

    // The stream goes on: the shed and refused batch 1 is applied now.
    tx.send(batch(1, &reports[..4])).await.unwrap();
    let ok = updates.message().await.unwrap().expect("answered");
    assert!(ok.error.is_none() && !ok.duplicate, "{ok:?}");
    assert_eq!((ok.sequence, ok.version), (Some(1), 2));
    let state = client
        .get_session(pb::GetSessionRequest { session_id: id })
        .await
        .unwrap()
        .into_inner();
    assert_eq!((state.kind.as_str(), state.batches), ("correlation", 1));
}

/// `kind` at creation: `correlation` is the default and may be named; an
/// unknown kind is a 422 naming `kind` (INVALID_ARGUMENT over gRPC); the
/// session, its summary in the list, and the gRPC state say the kind.
#[tokio::test]
async fn sessions_say_their_kind_and_an_unknown_kind_is_refused() {
    use radar_fusion::proto::{self as pb, session_service_client::SessionServiceClient};
    let app = spawn_app().await;
    let (batch, _) = scenario();
    let mut config = session_config(&batch);
    let created = app.post_json("/v1/sessions", &config).await;
    assert_eq!(created.status(), 201);
    let created: Value = created.json().await.unwrap();
    assert_eq!(created["kind"], "correlation");
    config["kind"] = json!("correlation");
    let named = app.post_json("/v1/sessions", &config).await;
    assert_eq!(named.status(), 201);
    let named: Value = named.json().await.unwrap();
    assert_eq!(named["kind"], "correlation");
    config["kind"] = json!("tea_making");
    let problem =
        crate::helpers::assert_problem(app.post_json("/v1/sessions", &config).await, 422).await;
    assert_eq!(crate::helpers::problem_fields(&problem), ["kind"]);
    let list = app.get_ok("/v1/sessions").await;
    let kinds: Vec<&str> = list["sessions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["correlation", "correlation"]);

    let mut client = SessionServiceClient::new(app.channel().await);
    let mut open = pb_open();
    open.kind = "tea_making".into();
    let err = client.create_session(open).await.unwrap_err();
    assert_eq!(err.code(), tonic::Code::InvalidArgument);
    assert_eq!(crate::helpers::grpc_fields(&err), ["kind"]);
    let listed = client
        .list_sessions(pb::ListSessionsRequest {})
        .await
        .unwrap()
        .into_inner();
    assert!(listed.sessions.iter().all(|s| s.kind == "correlation"));
}
