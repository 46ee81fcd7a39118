//! The JPDA update (seed 002) over REST and gRPC: a hand-computed scan, the
//! same answer from both transports, clusters and fallback reported, and bad
//! input named by field on both.

use radar_fusion::proto::{self as pb, jpda_service_client::JpdaServiceClient};
use serde_json::{Value, json};
use tonic::Code;
use tonic_types::StatusExt;

use crate::helpers::{TestApp, assert_problem, problem_fields, spawn_app};

const PATH: &str = "/v1/jpda/update";

async fn client(app: &TestApp) -> JpdaServiceClient<tonic::transport::Channel> {
    JpdaServiceClient::new(app.channel().await)
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// The scalar scan of `algo::jpda::tests::hand_computed_single_target_scan`:
/// x = 0, P = 1, H = 1, R = 1, z = 1, λ = 0.1, P_D = 0.9, γ = 4 (P_G = erf √2):
/// β_1 = a/(a + b) with a = 0.9·e^{−1/4}/√(4π)/0.1 = 1.9772608026047511 and
/// b = 1 − 0.9·0.9544997361036416 = 0.14095023750672253, so β_1 =
/// 0.9334578874164942, x⁺ = β_1/2 = 0.4667289437082471 and
/// P⁺ = β_0 + β_1/2 + (β_1 − β_1²)/4 = 0.5487996212508603.
#[tokio::test]
async fn hand_computed_scan_over_rest() {
    let app = spawn_app().await;
    let body = json!({
        "tracks": [{"id": "t1", "state": [0.0], "covariance": [[1.0]]}],
        "sensors": [{"kind": "linear", "h": [[1.0]], "r": [[1.0]], "detection_probability": 0.9,
                     "gate_threshold": 4.0, "clutter_density": 0.1, "measurements": [{"z": [1.0]}]}]
    });
    let response = app.post_json(PATH, &body).await;
    assert_eq!(response.status(), 200);
    let out: Value = response.json().await.unwrap();
    assert_eq!(out["method"], "exact");
    assert!((f(&out["tracks"][0]["state"][0]) - 0.4667289437082471).abs() < 1e-13);
    assert!((f(&out["tracks"][0]["covariance"][0][0]) - 0.5487996212508603).abs() < 1e-13);
    let a = &out["sensors"][0]["associations"][0];
    assert_eq!(a["track"], "t1");
    assert!((f(&a["measurements"][0]["beta"]) - 0.9334578874164942).abs() < 1e-13);
    assert!((f(&a["miss_probability"]) - (1.0 - 0.9334578874164942)).abs() < 1e-13);
    assert_eq!(out["sensors"][0]["clusters"][0]["method"], "exact");
    assert!(out["timing"]["compute_us"].as_f64().unwrap() >= 0.0);
    assert_eq!(out["warnings"], json!([]));
}

/// Three 2D tracks, two close (one cluster) and one apart; a position sensor
/// and a polar radar; all four methods.
fn scene(method: &str) -> Value {
    let cov = json!([
        [400.0, 0.0, 0.0, 0.0],
        [0.0, 25.0, 0.0, 0.0],
        [0.0, 0.0, 400.0, 0.0],
        [0.0, 0.0, 0.0, 25.0]
    ]);
    json!({
        "state_layout": ["x", "vx", "y", "vy"],
        "method": method,
        "prediction": {"dt_s": 2.0, "sigma_a_mps2": 1.0},
        "tracks": [
            {"id": "a", "state": [1000.0, 10.0, 20000.0, 0.0], "covariance": cov},
            {"id": "b", "state": [1040.0, 10.0, 20010.0, 0.0], "covariance": cov},
            {"id": "c", "state": [9000.0, -5.0, 15000.0, 3.0], "covariance": cov}
        ],
        "sensors": [
            {"id": "pos", "kind": "linear", "h": [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
             "r": [[100.0, 0.0], [0.0, 100.0]], "detection_probability": 0.9, "clutter_density": 1e-6,
             "measurements": [{"z": [1025.0, 20003.0]}, {"z": [1055.0, 20012.0]}, {"z": [8990.0, 15010.0]},
                              {"z": [1038.0, 19990.0]}]},
            {"id": "radar", "kind": "polar", "site_m": [0.0, 0.0, 0.0], "sigma_range_m": 30.0,
             "sigma_azimuth_deg": 0.1, "detection_probability": 0.8,
             "measurements": [{"range_m": 20045.0, "azimuth_deg": 3.0}, {"range_m": 17500.0, "azimuth_deg": 31.0}]},
            {"id": "silent", "kind": "linear", "h": [[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]],
             "r": [[100.0, 0.0], [0.0, 100.0]], "detection_probability": 0.9, "measurements": []}
        ]
    })
}

fn to_proto(v: &Value) -> pb::JpdaUpdateRequest {
    let nums = |v: &Value| -> Vec<f64> { v.as_array().unwrap().iter().map(f).collect() };
    let matrix = |v: &Value| -> pb::Matrix {
        let rows = v.as_array().unwrap();
        pb::Matrix {
            rows: rows.len() as u32,
            cols: rows[0].as_array().unwrap().len() as u32,
            values: rows.iter().flat_map(nums).collect(),
        }
    };
    pb::JpdaUpdateRequest {
        state_layout: v["state_layout"]
            .as_array()
            .map(|a| a.iter().map(|s| s.as_str().unwrap().to_string()).collect())
            .unwrap_or_default(),
        method: v["method"].as_str().map(String::from),
        max_exact_cluster_tracks: v["max_exact_cluster_tracks"].as_u64().map(|x| x as u32),
        prediction: v.get("prediction").map(|p| pb::JpdaPrediction {
            dt_s: p["dt_s"].as_f64(),
            sigma_a_mps2: p["sigma_a_mps2"].as_f64(),
        }),
        tracks: v["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| pb::JpdaTrack {
                id: t["id"].as_str().map(String::from),
                state: nums(&t["state"]),
                covariance: Some(matrix(&t["covariance"])),
            })
            .collect(),
        sensors: v["sensors"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| pb::JpdaSensor {
                id: s["id"].as_str().map(String::from),
                kind: s["kind"].as_str().map(String::from),
                h: s.get("h").map(matrix),
                r: s.get("r").map(matrix),
                site_m: s.get("site_m").map(nums).unwrap_or_default(),
                sigma_range_m: s["sigma_range_m"].as_f64(),
                sigma_azimuth_deg: s["sigma_azimuth_deg"].as_f64(),
                sigma_elevation_deg: s["sigma_elevation_deg"].as_f64(),
                detection_probability: s["detection_probability"].as_f64(),
                gate_probability: s["gate_probability"].as_f64(),
                gate_threshold: s["gate_threshold"].as_f64(),
                clutter_density: s["clutter_density"].as_f64(),
                measurements: s["measurements"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|m| pb::JpdaMeasurement {
                        z: m.get("z").map(nums).unwrap_or_default(),
                        range_m: m["range_m"].as_f64(),
                        azimuth_deg: m["azimuth_deg"].as_f64(),
                        elevation_deg: m["elevation_deg"].as_f64(),
                    })
                    .collect(),
            })
            .collect(),
    }
}

#[tokio::test]
async fn rest_and_grpc_return_identical_results() {
    let app = spawn_app().await;
    let mut grpc = client(&app).await;
    for method in [
        "exact",
        "amsjpda",
        "nearest_neighbour",
        "global_nearest_neighbour",
    ] {
        let req = scene(method);
        let response = app.post_json(PATH, &req).await;
        assert_eq!(response.status(), 200, "{method}");
        let rest: Value = response.json().await.unwrap();
        let g = grpc.update(to_proto(&req)).await.unwrap().into_inner();
        assert_eq!(rest["method"], g.method.as_str());
        assert_eq!(rest["warnings"].as_array().unwrap().len(), g.warnings.len());
        for (r, t) in rest["tracks"].as_array().unwrap().iter().zip(&g.tracks) {
            assert_eq!(r["id"], t.id.as_str());
            let state: Vec<f64> = r["state"].as_array().unwrap().iter().map(f).collect();
            assert_eq!(state, t.state, "{method}");
            let cov: Vec<f64> = r["covariance"]
                .as_array()
                .unwrap()
                .iter()
                .flat_map(|row| row.as_array().unwrap().iter().map(f).collect::<Vec<_>>())
                .collect();
            assert_eq!(cov, t.covariance.as_ref().unwrap().values);
        }
        for (rs, gs) in rest["sensors"].as_array().unwrap().iter().zip(&g.sensors) {
            assert_eq!(rs["id"], gs.id.as_str());
            let rc = rs["clusters"].as_array().unwrap();
            assert_eq!(rc.len(), gs.clusters.len());
            for (r, c) in rc.iter().zip(&gs.clusters) {
                assert_eq!(r["method"], c.method.as_str());
                assert_eq!(r["hypotheses"], c.hypotheses);
                assert_eq!(r["tracks"].as_array().unwrap().len(), c.tracks.len());
            }
            for (r, a) in rs["associations"]
                .as_array()
                .unwrap()
                .iter()
                .zip(&gs.associations)
            {
                assert_eq!(f(&r["miss_probability"]), a.miss_probability);
                let betas: Vec<f64> = r["measurements"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|b| f(&b["beta"]))
                    .collect();
                assert_eq!(
                    betas,
                    a.measurements.iter().map(|b| b.beta).collect::<Vec<_>>()
                );
            }
        }
    }
}

#[tokio::test]
async fn clusters_betas_and_the_silent_sensor() {
    let app = spawn_app().await;
    let out: Value = app
        .post_json(PATH, &scene("exact"))
        .await
        .json()
        .await
        .unwrap();
    let pos = &out["sensors"][0];
    // a and b share measurements 0, 1 and 3; c is alone with measurement 2.
    let clusters = pos["clusters"].as_array().unwrap();
    assert_eq!(clusters.len(), 2);
    assert_eq!(clusters[0]["tracks"], json!(["a", "b"]));
    assert_eq!(clusters[1]["tracks"], json!(["c"]));
    assert_eq!(clusters[1]["measurements"], json!([2]));
    for a in pos["associations"].as_array().unwrap() {
        let sum = f(&a["miss_probability"])
            + a["measurements"]
                .as_array()
                .unwrap()
                .iter()
                .map(|b| f(&b["beta"]))
                .sum::<f64>();
        assert!((sum - 1.0).abs() < 1e-12);
    }
    // The sensor without measurements: every track misses.
    for a in out["sensors"][2]["associations"].as_array().unwrap() {
        assert_eq!(f(&a["miss_probability"]), 1.0);
    }
    // A cluster guard of one track: the a–b cluster falls back, with a warning.
    let mut req = scene("exact");
    req["max_exact_cluster_tracks"] = json!(1);
    let out: Value = app.post_json(PATH, &req).await.json().await.unwrap();
    let c = &out["sensors"][0]["clusters"][0];
    assert_eq!(c["method"], "amsjpda");
    assert_eq!(c["fallback"], "too_many_tracks");
    assert!(!out["warnings"].as_array().unwrap().is_empty());
}

#[tokio::test]
async fn bad_input_names_the_field() {
    let app = spawn_app().await;
    let mut req = scene("exact");
    req["method"] = json!("jpda++");
    req["tracks"][1]["covariance"][0][0] = json!(-400.0);
    req["tracks"][2]["state"] = json!([1.0, 2.0, 3.0]);
    req["sensors"][0]["detection_probability"] = json!(1.5);
    req["sensors"][0]["clutter_density"] = json!(-1.0);
    req["sensors"][0]["measurements"][1]["z"] = json!([1.0, 2.0, 3.0]);
    req["sensors"][1]["gate_probability"] = json!(0.0);
    req["sensors"][1]["measurements"][0]["range_m"] = json!(-5.0);
    req["sensors"][2]["h"] = json!([[1.0, 0.0], [0.0, 1.0]]);
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    let fields = problem_fields(&body);
    for want in [
        "method",
        "tracks[1].covariance",
        "tracks[2].state",
        "sensors[0].detection_probability",
        "sensors[0].clutter_density",
        "sensors[0].measurements[1].z",
        "sensors[1].gate_probability",
        "sensors[1].measurements[0].range_m",
        "sensors[2].h",
    ] {
        assert!(
            fields.contains(&want.to_string()),
            "{want} not in {fields:?}"
        );
    }
    // Unknown and mistyped fields are named by the extractor.
    let mut req = scene("exact");
    req["sensors"][0]["lambda"] = json!(1.0);
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert!(problem_fields(&body)[0].starts_with("sensors[0]"));
}

#[tokio::test]
async fn grpc_bad_input_names_the_field_including_nan() {
    let app = spawn_app().await;
    let mut grpc = client(&app).await;
    let mut req = to_proto(&scene("exact"));
    req.sensors[0].measurements[2].z[1] = f64::NAN;
    req.sensors[1].measurements[1].azimuth_deg = Some(f64::NAN);
    req.sensors[0].detection_probability = None;
    let status = grpc.update(req).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    let fields: Vec<String> = status
        .get_details_bad_request()
        .unwrap()
        .field_violations
        .into_iter()
        .map(|v| v.field)
        .collect();
    for want in [
        "sensors[0].measurements[2].z",
        "sensors[1].measurements[1].azimuth_deg",
        "sensors[0].detection_probability",
    ] {
        assert!(
            fields.contains(&want.to_string()),
            "{want} not in {fields:?}"
        );
    }
}

#[tokio::test]
async fn grpc_matrix_that_does_not_fill_rows_times_cols_is_named() {
    let app = spawn_app().await;
    let mut req = to_proto(&scene("exact"));
    req.tracks[0].covariance = Some(pb::Matrix {
        rows: 4,
        cols: 4,
        values: vec![1.0; 3],
    });
    let status = client(&app).await.update(req).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    let fields: Vec<String> = status
        .get_details_bad_request()
        .unwrap()
        .field_violations
        .into_iter()
        .map(|v| v.field)
        .collect();
    assert_eq!(fields, vec!["tracks[0].covariance"]);
}

/// Quirks found by an independent check: a JSON array in the fields'
/// declaration order was accepted as a request, and a negative `dt_s`
/// predicted backwards.
#[tokio::test]
async fn an_array_body_and_a_backward_prediction_are_refused() {
    let app = spawn_app().await;
    let req = scene("exact");
    let array = Value::Array(req.as_object().unwrap().values().cloned().collect());
    let body = assert_problem(app.post_json(PATH, &array).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["body"]);
    let truncated = app.post_raw(PATH, "[1,2").await;
    assert_problem(truncated, 400).await;
    let mut backwards = scene("exact");
    backwards["prediction"] = json!({"dt_s": -4.0, "sigma_a_mps2": 1.0});
    let body = assert_problem(app.post_json(PATH, &backwards).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["prediction.dt_s"]);
}

/// A scan without sensors is answered, and says that nothing updated the
/// tracks.
#[tokio::test]
async fn no_sensors_is_said() {
    let app = spawn_app().await;
    let mut req = scene("exact");
    req["sensors"] = json!([]);
    let out: Value = app.post_ok(PATH, &req).await;
    assert!(
        out["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().starts_with("no sensors")),
        "{out}"
    );
}
