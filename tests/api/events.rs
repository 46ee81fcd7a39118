//! `GET /v1/sessions/{id}/events` and gRPC `SessionService/Watch`: a
//! session's committed updates, in version order, to its watchers.

use std::time::Duration;

use radar_fusion::proto::{self as pb, session_service_client::SessionServiceClient};
use serde_json::{Value, json};

use crate::{
    cat062::request_with_cat062,
    helpers::{TestApp, assert_problem, spawn_app, spawn_app_with},
    sessions::data::open_stream,
};

/// One parsed Server-Sent Event.
#[derive(Debug)]
struct Sse {
    event: String,
    id: Option<u64>,
    data: Value,
}

/// Reads SSE blocks from a streaming response (comments skipped).
struct Reader {
    response: reqwest::Response,
    buf: String,
}

impl Reader {
    async fn next(&mut self) -> Sse {
        loop {
            if let Some(i) = self.buf.find("\n\n") {
                let block: String = self.buf.drain(..i + 2).collect();
                let (mut event, mut id, mut data) = ("message".to_string(), None, String::new());
                for line in block.lines() {
                    if let Some(v) = line.strip_prefix("event:") {
                        event = v.trim().to_string();
                    } else if let Some(v) = line.strip_prefix("id:") {
                        id = v.trim().parse().ok();
                    } else if let Some(v) = line.strip_prefix("data:") {
                        data.push_str(v.trim_start());
                    }
                }
                if data.is_empty() {
                    continue; // a heartbeat comment
                }
                return Sse {
                    event,
                    id,
                    data: serde_json::from_str(&data).unwrap(),
                };
            }
            let chunk = tokio::time::timeout(Duration::from_secs(20), self.response.chunk())
                .await
                .expect("an event within 20 s")
                .unwrap()
                .expect("the stream is open");
            self.buf
                .push_str(&String::from_utf8_lossy(&chunk).replace("\r\n", "\n"));
        }
    }
}

async fn open(app: &TestApp, id: &str, last: Option<u64>) -> reqwest::Response {
    let mut req = app
        .client
        .get(app.url(&format!("/v1/sessions/{id}/events")));
    if let Some(v) = last {
        req = req.header("Last-Event-ID", v.to_string());
    }
    req.send().await.unwrap()
}

async fn reader(app: &TestApp, id: &str, last: Option<u64>) -> Reader {
    let response = open(app, id, last).await;
    assert_eq!(response.status(), 200);
    assert_eq!(
        response.headers()["content-type"].to_str().unwrap(),
        "text/event-stream"
    );
    Reader {
        response,
        buf: String::new(),
    }
}

/// A plot-fusion session of the CAT062 scene and its plots in time order,
/// in `n` batches.
async fn scene(app: &TestApp, n: usize) -> (String, Vec<Value>) {
    let req = request_with_cat062();
    let mut create = json!({"kind": "plot_fusion"});
    for k in ["origin", "radars"] {
        create[k] = req[k].clone();
    }
    let created = app.post_json("/v1/sessions", &create).await;
    assert_eq!(created.status(), 201);
    let created: Value = created.json().await.unwrap();
    let id = created["id"].as_str().unwrap().to_string();
    let mut plots: Vec<Value> = req["plots"].as_array().unwrap().clone();
    plots.sort_by(|a, b| {
        a["t"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["t"].as_f64().unwrap())
    });
    let size = plots.len().div_ceil(n);
    let batches = plots
        .chunks(size)
        .enumerate()
        .map(|(k, c)| json!({"sequence": k + 1, "plots": c}))
        .collect();
    (id, batches)
}

