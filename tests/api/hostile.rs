//! Hostile clients (issue 53) through the real servers: a request can not
//! make the service answer much more than it sent. Ids are at most 64
//! bytes, a list of ids is given once however many violations refer to it,
//! a bad request lists at most 100 violations, and a plot-fusion `history`
//! has a bound.

use radar_fusion::proto::plot_fusion_service_client::PlotFusionServiceClient;
use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{
    TestApp, assert_problem, grpc_fields, problem_fields, spawn_app, spawn_app_with,
};
use crate::plot_fusion::plot_scene::{self, SceneRadar, Target, plots, radars_json};
use crate::plot_fusion::proto_request;
use crate::sessions::data::{scenario, session_config};

const PATH: &str = "/v1/plot-fusion/track";

/// A 200 kB id, as the issue's probe sent.
fn huge_id() -> String {
    "r".repeat(200_000)
}

/// Posts `body` and expects a 422 whose whole body is under `max_bytes`;
/// returns the problem.
async fn small_422(app: &TestApp, path: &str, body: &Value, max_bytes: usize) -> Value {
    let response = app.post_json(path, body).await;
    assert_eq!(response.status(), 422);
    let text = response.text().await.unwrap();
    assert!(
        text.len() < max_bytes,
        "a {} byte problem body: {}…",
        text.len(),
        &text[..2000.min(text.len())]
    );
    serde_json::from_str(&text).unwrap()
}

/// The message of the violation of `field`.
fn message<'a>(problem: &'a Value, field: &str) -> &'a str {
    problem["errors"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["field"] == field)
        .unwrap_or_else(|| panic!("no violation of {field}: {problem}"))["message"]
        .as_str()
        .unwrap()
}

#[tokio::test]
async fn a_200_kb_radar_id_is_a_small_422_naming_the_field_on_both_transports() {
    let app = spawn_app().await;
    // The probe: a radar with a 200 kB id and plots naming another radar.
    // Each of the 100 listed violations used to repeat the radars' ids: a
    // 20 MB answer.
    let mut req = plot_scene::request(false, 5);
    req["radars"][0]["id"] = json!(huge_id());
    let p = small_422(&app, PATH, &req, 1_000).await;
    assert_eq!(problem_fields(&p), ["radars[0].id"]);
    assert_eq!(
        message(&p, "radars[0].id"),
        "must be at most 64 bytes, got 200000"
    );

    // The same over gRPC: INVALID_ARGUMENT naming the field, as short.
    let status = PlotFusionServiceClient::new(app.channel().await)
        .track(proto_request(&req))
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    assert_eq!(grpc_fields(&status), ["radars[0].id"]);
    assert!(status.message().len() < 1_000, "{}", status.message());

    // A plot naming a 200 kB radar id is refused by its length, not quoted.
    let mut req = plot_scene::request(false, 5);
    req["plots"][3]["radar_id"] = json!(huge_id());
    let p = small_422(&app, PATH, &req, 4_000).await;
    assert_eq!(problem_fields(&p), ["plots[3].radar_id"]);
    assert_eq!(
        message(&p, "plots[3].radar_id"),
        "must be at most 64 bytes, got 200000"
    );
}

#[tokio::test]
async fn unknown_radars_list_the_network_once_and_violations_are_capped_at_100() {
    let app = spawn_app().await;
    // 64 radars with 64-byte ids (4 kB of ids), and 300 plots naming none
    // of them: the ids are listed in the first violation only, and 100
    // violations are listed, the last entry counting the rest.
    let mut req = plot_scene::request(false, 5);
    let template = req["radars"][0].clone();
    let ids: Vec<String> = (0..64).map(|i| format!("{i:064}")).collect();
    req["radars"] = ids
        .iter()
        .map(|id| {
            let mut r = template.clone();
            r["id"] = json!(id);
            r
        })
        .collect();
    let plots: Vec<Value> = req["plots"]
        .as_array()
        .unwrap()
        .iter()
        .cycle()
        .take(300)
        .map(|p| {
            let mut p = p.clone();
            p["radar_id"] = json!("nowhere");
            p
        })
        .collect();
    req["plots"] = json!(plots);
    // 64 × 66 bytes of ids once, and 100 violations of about 120 bytes.
    let p = small_422(&app, PATH, &req, 20_000).await;
    let errors = p["errors"].as_array().unwrap();
    assert_eq!(errors.len(), 101);
    let first = message(&p, "plots[0].radar_id");
    assert!(first.starts_with("no radar 'nowhere' in the network (radars: 0000"));
    assert!(first.contains(&ids[63]), "{first}");
    assert_eq!(
        message(&p, "plots[1].radar_id"),
        "no radar 'nowhere' in the network (radars: as listed at plots[0].radar_id)"
    );
    assert_eq!(
        message(&p, "plots[100].radar_id"),
        "and 200 more violations not listed"
    );
}

