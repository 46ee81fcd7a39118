//! Batch track-to-track correlation through the real servers.

use radar_fusion::proto as pb;
use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{assert_problem, grpc_fields, problem_fields, spawn_app};

const PATH: &str = "/v1/correlation/tracks";

/// Deterministic pseudo-noise in [−1, 1] (no RNG needed for these tests).
fn wobble(i: usize) -> f64 {
    ((i as f64) * 12.9898).sin() * 0.5 + ((i as f64) * 78.233).cos() * 0.5
}

/// A target moving at constant velocity, seen by a node with position noise
/// of about ±`noise` m, reported every 4 s from `t0`, 8 samples.
fn track(id: &str, start: (f64, f64), v: (f64, f64), t0: f64, noise: f64, seed: usize) -> Value {
    let cov = json!([
        [400.0, 0.0, 0.0, 0.0],
        [0.0, 100.0, 0.0, 0.0],
        [0.0, 0.0, 400.0, 0.0],
        [0.0, 0.0, 0.0, 100.0]
    ]);
    let samples: Vec<Value> = (0..8)
        .map(|k| {
            let t = t0 + 4.0 * k as f64;
            let e = noise * wobble(seed * 100 + k);
            let n = noise * wobble(seed * 100 + k + 50);
            json!({"t": t, "state": [start.0 + v.0 * t + e, v.0, start.1 + v.1 * t + n, v.1], "covariance": cov})
        })
        .collect();
    json!({"id": id, "samples": samples})
}

const TARGETS: [((f64, f64), (f64, f64)); 3] = [
    ((0.0, 0.0), (100.0, 0.0)),
    ((5000.0, 0.0), (0.0, 120.0)),
    ((0.0, 8000.0), (-60.0, 60.0)),
];

fn node(id: &str, t0: f64, seed: usize) -> Value {
    let tracks: Vec<Value> = TARGETS
        .iter()
        .enumerate()
        .map(|(i, &(s, v))| track(&format!("{id}-{i}"), s, v, t0, 10.0, seed + i))
        .collect();
    json!({"id": id, "tracks": tracks})
}

fn request(method: Value, nodes: Vec<Value>) -> Value {
    json!({
        "state_layout": ["x", "vx", "y", "vy"],
        "method": method,
        "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0},
        "nodes": nodes,
    })
}

