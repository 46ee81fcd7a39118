//! The streaming-session scenario shared by `tests/api/sessions.rs` and
//! `tests/sessions_redis.rs`: reports of two radars as JSON, the session
//! configuration, and their gRPC forms.

// Helpers shared by test targets: `pub` is for the modules that use them.
#![allow(unreachable_pub)]

use radar_fusion::proto as pb;
use serde_json::{Value, json};

/// Two radars, six straight targets, radar b reporting 0.3 s after radar a;
/// targets 0 and 1 cross mid-way.
pub fn scenario() -> (Value, Vec<Value>) {
    scenario_offset(0.3, Some("predict"))
}

/// The scenario with radar b reporting `offset` s after radar a (scans every
/// 2 s) and the given alignment mode (`None`: the default grid).
pub fn scenario_offset(offset_b: f64, mode: Option<&str>) -> (Value, Vec<Value>) {
    let mut reports = Vec::new();
    let mut nodes = Vec::new();
    for (node, offset, bias) in [("a", 0.0, 0.0), ("b", offset_b, 15.0)] {
        let mut tracks = Vec::new();
        for target in 0..6 {
            let (x0, y0, vx, vy) = match target {
                0 => (0.0, 0.0, 120.0, 10.0),
                1 => (2400.0, 200.0, -120.0, -10.0),
                t => (f64::from(t) * 5000.0, 7000.0, 30.0, -60.0),
            };
            let mut samples = Vec::new();
            for scan in 0..15 {
                let t = f64::from(scan) * 2.0 + offset;
                // Deterministic "noise": a different fixed pattern per radar.
                let e = bias * (f64::from(scan * 7 + target) % 5.0 - 2.0) / 2.0;
                let sample = json!({
                    "t": t,
                    "state": [x0 + vx * t + e, vx, y0 + vy * t - e, vy],
                    "covariance": [[400.0, 0.0, 0.0, 0.0], [0.0, 25.0, 0.0, 0.0],
                                   [0.0, 0.0, 400.0, 0.0], [0.0, 0.0, 0.0, 25.0]],
                });
                let mut report = sample.clone();
                report["node"] = json!(node);
                report["track"] = json!(format!("{node}{target}"));
                reports.push(report);
                samples.push(sample);
            }
            tracks.push(json!({"id": format!("{node}{target}"), "samples": samples}));
        }
        nodes.push(json!({"id": node, "tracks": tracks}));
    }
    reports.sort_by(|a, b| {
        a["t"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["t"].as_f64().unwrap())
    });
    let mut batch = json!({
        "state_layout": ["x", "vx", "y", "vy"],
        "method": {"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}},
        "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0},
        "nodes": nodes,
    });
    if let Some(mode) = mode {
        batch["alignment"] = json!({"mode": mode, "tolerance_s": 0.5});
    }
    (batch, reports)
}

pub fn session_config(batch: &Value) -> Value {
    let mut c = batch.clone();
    c["nodes"] = json!(["a", "b"]);
    c["history_instants"] = json!(64);
    c
}

pub fn pb_report(r: &Value) -> pb::TrackReport {
    let cov: Vec<f64> = r["covariance"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|row| row.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()))
        .collect();
    pb::TrackReport {
        node: r["node"].as_str().unwrap().into(),
        track: r["track"].as_str().unwrap().into(),
        sample: Some(pb::TrackSample {
            t: r["t"].as_f64(),
            state: r["state"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect(),
            covariance: Some(pb::Matrix {
                rows: 4,
                cols: 4,
                values: cov,
            }),
            gain: None,
        }),
    }
}

/// The gRPC form of [`session_config`].
pub fn pb_open() -> pb::CreateSessionRequest {
    pb::CreateSessionRequest {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(pb::CorrelationMethod {
            kind: Some("independent_double_threshold".into()),
            rule: Some(pb::LrRule {
                l: Some(3),
                r: Some(4),
            }),
            ..Default::default()
        }),
        motion_model: Some(pb::MotionModel {
            process_noise: Some("dwna".into()),
            sigma_a_mps2: Some(1.0),
            ..Default::default()
        }),
        alignment: Some(pb::Alignment {
            mode: Some("predict".into()),
            tolerance_s: Some(0.5),
            ..Default::default()
        }),
        nodes: vec!["a".into(), "b".into()],
        history_instants: Some(64),
        ..Default::default()
    }
}

/// A bidirectional session stream whose first message is `first` (`Open`
/// or `Attach`): the sender for the following messages and the answers.
pub async fn open_stream(
    client: &mut pb::session_service_client::SessionServiceClient<tonic::transport::Channel>,
    first: pb::stream_request::Kind,
) -> (
    tokio::sync::mpsc::Sender<pb::StreamRequest>,
    tonic::Streaming<pb::BatchUpdate>,
) {
    let (tx, rx) = tokio::sync::mpsc::channel(8);
    tx.send(pb::StreamRequest { kind: Some(first) })
        .await
        .expect("the stream takes its first message");
    let updates = client
        .stream(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await
        .expect("the stream opens")
        .into_inner();
    (tx, updates)
}