#[tokio::test]
async fn long_node_and_track_ids_are_refused_by_their_length() {
    let app = spawn_app().await;
    let (mut batch, reports) = scenario();
    // Batch correlation: a node and a track id over 64 bytes.
    batch["nodes"][0]["id"] = json!(huge_id());
    batch["nodes"][1]["tracks"][2]["id"] = json!("t".repeat(65));
    let p = small_422(&app, "/v1/correlation/tracks", &batch, 4_000).await;
    assert_eq!(problem_fields(&p), ["nodes[0].id", "nodes[1].tracks[2].id"]);
    assert_eq!(
        message(&p, "nodes[1].tracks[2].id"),
        "must be at most 64 bytes, got 65"
    );

    // A session: 200 reports naming an unknown node, the first 20 with a
    // 200 kB track. The session's nodes are listed once, the track's name
    // is not quoted, and 100 violations are listed.
    let (batch, _) = scenario();
    let r = app.post_json("/v1/sessions", &session_config(&batch)).await;
    assert_eq!(r.status(), 201);
    let session: Value = r.json().await.unwrap();
    let url = format!("/v1/sessions/{}/batches", session["id"].as_str().unwrap());
    let huge = huge_id();
    let bad: Vec<Value> = reports
        .iter()
        .cycle()
        .take(200)
        .enumerate()
        .map(|(i, r)| {
            let mut r = r.clone();
            r["node"] = json!("c");
            if i < 20 {
                r["track"] = json!(huge);
            }
            r
        })
        .collect();
    let p = small_422(&app, &url, &json!({"reports": bad}), 16_000).await;
    assert_eq!(p["errors"].as_array().unwrap().len(), 101);
    assert_eq!(
        message(&p, "reports[0].node"),
        "must be one of a, b, got 'c'"
    );
    assert_eq!(
        message(&p, "reports[0].track"),
        "must be at most 64 bytes, got 200000"
    );
    assert_eq!(
        message(&p, "reports[1].node"),
        "must be one of as listed at reports[0].node, got 'c'"
    );
    // 64 bytes is still an id; a session takes it.
    let mut good = reports[0].clone();
    good["track"] = json!("t".repeat(64));
    let r = app.post_json(&url, &json!({"reports": [good]})).await;
    assert_eq!(r.status(), 200, "{}", r.text().await.unwrap());
}

#[tokio::test]
async fn a_history_over_its_bound_is_refused_naming_the_option() {
    let app = spawn_app().await;
    // 60 aircraft 4 km apart under one 2D radar with 1-s scans, each plot
    // at its own time: every plot is a frame, and after confirmation each
    // frame holds about 60 confirmed tracks. 30 s give about 1,600 frames
    // and 90,000 track states, over the bound of 50,000.
    let radar = SceneRadar {
        id: "west",
        lat: 52.05,
        lon: 3.4,
        three_d: false,
        doppler: false,
        period: 1.0,
        phase: 0.0,
    };
    let targets: Vec<Target> = (0..60)
        .map(|i| Target {
            start: 0.0,
            end: 1e9,
            p0: [
                -60_000.0 + 4_000.0 * f64::from(i % 10),
                -12_000.0 + 4_000.0 * f64::from(i / 10),
                8_000.0,
            ],
            v: [200.0, 0.0, 0.0],
        })
        .collect();
    let mut scan_plots = plots(std::slice::from_ref(&radar), &targets, 30.0, 0.0, 7);
    // Spread each scan's plots over 60 ms: 200 m/s × 60 ms = 12 m, well
    // within the 50 m range noise.
    let mut last = f64::NEG_INFINITY;
    let mut k = 0.0;
    for p in &mut scan_plots {
        let t = p["t"].as_f64().unwrap();
        k = if t == last { k + 1.0 } else { 0.0 };
        last = t;
        p["t"] = json!(t + k * 1e-3);
    }
    let mut req = json!({
        "origin": {"lat_deg": plot_scene::ORIGIN.0, "lon_deg": plot_scene::ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(std::slice::from_ref(&radar), 1e-7),
        "plots": scan_plots,
        "tracker": {"default_height_m": 8000.0},
    });
    // Without the history the request is fine.
    let out = app.post_ok(PATH, &req).await;
    assert!(out["counters"]["frames"].as_u64().unwrap() > 1_500);
    req["history"] = json!(true);
    let p = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&p), ["history"]);
    let m = message(&p, "history");
    assert!(
        m.contains(&format!(
            "at most {} per request",
            service::plot_fusion::MAX_HISTORY_TRACK_STATES
        )),
        "{m}"
    );
}