fn correlated(body: &Value) -> Vec<(String, String)> {
    let mut out: Vec<_> = body["pairs"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|p| p["decision"] == "correlated")
        .map(|p| {
            (
                p["a"]["track"].as_str().unwrap().to_string(),
                p["b"]["track"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    out.sort();
    out
}

#[tokio::test]
async fn every_method_correlates_three_well_separated_targets() {
    let app = spawn_app().await;
    let expected: Vec<(String, String)> = (0..3)
        .map(|i| (format!("r1-{i}"), format!("r2-{i}")))
        .collect();
    for kind in [
        "weighted",
        "modified",
        "independent_double_threshold",
        "dependent_double_threshold",
        "double_threshold_assignment",
        "nearest_neighbour",
        "k_nearest_neighbour",
        "global_assignment",
    ] {
        let body = request(
            json!({"kind": kind}),
            vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
        );
        let response = app.post_json(PATH, &body).await;
        assert_eq!(response.status(), 200, "{kind}");
        let body: Value = response.json().await.unwrap();
        assert_eq!(correlated(&body), expected, "{kind}: {body}");
        assert_eq!(body["system_tracks"].as_array().unwrap().len(), 3, "{kind}");
        assert_eq!(body["thresholds"]["dof"], 4);
        // δ = χ²₄(0.95) = 9.487729036781154 (published table value).
        assert!((body["thresholds"]["delta"].as_f64().unwrap() - 9.487729036781154).abs() < 1e-9);
        assert_eq!(body["unpaired"][0]["tracks"], json!([]));
    }
}

#[tokio::test]
async fn double_threshold_reports_quality_counters_and_the_rule() {
    let app = spawn_app().await;
    let body = request(
        json!({"kind": "independent_double_threshold", "rule": {"l": 6, "r": 8}}),
        vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
    );
    let body: Value = app.post_ok(PATH, &body).await;
    assert_eq!(body["thresholds"]["rule"], json!({"l": 6, "r": 8}));
    assert_eq!(body["gains"], "not_used");
    let pair = &body["pairs"][0];
    // Same target with ~10 m noise against 20 m σ: every sample passes, so
    // m reaches L = 6 at the sixth instant (t = 20 s) with no competitor
    // (eq. 17), and m = 8, C = 0 after all eight.
    assert_eq!(pair["reason"], "early_decision");
    assert_eq!(pair["decided_at_t"], 20.0);
    assert_eq!((pair["m"].as_u64(), pair["c"].as_u64()), (Some(8), Some(0)));
}

#[tokio::test]
async fn rest_and_grpc_return_identical_results() {
    let app = spawn_app().await;
    let rest: Value = app
        .post_ok(
            PATH,
            &request(
                json!({"kind": "dependent_double_threshold", "rule": {"l": 3, "r": 4}}),
                vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
            ),
        )
        .await;
    let grpc_req = pb::CorrelateTracksRequest {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(pb::CorrelationMethod {
            kind: Some("dependent_double_threshold".into()),
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
        nodes: ["r1", "r2"]
            .iter()
            .zip([1, 7])
            .map(|(id, seed)| to_proto_node(&node(id, 0.0, seed)))
            .collect(),
        ..Default::default()
    };
    let grpc = app
        .correlation()
        .await
        .correlate_tracks(grpc_req)
        .await
        .unwrap()
        .into_inner();
    let rest_pairs = rest["pairs"].as_array().unwrap();
    assert_eq!(rest_pairs.len(), grpc.pairs.len());
    for (r, g) in rest_pairs.iter().zip(&grpc.pairs) {
        assert_eq!(r["decision"], g.decision.as_str());
        assert_eq!(r["reason"], g.reason.as_str());
        assert_eq!(r["m"], g.m);
        assert_eq!(r["c"], g.c);
        assert_eq!(r["mean_statistic"].as_f64(), g.mean_statistic);
    }
    let rest_tracks = rest["system_tracks"].as_array().unwrap();
    assert_eq!(rest_tracks.len(), grpc.system_tracks.len());
    for (r, g) in rest_tracks.iter().zip(&grpc.system_tracks) {
        let state: Vec<f64> = r["state"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(state, g.state);
        assert_eq!(r["fusion"], g.fusion.as_str());
    }
    assert_eq!(
        rest["instants"].as_array().unwrap().len(),
        grpc.instants.len()
    );
}

fn to_proto_node(n: &Value) -> pb::Node {
    pb::Node {
        id: n["id"].as_str().unwrap().into(),
        tracks: n["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| pb::LocalTrack {
                id: t["id"].as_str().unwrap().into(),
                samples: t["samples"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|s| pb::TrackSample {
                        t: s["t"].as_f64(),
                        state: s["state"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|x| x.as_f64().unwrap())
                            .collect(),
                        covariance: Some(pb::Matrix {
                            rows: 4,
                            cols: 4,
                            values: s["covariance"]
                                .as_array()
                                .unwrap()
                                .iter()
                                .flat_map(|r| {
                                    r.as_array().unwrap().iter().map(|x| x.as_f64().unwrap())
                                })
                                .collect(),
                        }),
                        gain: None,
                    })
                    .collect(),
            })
            .collect(),
    }
}

#[tokio::test]
async fn three_nodes_form_consistent_groups_with_fused_system_tracks() {
    let app = spawn_app().await;
    let body = request(
        json!({"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}}),
        vec![node("a", 0.0, 1), node("b", 0.0, 7), node("c", 0.0, 13)],
    );
    let body: Value = app.post_ok(PATH, &body).await;
    let groups = body["system_tracks"].as_array().unwrap();
    assert_eq!(groups.len(), 3, "{body}");
    for (i, g) in groups.iter().enumerate() {
        let members: Vec<&str> = g["members"]
            .as_array()
            .unwrap()
            .iter()
            .map(|m| m["track"].as_str().unwrap())
            .collect();
        assert_eq!(
            members,
            vec![format!("a-{i}"), format!("b-{i}"), format!("c-{i}")]
        );
        assert_eq!(g["fusion"], "covariance_intersection");
        // The fused covariance is no larger than any member's (400 m² on x).
        assert!(g["covariance"][0][0].as_f64().unwrap() <= 400.0 + 1e-9);
        assert_eq!(g["t"], 28.0);
    }
    assert_eq!(body["conflicts"], json!([]));
}

#[tokio::test]
async fn asynchronous_nodes_are_aligned_by_prediction() {
    let app = spawn_app().await;
    // Node r2 reports 1 s after r1; a tolerance of 1.5 s merges the pairs of
    // report times, and r1's samples are predicted 1 s forward.
    let mut body = request(
        json!({"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}}),
        vec![node("r1", 0.0, 1), node("r2", 1.0, 7)],
    );
    body["alignment"] = json!({"mode": "predict", "tolerance_s": 1.5});
    let body: Value = app.post_ok(PATH, &body).await;
    assert_eq!(body["instants"][0], 1.0);
    assert_eq!(body["instants"].as_array().unwrap().len(), 8);
    assert_eq!(correlated(&body).len(), 3, "{body}");
    assert!(
        body["warnings"][0]
            .as_str()
            .unwrap()
            .contains("predicted forward")
    );

    // Without merging (nearest, tolerance 0), the two nodes never share an
    // instant: nothing correlates, and the answer says why and what to do.
    let mut body = request(
        json!({"kind": "weighted"}),
        vec![node("r1", 0.0, 1), node("r2", 1.0, 7)],
    );
    body["alignment"] = json!({"mode": "nearest", "tolerance_s": 0.0});
    let out: Value = app.post_ok(PATH, &body).await;
    assert_eq!(out["instants"].as_array().unwrap().len(), 16);
    assert!(correlated(&out).is_empty());
    assert_eq!(out["alignment"]["node_pairs_without_common_instant"], 1);
    assert_eq!(out["alignment"]["tracks_without_partner_instant"], 6);
    let warning = out["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(Value::as_str)
        .find(|w| w.contains("share no instant"))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(warning.contains("r1–r2") && warning.contains("alignment.mode: grid"));

    // The default grid: both nodes report every 4 s (the `track` helper's
    // period), so the grid is 4 s: instants 0, 4, …, 32 (the first grid
    // point at or after r1's first report at 0, to the first at or after
    // r2's last report at 29), each track brought from its latest report at
    // most 1.5 × 4 = 6 s old: they meet at every instant but the first.
    body.as_object_mut().unwrap().remove("alignment");
    let out: Value = app.post_ok(PATH, &body).await;
    assert_eq!(out["alignment"]["mode"], "grid");
    assert_eq!(out["alignment"]["period_s"], 4.0);
    assert_eq!(out["alignment"]["period_estimated"], true);
    assert_eq!(out["instants"].as_array().unwrap().len(), 9);
    assert_eq!(out["alignment"]["nodes"][0]["max_staleness_s"], 6.0);
    assert_eq!(out["alignment"]["node_pairs_without_common_instant"], 0);
    assert_eq!(correlated(&out).len(), 3, "{out}");
}

#[tokio::test]
async fn grpc_aligns_unsynchronised_nodes_on_the_grid_and_reports_it() {
    let app = spawn_app().await;
    // r2 reports 2 s after r1 (half the 4 s scan), nothing set but the
    // motion model: the same answer as REST's default grid.
    let out = app
        .correlation()
        .await
        .correlate_tracks(pb::CorrelateTracksRequest {
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
            nodes: vec![
                to_proto_node(&node("r1", 0.0, 1)),
                to_proto_node(&node("r2", 2.0, 7)),
                pb::Node {
                    id: "r3".into(),
                    tracks: vec![],
                },
            ],
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    let a = out.alignment.expect("an alignment report");
    assert_eq!(a.mode, "grid");
    assert_eq!(a.period_s, Some(4.0));
    assert!(a.period_estimated);
    assert_eq!(a.node_pairs_without_common_instant, 0);
    assert_eq!(a.nodes[2].tracks, 0);
    let correlated = out
        .pairs
        .iter()
        .filter(|p| p.decision == "correlated")
        .count();
    assert_eq!(correlated, 3, "{:?}", out.pairs);
    assert!(out.system_tracks.iter().all(|g| !g.trial));
    assert!(
        out.warnings
            .iter()
            .any(|w| w.contains("hold no tracks (r3)"))
    );
}

#[tokio::test]
async fn a_node_without_tracks_is_accepted_with_a_warning() {
    let app = spawn_app().await;
    let mut body = request(
        json!({"kind": "weighted"}),
        vec![
            node("r1", 0.0, 1),
            node("r2", 0.0, 7),
            json!({"id": "r3", "tracks": []}),
        ],
    );
    body["alignment"] = json!({"mode": "nearest"});
    let out: Value = app.post_ok(PATH, &body).await;
    assert_eq!(correlated(&out).len(), 3, "{out}");
    assert_eq!(out["alignment"]["nodes"][2]["tracks"], 0);
    assert!(
        out["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("hold no tracks (r3)")),
        "{out}"
    );
}

#[tokio::test]
async fn degenerate_but_valid_inputs_get_answers() {
    let app = spawn_app().await;
    // One node: nothing to correlate.
    let body: Value = app
        .post_ok(
            PATH,
            &request(json!({"kind": "weighted"}), vec![node("r1", 0.0, 1)]),
        )
        .await;
    assert_eq!(body["pairs"], json!([]));
    assert_eq!(body["unpaired"][0]["tracks"].as_array().unwrap().len(), 3);
    assert!(!body["warnings"].as_array().unwrap().is_empty());
    // Identical tracks in two nodes: statistic 0, correlated.
    let body: Value = app
        .post_ok(
            PATH,
            &request(
                json!({"kind": "weighted"}),
                vec![node("r1", 0.0, 1), node("r2", 0.0, 1)],
            ),
        )
        .await;
    assert_eq!(correlated(&body).len(), 3);
    assert_eq!(body["pairs"][0]["last_statistic"], 0.0);
    // Far apart: no candidates at all.
    let far = json!({"id": "r2", "tracks": [track("far", (1e6, 1e6), (0.0, 0.0), 0.0, 1.0, 3)]});
    let body: Value = app
        .post_ok(
            PATH,
            &request(
                json!({"kind": "global_assignment"}),
                vec![node("r1", 0.0, 1), far],
            ),
        )
        .await;
    assert_eq!(body["pairs"], json!([]));
    assert_eq!(body["omitted_pairs"], 3);
    assert_eq!(body["system_tracks"], json!([]));
}

#[tokio::test]
async fn brute_force_and_grid_pruning_agree() {
    let app = spawn_app().await;
    let mut grid = request(
        json!({"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}}),
        vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
    );
    let mut brute = grid.clone();
    grid["pruning"] = json!("grid");
    brute["pruning"] = json!("none");
    let mut g: Value = app.post_ok(PATH, &grid).await;
    let mut b: Value = app.post_ok(PATH, &brute).await;
    g["timing"] = json!(null);
    b["timing"] = json!(null);
    assert_eq!(g, b);
}

#[tokio::test]
async fn bad_input_names_the_field() {
    let app = spawn_app().await;
    let good = || {
        request(
            json!({"kind": "weighted"}),
            vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
        )
    };
    type Mutation = Box<dyn Fn(&mut Value)>;
    let cases: Vec<(Mutation, &str)> = vec![
        (
            Box::new(|b| b["nodes"][1]["tracks"][0]["samples"][2]["state"] = json!([1.0, 2.0])),
            "nodes[1].tracks[0].samples[2].state",
        ),
        (
            Box::new(|b| {
                b["nodes"][0]["tracks"][1]["samples"][0]["covariance"][0][0] = json!(-1.0)
            }),
            "nodes[0].tracks[1].samples[0].covariance",
        ),
        (
            Box::new(|b| b["nodes"][0]["tracks"][1]["samples"][0]["covariance"][0][1] = json!(5.0)),
            "nodes[0].tracks[1].samples[0].covariance",
        ),
        (Box::new(|b| b["nodes"] = json!([])), "nodes"),
        (
            Box::new(|b| b["nodes"][1]["tracks"][2]["id"] = json!("r2-0")),
            "nodes[1].tracks[2].id",
        ),
        (
            Box::new(|b| b["nodes"][1]["id"] = json!("r1")),
            "nodes[1].id",
        ),
        (
            Box::new(|b| b["method"]["kind"] = json!("telepathy")),
            "method.kind",
        ),
        (
            Box::new(|b| {
                b["method"] =
                    json!({"kind": "independent_double_threshold", "rule": {"l": 5, "r": 4}})
            }),
            "method.rule.l",
        ),
        (
            Box::new(|b| b["method"]["alpha"] = json!(1.5)),
            "method.alpha",
        ),
        (
            Box::new(|b| b["nodes"][0]["tracks"][0]["samples"][3]["t"] = json!(1.0)),
            "nodes[0].tracks[0].samples[3].t",
        ),
        (
            Box::new(|b| b["state_layout"] = json!(["x", "y", "vx", "q"])),
            "state_layout",
        ),
        (
            Box::new(|b| b["method"]["kind"] = json!("modified")),
            "motion_model",
        ),
        (
            Box::new(|b| b["alignment"] = json!({"mode": "sideways"})),
            "alignment.mode",
        ),
        (
            Box::new(
                |b| b["method"] = json!({"kind": "independent_double_threshold", "schedule": [{"l": 1, "r": 1}, {"l": 2, "r": 3}]}),
            ),
            "method.schedule",
        ),
    ];
    for (i, (mutate, field)) in cases.iter().enumerate() {
        let mut body = good();
        if *field == "motion_model" {
            body.as_object_mut().unwrap().remove("motion_model");
        }
        mutate(&mut body);
        let problem = assert_problem(app.post_json(PATH, &body).await, 422).await;
        let fields = problem_fields(&problem);
        assert!(
            fields.contains(&field.to_string()),
            "case {i}: {fields:?} should name {field}"
        );
    }
}

#[tokio::test]
async fn grpc_bad_input_names_the_field_including_nan_and_bad_matrices() {
    let app = spawn_app().await;
    let mut n = to_proto_node(&node("r1", 0.0, 1));
    n.tracks[0].samples[1].state[2] = f64::NAN;
    n.tracks[1].samples[0].covariance = Some(pb::Matrix {
        rows: 4,
        cols: 4,
        values: vec![1.0; 3],
    });
    let status = app
        .correlation()
        .await
        .correlate_tracks(pb::CorrelateTracksRequest {
            state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
            method: Some(pb::CorrelationMethod {
                kind: Some("weighted".into()),
                ..Default::default()
            }),
            nodes: vec![n, to_proto_node(&node("r2", 0.0, 7))],
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    let fields = grpc_fields(&status);
    assert!(
        fields.contains(&"nodes[0].tracks[1].samples[0].covariance".to_string()),
        "{fields:?}"
    );

    let mut n = to_proto_node(&node("r1", 0.0, 1));
    n.tracks[0].samples[1].state[2] = f64::NAN;
    let status = app
        .correlation()
        .await
        .correlate_tracks(pb::CorrelateTracksRequest {
            state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
            method: Some(pb::CorrelationMethod {
                kind: Some("weighted".into()),
                ..Default::default()
            }),
            nodes: vec![n],
            ..Default::default()
        })
        .await
        .unwrap_err();
    let fields = grpc_fields(&status);
    assert_eq!(fields, vec!["nodes[0].tracks[0].samples[1].state"]);
}

#[tokio::test]
async fn reported_gains_are_used_by_the_modified_statistic() {
    let app = spawn_app().await;
    let mut body = request(
        json!({"kind": "dependent_double_threshold", "rule": {"l": 3, "r": 4}}),
        vec![node("r1", 0.0, 1), node("r2", 0.0, 7)],
    );
    // A position-measuring filter: H picks x and y; K (4×2) as a steady
    // filter would report it.
    body["measurement_matrix"] = json!([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]);
    for node in body["nodes"].as_array_mut().unwrap() {
        for track in node["tracks"].as_array_mut().unwrap() {
            for sample in track["samples"].as_array_mut().unwrap() {
                sample["gain"] = json!([[0.5, 0.0], [0.1, 0.0], [0.0, 0.5], [0.0, 0.1]]);
            }
        }
    }
    let response: Value = app.post_ok(PATH, &body).await;
    assert_eq!(response["gains"], "reported", "{response}");
    assert_eq!(response["statistic"], "modified");

    // A gain without H is an error naming the sample.
    body.as_object_mut().unwrap().remove("measurement_matrix");
    let problem = assert_problem(app.post_json(PATH, &body).await, 422).await;
    assert!(problem_fields(&problem).contains(&"nodes[0].tracks[0].samples[0].gain".to_string()));
}

#[tokio::test]
async fn asynchronous_nodes_are_aligned_by_interpolation_without_extrapolating() {
    let app = spawn_app().await;
    // r1 reports at 0, 4, …, 28 s and r2 at 2, 6, …, 30 s. With tolerance 0
    // every report time is an instant (16 of them); each track is
    // interpolated at the other node's times inside its own span, so the two
    // nodes share the 14 instants 2 … 28 and never extrapolate (r1 is absent
    // at 30 s, r2 at 0 s).
    let mut body = request(
        json!({"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}}),
        vec![node("r1", 0.0, 1), node("r2", 2.0, 7)],
    );
    body["alignment"] = json!({"mode": "interpolate", "tolerance_s": 0.0, "max_gap_s": 5.0});
    let body = app.post_ok(PATH, &body).await;
    assert_eq!(body["instants"].as_array().unwrap().len(), 16);
    assert_eq!(correlated(&body).len(), 3, "{body}");
    assert!(
        body["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("interpolated")),
        "{body}"
    );
    // A gap wider than max_gap_s is not bridged: with 3 s, nothing is
    // interpolated (samples are 4 s apart) and the nodes share no instant.
    let mut narrow = request(
        json!({"kind": "weighted"}),
        vec![node("r1", 0.0, 1), node("r2", 2.0, 7)],
    );
    narrow["alignment"] = json!({"mode": "interpolate", "tolerance_s": 0.0, "max_gap_s": 3.0});
    let narrow = app.post_ok(PATH, &narrow).await;
    assert!(correlated(&narrow).is_empty());
    // A bad gap is named.
    let mut bad = request(json!({"kind": "weighted"}), vec![node("r1", 0.0, 1)]);
    bad["alignment"] = json!({"mode": "interpolate", "max_gap_s": -1.0});
    let problem = assert_problem(app.post_json(PATH, &bad).await, 422).await;
    assert_eq!(problem_fields(&problem), vec!["alignment.max_gap_s"]);
}
