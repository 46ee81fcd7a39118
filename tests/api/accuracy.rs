//! Each radar's accuracy learnt online through the real servers: a radar
//! declared three times more accurate than its plots is learnt, the answer
//! says so in `accuracy` and in a warning naming the option, the session
//! keeps the learnt σ (REST and gRPC state equal the batch call's), a
//! pinned radar keeps its declared σ, bad options are named.

use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{assert_problem, grpc_fields, problem_fields, spawn_app};
use crate::plot_fusion::plot_scene::{
    ORIGIN, P_D, SIGMA_RANGE, Target, plots, radars_json, targets, two_radars,
};
use crate::plot_fusion::{proto_request, session_fed_in_batches};
use radar_fusion::proto::plot_fusion_service_client::PlotFusionServiceClient;

const PATH: &str = "/v1/plot-fusion/track";

/// Eight aircraft for 400 s (the default scene's two long ones and six
/// more on crossing courses, 8 km up), two 2D radars, plots drawn with
/// σ_range 50 m; radar `r1` declared with σ_range 50/3 m.
fn misdeclared() -> Value {
    let radars = two_radars(false);
    let mut spec = radars_json(&radars, 1e-7);
    spec[0]["sigma_range_m"] = json!(SIGMA_RANGE / 3.0);
    let mut fleet: Vec<Target> = targets().into_iter().filter(|g| g.end > 1e6).collect();
    for k in 0..6 {
        let a = std::f64::consts::TAU * f64::from(k) / 6.0;
        fleet.push(Target {
            start: 0.0,
            end: 1e9,
            p0: [
                -25_000.0 * a.sin() + 3_000.0 * f64::from(k),
                -25_000.0 * a.cos(),
                8_000.0,
            ],
            v: [120.0 * a.sin(), 120.0 * a.cos(), 0.0],
        });
    }
    json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": spec,
        "plots": plots(&radars, &fleet, 400.0, 1.0, 5),
        // The 2D radars' slant ranges made horizontal at the aircraft's
        // height.
        "tracker": {"default_height_m": 8000.0},
    })
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[tokio::test]
async fn a_radar_declared_too_accurate_is_learnt_and_said() {
    let app = spawn_app().await;
    let req = misdeclared();
    let out = app.post_ok(PATH, &req).await;
    let acc = out["accuracy"].as_array().unwrap();
    assert_eq!(acc.len(), 2);
    let r = &acc[0]["range_m"];
    assert_eq!(f(&r["declared"]), SIGMA_RANGE / 3.0, "{r}");
    assert_eq!(r["converged"], true, "{r}");
    // The plots' σ is 50 m; the estimate within 20 % of it and applied.
    let est = f(&r["estimated"]);
    assert!((est / SIGMA_RANGE - 1.0).abs() < 0.2, "{r}");
    assert_eq!(f(&r["applied"]), est);
    assert!(f(&r["sigma"]) < 0.1 * est && f(&r["plots"]) >= 30.0, "{r}");
    assert_eq!(acc[0]["pinned"], false);
    // The right radar: declared 50, learnt near it.
    let r2 = &acc[1]["range_m"];
    if r2["converged"] == true {
        assert!(
            (f(&r2["estimated"]) / SIGMA_RANGE - 1.0).abs() < 0.2,
            "{r2}"
        );
    }
    let warnings = out["warnings"].to_string();
    assert!(
        warnings.contains("radars[0].sigma_range_m") && warnings.contains("range σ"),
        "{warnings}"
    );
    assert!(!warnings.contains("radars[1].sigma_range_m"), "{warnings}");

    // gRPC: the same numbers.
    let mut grpc = PlotFusionServiceClient::new(app.channel().await);
    let answer = grpc.track(proto_request(&req)).await.unwrap().into_inner();
    let g = answer.accuracy[0].range_m.as_ref().unwrap();
    assert_eq!(g.estimated, Some(est));
    assert!(g.converged);

    // A session fed the same plots in batches ends with the batch call's
    // accuracy (its stored tracker carries the estimator's data); the gRPC
    // state says the same.
    let (id, state) = session_fed_in_batches(&app, &req, 37).await;
    assert_eq!(state["plot_fusion"]["accuracy"], out["accuracy"]);
    assert_eq!(state["plot_fusion"]["tracks"], out["tracks"]);
    let s =
        radar_fusion::proto::session_service_client::SessionServiceClient::new(app.channel().await)
            .get_session(radar_fusion::proto::GetSessionRequest { session_id: id })
            .await
            .unwrap()
            .into_inner();
    let a = &s.plot_fusion.unwrap().accuracy[0];
    assert_eq!(a.range_m.as_ref().unwrap().estimated, Some(est));

    // Pinned: estimated and reported, the declared σ applied.
    let mut pinned = req.clone();
    pinned["tracker"]["accuracy"] = json!({"pinned": [req["radars"][0]["id"]]});
    let out = app.post_ok(PATH, &pinned).await;
    let r = &out["accuracy"][0];
    assert_eq!(r["pinned"], true);
    assert_eq!(f(&r["range_m"]["applied"]), SIGMA_RANGE / 3.0, "{r}");
    assert!(out["warnings"].to_string().contains("pinned"));

    // Off: nothing learnt.
    let mut off = req.clone();
    off["tracker"]["accuracy"] = json!({"enabled": false});
    let out = app.post_ok(PATH, &off).await;
    assert!(out["accuracy"][0]["range_m"].get("estimated").is_none());
    assert_eq!(f(&out["accuracy"][0]["range_m"]["plots"]), 0.0);
}