#[tokio::test]
async fn a_tenant_over_its_share_of_the_memory_store_gets_a_429_naming_the_limit() {
    const ACME: &str = "acme-key-0123456789";
    const GLOBEX: &str = "globex-key-0123456789";
    let (batch, _) = scenario();
    let config = session_config(&batch);
    // One such session's stored size, from a store without the bound.
    let probe = spawn_app().await;
    let created = probe.post_json("/v1/sessions", &config).await;
    assert_eq!(created.status(), 201);
    let one = created.json::<Value>().await.unwrap()["encoded_bytes"]
        .as_u64()
        .unwrap() as usize;
    // Room for one session of each tenant, not two.
    let share = one * 3 / 2;
    let app = spawn_app_with(|s| {
        s.api_keys = Some(format!("{ACME}=acme,{GLOBEX}=globex").as_str().into());
        s.session_memory_bytes_per_tenant = share;
    })
    .await;
    let create = |key: &'static str| {
        app.client
            .post(app.url("/v1/sessions"))
            .bearer_auth(key)
            .json(&config)
            .send()
    };
    assert_eq!(create(ACME).await.unwrap().status(), 201);
    let problem = assert_problem(create(ACME).await.unwrap(), 429).await;
    let detail = problem["detail"].as_str().unwrap();
    assert!(
        detail.contains(&format!("{share} bytes"))
            && detail.contains("FUSION_SESSION_MEMORY_BYTES_PER_TENANT"),
        "{detail}"
    );
    // The other tenant's share is its own.
    assert_eq!(create(GLOBEX).await.unwrap().status(), 201);
}

#[tokio::test]
async fn co_located_tracks_over_the_candidate_pair_budget_are_a_422_naming_it() {
    let app = spawn_app().await;
    // Two nodes of 1,001 tracks, all at the origin: every one of the
    // 1,001² = 1,002,001 pairs is inside the gate, one more than a request
    // may hold (1,000,000). Before, each became a pair with its state (a
    // few hundred bytes): the product of the nodes grew without a bound.
    let node = |id: &str| {
        let tracks: Vec<Value> = (0..1001)
            .map(|i| {
                json!({"id": format!("{id}{i}"), "samples": [
                    {"t": 0.0, "state": [0.0, 0.0], "covariance": [[1.0, 0.0], [0.0, 1.0]]}
                ]})
            })
            .collect();
        json!({"id": id, "tracks": tracks})
    };
    let method = json!({"kind": "independent_double_threshold", "rule": {"l": 1, "r": 1}});
    let req =
        json!({"state_layout": ["x", "y"], "method": method, "nodes": [node("a"), node("b")]});
    let p = small_422(&app, "/v1/correlation/tracks", &req, 2_000).await;
    assert_eq!(problem_fields(&p), ["nodes"]);
    let m = message(&p, "nodes");
    assert!(
        m.contains("more than 1000000 candidate pairs") && m.contains("method.alpha"),
        "{m}"
    );
}