#[tokio::test]
async fn updates_arrive_in_order_resume_and_end_on_delete() {
    let app = spawn_app().await;
    let (id, batches) = scene(&app, 4).await;
    let mut watcher = reader(&app, &id, None).await;
    let first = watcher.next().await;
    assert_eq!(first.event, "snapshot");
    assert_eq!(first.id, Some(1));
    assert_eq!(first.data["version"], 1);
    let sites = first.data["plot_fusion"]["sites"].as_array().unwrap();
    assert_eq!(sites.len(), 2);
    assert!(sites[0]["lat_deg"].is_f64(), "{}", first.data);
    let mut answers = Vec::new();
    for b in &batches {
        answers.push(app.post_ok(&format!("/v1/sessions/{id}/batches"), b).await);
    }
    for (k, answer) in answers.iter().enumerate() {
        let e = watcher.next().await;
        assert_eq!(e.event, "update");
        assert_eq!(e.id, Some(k as u64 + 2));
        // The push's answer, plus where its plots are.
        let mut data = e.data.clone();
        let plots = data["plot_fusion"]
            .as_object_mut()
            .unwrap()
            .remove("plots")
            .expect("an update event carries its plots");
        assert_eq!(&data, answer);
        let sent = batches[k]["plots"].as_array().unwrap().len();
        let late = answer["plot_fusion"]["late_plots"]
            .as_array()
            .unwrap()
            .len();
        assert_eq!(plots.as_array().unwrap().len(), sent - late);
    }
    // The page and programs see the confirmed tracks the session holds.
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert!(
        state["plot_fusion"]["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t["status"] == "confirmed"),
        "{state}"
    );

    // Resuming after version 2: the held updates 3.., no snapshot.
    let mut resumed = reader(&app, &id, Some(2)).await;
    for v in 3..=batches.len() as u64 + 1 {
        let e = resumed.next().await;
        assert_eq!((e.event.as_str(), e.id), ("update", Some(v)));
    }
    // Resuming from a version this replica never held: a fresh snapshot.
    let mut fresh = reader(&app, &id, Some(10_000)).await;
    let e = fresh.next().await;
    assert_eq!(
        (e.event.as_str(), e.id),
        ("snapshot", Some(batches.len() as u64 + 1))
    );

    let deleted = app
        .client
        .delete(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(deleted.status(), 204);
    for r in [&mut watcher, &mut resumed, &mut fresh] {
        let end = r.next().await;
        assert_eq!(end.event, "end");
        assert_eq!(end.data["reason"], "deleted", "{:?}", end.data);
        assert!(
            tokio::time::timeout(Duration::from_secs(5), r.response.chunk())
                .await
                .unwrap()
                .unwrap()
                .is_none(),
            "the stream closes after its end event"
        );
    }
    // A bad Last-Event-ID names the header; no such session is a 404.
    let bad = app
        .client
        .get(app.url(&format!("/v1/sessions/{id}/events")))
        .header("Last-Event-ID", "soon")
        .send()
        .await
        .unwrap();
    let p = assert_problem(bad, 422).await;
    assert!(p.to_string().contains("Last-Event-ID"), "{p}");
    assert_problem(open(&app, &id, None).await, 404).await;
}

#[tokio::test]
async fn watchers_are_capped_per_session_and_tenant_and_isolated() {
    const ACME: &str = "acme-key-0123456789";
    const GLOBEX: &str = "globex-key-0123456789";
    let app = spawn_app_with(|s| {
        s.api_keys = Some(format!("{ACME}=acme,{GLOBEX}=globex").as_str().into());
        s.watchers_per_session = 1;
        s.watchers_per_tenant = 2;
    })
    .await;
    let auth = |key: &str| format!("Bearer {key}");
    let create = |key: &'static str| {
        let req = request_with_cat062();
        let body = json!({"kind": "plot_fusion", "origin": req["origin"], "radars": req["radars"]});
        let c = app
            .client
            .post(app.url("/v1/sessions"))
            .header("authorization", auth(key));
        async move {
            let r = c.json(&body).send().await.unwrap();
            assert_eq!(r.status(), 201);
            r.json::<Value>().await.unwrap()["id"]
                .as_str()
                .unwrap()
                .to_string()
        }
    };
    let watch = |key: &str, id: &str| {
        app.client
            .get(app.url(&format!("/v1/sessions/{id}/events")))
            .header("authorization", auth(key))
            .send()
    };
    let (a1, a2, a3) = (create(ACME).await, create(ACME).await, create(ACME).await);
    let w1 = watch(ACME, &a1).await.unwrap();
    assert_eq!(w1.status(), 200);
    // A second watcher of the same session: over the per-session cap.
    let p = assert_problem(watch(ACME, &a1).await.unwrap(), 429).await;
    assert!(p.to_string().contains("watchers"), "{p}");
    let w2 = watch(ACME, &a2).await.unwrap();
    assert_eq!(w2.status(), 200);
    // A third of the tenant: over the per-tenant cap.
    assert_problem(watch(ACME, &a3).await.unwrap(), 429).await;
    // Another tenant cannot watch acme's session (and its caps are its own).
    assert_problem(watch(GLOBEX, &a3).await.unwrap(), 404).await;
    assert_problem(
        app.client
            .get(app.url(&format!("/v1/sessions/{a3}/events")))
            .send()
            .await
            .unwrap(),
        401,
    )
    .await;
    // A watcher that leaves frees its place.
    drop(w1);
    let mut ok = false;
    for _ in 0..50 {
        let r = watch(ACME, &a1).await.unwrap();
        if r.status() == 200 {
            ok = true;
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(ok, "the place of a closed watcher is free again");
    drop(w2);
}

#[tokio::test]
async fn watching_an_id_that_names_no_session_is_a_404_and_registers_no_watcher() {
    let app = spawn_app_with(|s| s.watchers_per_tenant = 2).await;
    let hub = app.state.sessions().events();
    // Random well-formed ids, more than the tenant's watcher cap: each is
    // a 404 (never a 429), and none leaves a channel in the hub.
    let ids: Vec<String> = (0..5u128)
        .map(|i| format!("{:032x}", 0x5eed_0000_u128 + i))
        .collect();
    for id in &ids {
        assert_problem(open(&app, id, None).await, 404).await;
        assert!(!hub.watched("default", id), "a channel left for {id}");
    }
    let mut client = SessionServiceClient::new(app.channel().await);
    for id in &ids {
        let missing = client
            .watch(pb::WatchRequest {
                session_id: id.clone(),
                after_version: None,
            })
            .await
            .unwrap_err();
        assert_eq!(missing.code(), tonic::Code::NotFound);
        assert!(!hub.watched("default", id), "a channel left for {id}");
    }
    // A session that exists is watched, and its channel is there.
    let (id, _) = scene(&app, 1).await;
    let _watch = reader(&app, &id, None).await;
    assert!(hub.watched("default", &id));
}

#[tokio::test]
async fn grpc_watch_streams_the_same_updates() {
    let app = spawn_app().await;
    let (id, batches) = scene(&app, 3).await;
    let mut client = SessionServiceClient::new(app.channel().await);
    let mut stream = client
        .watch(pb::WatchRequest {
            session_id: id.clone(),
            after_version: None,
        })
        .await
        .unwrap()
        .into_inner();
    let first = stream.message().await.unwrap().unwrap();
    assert_eq!(first.version, 1);
    assert!(matches!(
        first.event,
        Some(pb::watch_event::Event::Snapshot(_))
    ));
    for (k, b) in batches.iter().enumerate() {
        // Pushed over the gRPC batch call.
        let plots: Vec<pb::RadarPlot> = b["plots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| serde_json::from_value::<Value>(p.clone()).unwrap())
            .map(|p| pb::RadarPlot {
                radar_id: p["radar_id"].as_str().unwrap().into(),
                t: p["t"].as_f64(),
                range_m: p["range_m"].as_f64(),
                azimuth_deg: p["azimuth_deg"].as_f64(),
                elevation_deg: p["elevation_deg"].as_f64(),
                radial_velocity_mps: p["radial_velocity_mps"].as_f64(),
                ..Default::default()
            })
            .collect();
        // Odd batches over the unary call, even ones over the batch stream.
        let request = pb::PushBatchRequest {
            session_id: id.clone(),
            sequence: Some(k as u64 + 1),
            plots,
            ..Default::default()
        };
        let answer = if k % 2 == 0 {
            client.push_batch(request).await.unwrap().into_inner()
        } else {
            let (tx, mut answers) =
                open_stream(&mut client, pb::stream_request::Kind::Attach(id.clone())).await;
            let opened = answers.message().await.unwrap().unwrap();
            assert_eq!(opened.session_id, id);
            tx.send(pb::StreamRequest {
                kind: Some(pb::stream_request::Kind::Batch(request)),
            })
            .await
            .unwrap();
            answers.message().await.unwrap().unwrap()
        };
        let e = stream.message().await.unwrap().unwrap();
        assert_eq!(e.version, k as u64 + 2);
        let Some(pb::watch_event::Event::Update(mut u)) = e.event else {
            panic!("an update, got {e:?}");
        };
        let pf = u.plot_fusion.as_mut().unwrap();
        assert!(!pf.plots.is_empty());
        pf.plots.clear();
        assert_eq!(u, answer);
    }
    client
        .delete_session(pb::DeleteSessionRequest {
            session_id: id.clone(),
        })
        .await
        .unwrap();
    let end = stream.message().await.unwrap().unwrap();
    let Some(pb::watch_event::Event::End(end)) = end.event else {
        panic!("an end, got {end:?}");
    };
    assert_eq!(end.reason, "deleted");
    assert!(stream.message().await.unwrap().is_none());
    // No such session: NOT_FOUND.
    let missing = client
        .watch(pb::WatchRequest {
            session_id: id,
            after_version: None,
        })
        .await
        .unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound);
}

#[tokio::test]
async fn the_view_page_is_served_whole_and_offline() {
    let app = spawn_app().await;
    let r = app.client.get(app.url("/view/")).send().await.unwrap();
    assert_eq!(r.status(), 200);
    assert!(
        r.headers()["content-type"]
            .to_str()
            .unwrap()
            .starts_with("text/html")
    );
    let csp = r.headers()["content-security-policy"]
        .to_str()
        .unwrap()
        .to_string();
    assert!(csp.contains("default-src 'none'"), "{csp}");
    // Scripts only from this origin's files, none inline; no framing.
    let script_src = csp
        .split(';')
        .map(str::trim)
        .find(|d| d.starts_with("script-src"))
        .expect("a script-src directive");
    assert_eq!(script_src, "script-src 'self'", "{csp}");
    // Nothing inline at all: styles from this origin's file too (issue 53).
    assert!(!csp.contains("unsafe-inline"), "{csp}");
    assert!(csp.contains("frame-ancestors 'none'"), "{csp}");
    assert_eq!(r.headers()["x-frame-options"], "DENY");
    let page = r.text().await.unwrap();
    // The page's one script is its file; no inline script or handler.
    assert_eq!(page.matches("<script").count(), 1);
    assert!(page.contains(r#"<script src="view.js"></script>"#));
    assert!(!page.contains(" onclick=") && !page.contains(" onload="));
    // Its styles are its stylesheet: no <style> element, no style attribute.
    assert!(!page.contains("<style") && !page.contains(" style="));
    assert!(page.contains(r#"<link rel="stylesheet" href="view.css">"#));
    let r = app
        .client
        .get(app.url("/view/view.css"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(r.headers()["content-type"], "text/css; charset=utf-8");
    assert!(r.text().await.unwrap().contains("--conf:"));
    let r = app
        .client
        .get(app.url("/view/view.js"))
        .send()
        .await
        .unwrap();
    assert_eq!(r.status(), 200);
    assert_eq!(
        r.headers()["content-type"],
        "text/javascript; charset=utf-8"
    );
    let script = r.text().await.unwrap();
    assert!(script.contains("/v1/sessions/") && script.contains("Last-Event-ID"));
    // Nothing fetched from anywhere else.
    for text in [&page, &script] {
        assert!(
            !text.contains("http://") && !text.contains("https://"),
            "no external URL"
        );
    }
}