/// A radar declared to detect 99 % of the time whose plots come 90 % of
/// the time (the scene's P_D): its detection probability is learnt within
/// 3σ of 0.9 (σ from the binomial, ≈ 0.01 from ≈ 1,000 scans), applied,
/// warned about naming `radars[0].p_detection`; the other radar, declared
/// right, is not warned about; gRPC says the same.
#[tokio::test]
async fn a_radar_declared_to_detect_too_often_is_learnt_and_said() {
    let app = spawn_app().await;
    let mut req = misdeclared();
    req["radars"][0]["sigma_range_m"] = json!(SIGMA_RANGE);
    req["radars"][0]["p_detection"] = json!(0.99);
    let out = app.post_ok(PATH, &req).await;
    let p = &out["accuracy"][0]["p_detection"];
    assert_eq!(f(&p["declared"]), 0.99, "{p}");
    let est = f(&p["estimated"]);
    assert!((est - P_D).abs() < 3.0 * f(&p["sigma"]), "{p}");
    assert!(f(&p["sigma"]) < 0.02 && f(&p["plots"]) > 300.0, "{p}");
    assert_eq!(p["converged"], true, "{p}");
    assert_eq!(f(&p["applied"]), est, "{p}");
    let warnings = out["warnings"].to_string();
    assert!(warnings.contains("radars[0].p_detection"), "{warnings}");
    assert!(!warnings.contains("radars[1].p_detection"), "{warnings}");
    let mut grpc = PlotFusionServiceClient::new(app.channel().await);
    let answer = grpc.track(proto_request(&req)).await.unwrap().into_inner();
    let g = answer.accuracy[0].p_detection.as_ref().unwrap();
    assert_eq!(g.estimated, Some(est));
    assert!(g.converged);
}

#[tokio::test]
async fn bad_accuracy_options_are_named_on_both_transports() {
    let app = spawn_app().await;
    let mut req = misdeclared();
    req["plots"] = json!(req["plots"].as_array().unwrap()[..40].to_vec());
    req["tracker"]["accuracy"] = json!({"time_constant_s": -1.0, "pinned": ["nowhere"]});
    let want = vec![
        "tracker.accuracy.time_constant_s".to_string(),
        "tracker.accuracy.pinned[0]".to_string(),
    ];
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), want);
    let mut grpc = PlotFusionServiceClient::new(app.channel().await);
    let status = grpc.track(proto_request(&req)).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    assert_eq!(grpc_fields(&status), want);
}