/// A JPDA update that computes for long: 24 scalar tracks at 0 and
/// `scans` sensors of 24 measurements near 0, so every scan is one cluster
/// of 24 tracks whose exact hypothesis tree runs into its 2·10⁶-edge budget
/// before it falls back to AMSJPDA.
fn slow_jpda(scans: usize) -> Value {
    let tracks: Vec<Value> = (0..24)
        .map(|i| json!({"id": format!("t{i}"), "state": [0.0], "covariance": [[1.0]]}))
        .collect();
    let sensor = |s: usize| {
        let z: Vec<Value> = (0..24)
            .map(|j| json!({"z": [(j as f64 - 12.0) * 0.01]}))
            .collect();
        json!({"id": format!("s{s}"), "kind": "linear", "h": [[1.0]], "r": [[1.0]],
               "detection_probability": 0.9, "clutter_density": 0.1, "measurements": z})
    };
    json!({"tracks": tracks, "sensors": (0..scans).map(sensor).collect::<Vec<_>>()})
}

/// The value of the counter `name` with `label` in a `/metrics` text (0
/// when absent).
fn counter(metrics: &str, name: &str, label: &str) -> f64 {
    metrics
        .lines()
        .find(|l| l.starts_with(name) && l.contains(label))
        .and_then(|l| l.rsplit(' ').next())
        .map_or(0.0, |v| v.parse().unwrap())
}

#[tokio::test]
async fn a_request_that_times_out_stops_its_computation_and_frees_its_slot() {
    let app = spawn_app_with(|s| {
        s.max_in_flight = 1;
        s.request_timeout_s = 1.0;
    })
    .await;
    let name = "compute_jobs_cancelled_total";
    let stopped_before = counter(&app.metrics_text().await, name, "stage=\"running\"");
    let r = app.post_json("/v1/jpda/update", &slow_jpda(32)).await;
    assert_eq!(r.status(), 504);
    // The computation holds the only in-flight slot until it stops: before
    // the change it kept computing (for minutes) with its slot given back
    // at the 504; now it stops at the next scan, and the slot with it.
    let small = json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]});
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    loop {
        let r = app
            .post_json("/v1/correlation/rules/evaluate", &small)
            .await;
        if r.status() == 200 {
            break;
        }
        assert_eq!(r.status(), 503, "shed while the slot is held");
        assert!(
            std::time::Instant::now() < deadline,
            "the slot was never given back"
        );
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
    }
    let stopped = counter(&app.metrics_text().await, name, "stage=\"running\"");
    assert!(
        stopped > stopped_before,
        "no computation stopped at a checkpoint ({stopped_before} → {stopped})"
    );
}

#[tokio::test]
async fn with_every_lane_busy_a_request_past_the_blocking_bound_is_a_503_naming_it() {
    // No computation of this service may go to the blocking pool: once
    // every compute lane is held by a long request, the next is shed.
    let app = spawn_app_with(|s| s.max_blocking_jobs = 0).await;
    let lanes = std::thread::available_parallelism().map_or(1, |n| n.get());
    let slow = slow_jpda(32);
    // One long request per lane, sent again whenever it ends (shed because
    // other tests' jobs held the lanes at that moment, or stopped by its
    // timeout), so that the lanes stay held until the test ends.
    let held: Vec<_> = (0..lanes)
        .map(|_| {
            let (client, url, body) =
                (app.client.clone(), app.url("/v1/jpda/update"), slow.clone());
            tokio::spawn(async move {
                loop {
                    let _ = client.post(&url).json(&body).send().await;
                    tokio::time::sleep(std::time::Duration::from_millis(10)).await;
                }
            })
        })
        .collect();
    let small = json!({"alpha": 0.05, "rules": [{"l": 1, "r": 1}]});
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
    let response = loop {
        let r = app
            .post_json("/v1/correlation/rules/evaluate", &small)
            .await;
        if r.status() == 503 {
            break r;
        }
        // 200: a lane was free (the long jobs, this test's or another
        // test's in this process, come and go). Never a 504: a small job
        // queued while a lane was free is handed back by the lanes' watch
        // once every lane is held, and then shed like new work (before,
        // it waited behind the long jobs past its timeout).
        assert_eq!(r.status(), 200);
        assert!(
            std::time::Instant::now() < deadline,
            "the lanes were never all held"
        );
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    };
    assert_eq!(response.headers()["retry-after"], "1");
    let problem = assert_problem(response, 503).await;
    assert_eq!(problem["type"], "urn:radar-fusion:problem:overloaded");
    let detail = problem["detail"].as_str().unwrap();
    assert!(detail.contains("FUSION_MAX_BLOCKING_JOBS"), "{detail}");
    // The long requests' clients leave; their computations stop.
    for h in held {
        h.abort();
    }
}
