//! The plot-fusion tracker (seed 001) through the real servers: a realistic
//! scene with the defaults (WGS84 sites, unsynchronised radars, P_D < 1,
//! clutter, a target that starts and ends mid-way) in serial and parallel
//! mode, REST and gRPC giving the same tracks, the history, and bad input
//! named by field on both transports.

use radar_fusion::proto::{self as pb, plot_fusion_service_client::PlotFusionServiceClient};
use serde_json::{Value, json};
use tonic::Code;

#[path = "../common/plot_scene.rs"]
pub(crate) mod plot_scene;

use crate::helpers::{
    TestApp, assert_problem, grpc_fields, problem_fields, spawn_app, spawn_app_with,
};
use plot_scene::{far_radars, origin_frame, plots, radars_json, request, targets};

const PATH: &str = "/v1/plot-fusion/track";

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// Aircraft at 8 km: 2D slant ranges are made horizontal with it.
fn with_height(mut req: Value) -> Value {
    req["tracker"] = json!({"default_height_m": 8000.0});
    req
}

/// Every confirmed track at the end lies within `tol` m of a live target,
/// and every live target has one; lat/lon are the frame's conversion of
/// the state.
fn check_tracks(out: &Value, tol: f64) {
    let frame = origin_frame();
    let end = 150.0;
    let confirmed: Vec<&Value> = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .collect();
    let live: Vec<_> = targets()
        .into_iter()
        .filter(|g| g.start <= end && end <= g.end)
        .collect();
    assert_eq!(confirmed.len(), live.len(), "{}", out["tracks"]);
    for target in &live {
        let near = confirmed.iter().any(|t| {
            let p = target.at(f(&t["t"]));
            let s = &t["state"];
            (f(&s[0]) - p[0]).hypot(f(&s[2]) - p[1]) < tol
        });
        assert!(near, "no track near a target: {}", out["tracks"]);
    }
    // A 2D track's lat/lon is the point above its (e, n) at the assumed
    // height: back in the fusion frame at that height, it is (e, n) again.
    for t in &confirmed {
        let s = &t["state"];
        let height = if s.as_array().unwrap().len() == 6 {
            t["height_m"].as_f64().unwrap()
        } else {
            8000.0
        };
        let enu = frame
            .geodetic_to_enu(
                f(&t["lat_deg"]).to_radians(),
                f(&t["lon_deg"]).to_radians(),
                height,
            )
            .unwrap();
        assert!((enu[0] - f(&s[0])).abs() < 1e-3, "{enu:?} {s}");
        assert!((enu[1] - f(&s[2])).abs() < 1e-3, "{enu:?} {s}");
    }
}

#[tokio::test]
async fn serial_fusion_of_two_unsynchronised_2d_radars_with_the_defaults() {
    let app = spawn_app().await;
    let out = app.post_ok(PATH, &with_height(request(false, 7))).await;
    assert_eq!(out["mode"], "serial");
    assert_eq!(out["state_layout"], json!(["x", "vx", "y", "vy"]));
    check_tracks(&out, 400.0);
    // The target that ended at 100 s was deleted.
    assert!(!out["deleted"].as_array().unwrap().is_empty());
    let c = &out["counters"];
    assert_eq!(c["late"], 0);
    assert!(c["confirmed"].as_u64().unwrap() >= 3);
    assert_eq!(c["fused_plots"], 0);
    assert_eq!(out["warnings"], json!([]));
    assert!(out.get("history").is_none());
}

#[tokio::test]
async fn radars_200_km_away_2d_and_3d_track_aircraft_at_altitude() {
    // A 2D radar 190 km north-west and a 3D radar 160 km south-east of the
    // centre: meridian convergence, horizon tilt (1.7° and 1.4°) and 2D
    // slant ranges at 8 km all matter at this distance.
    let app = spawn_app().await;
    let radars = far_radars();
    let req = json!({
        "origin": {"lat_deg": plot_scene::ORIGIN.0, "lon_deg": plot_scene::ORIGIN.1},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots(&radars, &targets(), 150.0, 1.0, 13),
        "tracker": {"default_height_m": 8000.0, "dimensions": 2},
    });
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["tracker.dimensions"]);
    let mut req = req;
    req["tracker"] = json!({"default_height_m": 8000.0});
    let out = app.post_ok(PATH, &req).await;
    assert_eq!(
        out["state_layout"],
        json!(["x", "vx", "y", "vy", "z", "vz"])
    );
    check_tracks(&out, 600.0);
    for t in out["tracks"].as_array().unwrap() {
        if t["status"] == "confirmed" {
            // The 3D radar measures the height: 8 km within a few hundred m.
            let h = f(&t["height_m"]);
            assert!((h - 8000.0).abs() < 500.0, "height {h}");
        }
    }
}

#[tokio::test]
async fn parallel_fusion_when_asked_and_serial_by_default_with_doppler() {
    let app = spawn_app().await;
    // `auto` is serial also when every radar gives Doppler (the more
    // accurate mode with the range rate in the update).
    let out = app.post_ok(PATH, &with_height(request(true, 11))).await;
    assert_eq!(out["mode"], "serial");
    check_tracks(&out, 400.0);
    assert_eq!(out["counters"]["fused_plots"], 0);
    // The patent's parallel mode on the same plots also tracks every target.
    let mut req = with_height(request(true, 11));
    req["tracker"]["mode"] = json!("parallel");
    let out = app.post_ok(PATH, &req).await;
    assert_eq!(out["mode"], "parallel");
    check_tracks(&out, 400.0);
    assert!(out["counters"]["fused_plots"].as_u64().unwrap() > 0);
}

#[tokio::test]
async fn plots_in_any_order_give_the_same_tracks_and_history_is_returned_when_asked() {
    let app = spawn_app().await;
    let mut req = with_height(request(false, 3));
    req["history"] = json!(true);
    let sorted = app.post_ok(PATH, &req).await;
    let plots = req["plots"].as_array_mut().unwrap();
    plots.reverse();
    // Reversal also reverses plots of equal time; restore their order by a
    // stable sort on time to isolate "any order" from "ties".
    let mut shuffled: Vec<Value> = plots.clone();
    shuffled.sort_by(|a, b| f(&a["t"]).total_cmp(&f(&b["t"])));
    // Interleave: odd positions first, then even ones (times unsorted).
    let (odd, even): (Vec<_>, Vec<_>) = shuffled
        .into_iter()
        .enumerate()
        .partition(|(i, _)| i % 2 == 1);
    *plots = odd.into_iter().chain(even).map(|(_, p)| p).collect();
    let unsorted = app.post_ok(PATH, &req).await;
    assert_eq!(sorted["tracks"], unsorted["tracks"]);
    let history = sorted["history"].as_array().unwrap();
    assert_eq!(
        history.len() as u64,
        sorted["counters"]["frames"].as_u64().unwrap()
    );
    let mut last = f64::NEG_INFINITY;
    for entry in history {
        assert!(f(&entry["t"]) >= last);
        last = f(&entry["t"]);
        for t in entry["tracks"].as_array().unwrap() {
            assert_eq!(t["status"], "confirmed");
        }
    }
    assert!(
        !history.last().unwrap()["tracks"]
            .as_array()
            .unwrap()
            .is_empty()
    );
}

async fn client(app: &TestApp) -> PlotFusionServiceClient<tonic::transport::Channel> {
    PlotFusionServiceClient::new(app.channel().await)
}

/// The JSON request as its protobuf twin.
pub(crate) fn proto_request(req: &Value) -> pb::PlotFusionRequest {
    let o = |v: &Value| v.as_f64();
    pb::PlotFusionRequest {
        nmea: req.get("nmea").map(|n| pb::NmeaData {
            lines: n["lines"]
                .as_array()
                .unwrap()
                .iter()
                .map(|l| l.as_str().unwrap().to_string())
                .collect(),
            time_offset_s: n["time_offset_s"].as_f64(),
        }),
        cat062: req.get("cat062").map(|c| {
            let u = |k: &str| c[k].as_u64().map(|x| x as u32);
            pb::Cat062Options {
                sac: u("sac").unwrap(),
                sic: u("sic").unwrap(),
                service_id: u("service_id"),
                day_start_t: c["day_start_t"].as_f64(),
                max_block_bytes: u("max_block_bytes"),
            }
        }),
        origin: Some(pb::GeoPoint {
            lat_deg: o(&req["origin"]["lat_deg"]),
            lon_deg: o(&req["origin"]["lon_deg"]),
            height_m: o(&req["origin"]["height_m"]),
        }),
        radars: req["radars"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| pb::PlotRadar {
                id: r["id"].as_str().unwrap().into(),
                kind: r["kind"].as_str().unwrap().into(),
                site: Some(pb::PlotRadarSite {
                    lat_deg: o(&r["site"]["lat_deg"]),
                    lon_deg: o(&r["site"]["lon_deg"]),
                    height_m: o(&r["site"]["height_m"]),
                    position_m: r["site"]["position_m"]
                        .as_array()
                        .map(|a| a.iter().map(f).collect())
                        .unwrap_or_default(),
                }),
                sigma_range_m: o(&r["sigma_range_m"]),
                sigma_azimuth_deg: o(&r["sigma_azimuth_deg"]),
                sigma_elevation_deg: o(&r["sigma_elevation_deg"]),
                sigma_radial_velocity_mps: o(&r["sigma_radial_velocity_mps"]),
                scan_period_s: o(&r["scan_period_s"]),
                p_detection: o(&r["p_detection"]),
                clutter_density: o(&r["clutter_density"]),
                sac: None,
                sic: None,
                bias: None,
            })
            .collect(),
        plots: req["plots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| pb::RadarPlot {
                radar_id: p["radar_id"].as_str().unwrap().into(),
                t: o(&p["t"]),
                range_m: o(&p["range_m"]),
                azimuth_deg: o(&p["azimuth_deg"]),
                elevation_deg: o(&p["elevation_deg"]),
                radial_velocity_mps: o(&p["radial_velocity_mps"]),
                mode_3a: p["mode_3a"].as_str().map(str::to_string),
                mode_3a_validated: p["mode_3a_validated"].as_bool(),
                mode_3a_garbled: p["mode_3a_garbled"].as_bool(),
                flight_level: o(&p["flight_level"]),
                flight_level_validated: p["flight_level_validated"].as_bool(),
                flight_level_garbled: p["flight_level_garbled"].as_bool(),
                mode_s_address: p["mode_s_address"].as_str().map(str::to_string),
                callsign: p["callsign"].as_str().map(str::to_string),
                detection: p["detection"].as_str().map(str::to_string),
                spi: p["spi"].as_bool(),
            })
            .collect(),
        tracker: Some(pb::TrackerOptions {
            default_height_m: o(&req["tracker"]["default_height_m"]),
            accuracy: req["tracker"].get("accuracy").map(|a| pb::AccuracyOptions {
                enabled: a["enabled"].as_bool(),
                time_constant_s: o(&a["time_constant_s"]),
                pinned: a["pinned"]
                    .as_array()
                    .map(|v| v.iter().map(|s| s.as_str().unwrap().to_string()).collect())
                    .unwrap_or_default(),
            }),
            ..Default::default()
        }),
        history: false,
        asterix: None,
        cooperative: req["cooperative"]
            .as_array()
            .map(|a| a.iter().map(proto_report).collect())
            .unwrap_or_default(),
    }
}

/// A JSON cooperative report as its protobuf message.
pub(crate) fn proto_report(r: &Value) -> pb::CooperativeReport {
    let o = |k: &str| r[k].as_f64();
    let s = |k: &str| r[k].as_str().map(str::to_string);
    let u = |k: &str| r[k].as_u64().map(|v| v as u32);
    pb::CooperativeReport {
        source: r["source"].as_str().unwrap_or_default().into(),
        t: r["t"].as_f64().unwrap_or(f64::NAN),
        lat_deg: r["lat_deg"].as_f64().unwrap_or(f64::NAN),
        lon_deg: r["lon_deg"].as_f64().unwrap_or(f64::NAN),
        geometric_height_m: o("geometric_height_m"),
        velocity_east_mps: o("velocity_east_mps"),
        velocity_north_mps: o("velocity_north_mps"),
        vertical_rate_mps: o("vertical_rate_mps"),
        sog_kn: o("sog_kn"),
        cog_deg: o("cog_deg"),
        nacp: u("nacp"),
        nacv: u("nacv"),
        position_accurate: r["position_accurate"].as_bool(),
        sigma_m: o("sigma_m"),
        sigma_height_m: o("sigma_height_m"),
        sigma_velocity_mps: o("sigma_velocity_mps"),
        mode_s_address: s("mode_s_address"),
        callsign: s("callsign"),
        mode_3a: s("mode_3a"),
        flight_level: o("flight_level"),
        mmsi: r["mmsi"].as_u64(),
    }
}

#[tokio::test]
async fn grpc_gives_the_tracks_of_rest() {
    let app = spawn_app().await;
    let req = with_height(request(true, 5));
    let rest = app.post_ok(PATH, &req).await;
    let grpc = client(&app)
        .await
        .track(proto_request(&req))
        .await
        .unwrap()
        .into_inner();
    assert_eq!(grpc.mode, "serial");
    let tracks = rest["tracks"].as_array().unwrap();
    assert_eq!(grpc.tracks.len(), tracks.len());
    for (g, r) in grpc.tracks.iter().zip(tracks) {
        assert_eq!(g.id, r["id"].as_u64().unwrap());
        assert_eq!(g.status, r["status"].as_str().unwrap());
        let state: Vec<f64> = r["state"].as_array().unwrap().iter().map(f).collect();
        assert_eq!(g.state, state);
        let cov = g.covariance.as_ref().unwrap();
        assert_eq!((cov.rows, cov.cols), (4, 4));
        assert_eq!(g.lat_deg, r["lat_deg"].as_f64());
        assert_eq!(g.radars.len(), r["radars"].as_array().unwrap().len());
    }
    let c = grpc.counters.unwrap();
    assert_eq!(c.plots, rest["counters"]["plots"].as_u64().unwrap());
}

#[tokio::test]
async fn local_sites_without_origin_are_the_patents_flat_model_and_say_so() {
    // The patent's Fig. 5 geometry: radars at [−200, 0] and [200, 0] m.
    // One target at [−25, 35] km moving [30, −50] m/s, seen without noise
    // every 10 s (radar 1) and 8 s (radar 2) for 100 s.
    let app = spawn_app().await;
    let sites: [(&str, f64, f64); 2] = [("r1", -200.0, 10.0), ("r2", 200.0, 8.0)];
    let mut plots = Vec::new();
    for (id, x, period) in sites {
        let mut t = 0.0;
        while t <= 100.0 {
            let (e, n) = (-25_000.0 + 30.0 * t - x, 35_000.0 - 50.0 * t);
            plots.push(json!({"radar_id": id, "t": t, "range_m": e.hypot(n),
                              "azimuth_deg": e.atan2(n).to_degrees()}));
            t += period;
        }
    }
    let radars: Vec<Value> = sites
        .iter()
        .map(|(id, x, period)| {
            json!({"id": id, "kind": "2d", "site": {"position_m": [x, 0.0]},
                   "sigma_range_m": 100.0, "sigma_azimuth_deg": 0.1, "scan_period_s": period})
        })
        .collect();
    // One constant-velocity model: on noise-free plots it converges onto
    // the line, so the tolerance below tests the flat geometry alone (the
    // default IMM's turn models pull such a track by about a metre).
    let out = app
        .post_ok(
            PATH,
            &json!({"radars": radars, "plots": plots, "tracker": {"motion": "cv"}}),
        )
        .await;
    let tracks = out["tracks"].as_array().unwrap();
    assert_eq!(tracks.len(), 1, "{tracks:?}");
    let t = &tracks[0];
    assert_eq!(t["status"], "confirmed");
    assert!(t.get("lat_deg").is_none());
    assert!(t.get("modes").is_none(), "one model has no modes");
    // Noise-free plots: the track is on the truth to well under 1 m·s.
    let time = f(&t["t"]);
    let s = &t["state"];
    assert!((f(&s[0]) - (-25_000.0 + 30.0 * time)).abs() < 1.0, "{s}");
    assert!((f(&s[2]) - (35_000.0 - 50.0 * time)).abs() < 1.0, "{s}");
    assert!((f(&s[1]) - 30.0).abs() < 0.1 && (f(&s[3]) + 50.0).abs() < 0.1);
    assert_eq!(t["radars"].as_array().unwrap().len(), 1);
    let warnings = out["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("origin")),
        "{warnings:?}"
    );
}

fn small_request() -> Value {
    json!({
        "origin": {"lat_deg": 52.0, "lon_deg": 4.0},
        "radars": [
            {"id": "a", "kind": "2d", "site": {"position_m": [0.0, 0.0]},
             "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.1, "scan_period_s": 4.0},
            {"id": "b", "kind": "3d", "site": {"lat_deg": 52.1, "lon_deg": 4.1},
             "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.1, "sigma_elevation_deg": 0.1,
             "scan_period_s": 4.0}
        ],
        "plots": [
            {"radar_id": "a", "t": 0.0, "range_m": 1000.0, "azimuth_deg": 10.0},
            {"radar_id": "nope", "t": 0.0, "range_m": 1000.0, "azimuth_deg": 10.0},
            {"radar_id": "b", "t": 0.0, "range_m": 1000.0, "azimuth_deg": 10.0},
            {"radar_id": "a", "t": 0.0, "range_m": 1000.0, "azimuth_deg": 10.0,
             "radial_velocity_mps": 3.0},
            {"radar_id": "a", "t": 0.0, "range_m": -5.0, "azimuth_deg": 10.0},
            {"radar_id": "a", "t": 0.0, "range_m": 1000.0, "azimuth_deg": 10.0,
             "elevation_deg": 1.0}
        ]
    })
}

#[tokio::test]
async fn bad_plots_are_named_by_field_on_both_transports() {
    let app = spawn_app().await;
    let req = small_request();
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    let want = vec![
        "plots[1].radar_id",
        "plots[2].elevation_deg",
        "plots[3].radial_velocity_mps",
        "plots[4].range_m",
        "plots[5].elevation_deg",
    ];
    assert_eq!(problem_fields(&body), want);
    // gRPC: the same, plus a non-finite time (JSON cannot carry one).
    let mut p = proto_request(&req);
    p.tracker = None;
    p.plots[0].t = Some(f64::NAN);
    let status = client(&app).await.track(p).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    let mut want_grpc = vec!["plots[0].t"];
    want_grpc.extend(want);
    assert_eq!(grpc_fields(&status), want_grpc);
}

#[tokio::test]
async fn bad_radars_and_options_are_named_by_field() {
    let app = spawn_app().await;
    let mut req = small_request();
    req["plots"] = json!([]);
    req["radars"][0]["sigma_range_m"] = json!(0.0);
    req["radars"][1]["kind"] = json!("4d");
    req["radars"][1]["id"] = json!("a");
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    let fields = problem_fields(&body);
    for want in ["radars[0].sigma_range_m", "radars[1].id", "radars[1].kind"] {
        assert!(fields.iter().any(|f| f == want), "{fields:?}");
    }

    let mut req = small_request();
    req["plots"] = json!([]);
    req["tracker"] = json!({"mode": "parallel", "initiation": {"m": 5, "n": 4},
                            "deletion": {}});
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["tracker.deletion"]);
    req["tracker"]["deletion"] = json!({"max_consecutive_misses": 4});
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["tracker.mode"]);
    req["tracker"]["mode"] = json!("serial");
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["tracker.initiation.m"]);

    // A radar site given both ways, or neither.
    let mut req = small_request();
    req["plots"] = json!([]);
    req["radars"][0]["site"] = json!({"lat_deg": 52.0, "lon_deg": 4.0, "position_m": [0, 0]});
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["radars[0].site"]);
}

#[tokio::test]
async fn the_default_imm_reports_its_modes_on_both_transports() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    let rest = app.post_ok(PATH, &req).await;
    let confirmed: Vec<&Value> = rest["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .collect();
    assert!(!confirmed.is_empty());
    for t in &confirmed {
        let modes = t["modes"].as_array().unwrap();
        let names: Vec<&str> = modes.iter().map(|m| m["model"].as_str().unwrap()).collect();
        assert_eq!(names, ["cv", "ct_left", "ct_right", "cv_2"]);
        let sum: f64 = modes.iter().map(|m| f(&m["probability"])).sum();
        assert!((sum - 1.0).abs() < 1e-9, "{modes:?}");
        // The turn rate is the mixture's: (μ_left − μ_right) · 3 °/s.
        let want = 3.0 * (f(&modes[1]["probability"]) - f(&modes[2]["probability"]));
        assert!((f(&t["turn_rate_dps"]) - want).abs() < 1e-9);
    }
    let tentative = rest["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "tentative");
    for t in tentative {
        assert!(t.get("modes").is_none() && t.get("turn_rate_dps").is_none());
    }
    let grpc = client(&app)
        .await
        .track(proto_request(&req))
        .await
        .unwrap()
        .into_inner();
    for (g, r) in grpc.tracks.iter().zip(rest["tracks"].as_array().unwrap()) {
        let want: Vec<(String, f64)> = r["modes"]
            .as_array()
            .map(|m| {
                m.iter()
                    .map(|m| {
                        (
                            m["model"].as_str().unwrap().to_string(),
                            f(&m["probability"]),
                        )
                    })
                    .collect()
            })
            .unwrap_or_default();
        let got: Vec<(String, f64)> = g
            .modes
            .iter()
            .map(|m| (m.model.clone(), m.probability))
            .collect();
        assert_eq!(got, want);
        assert_eq!(g.turn_rate_dps, r["turn_rate_dps"].as_f64());
    }
}

#[tokio::test]
async fn bad_motion_options_are_named_by_field_on_both_transports() {
    let app = spawn_app().await;
    let mut req = small_request();
    req["plots"] = json!([]);
    let cases = [
        (json!({"motion": "kalman"}), "tracker.motion"),
        (
            json!({"motion": "cv", "imm_models": [{"model": "cv"}, {"model": "cv"}]}),
            "tracker.imm_models",
        ),
        (
            json!({"imm_models": [{"model": "cv"}]}),
            "tracker.imm_models",
        ),
        (
            json!({"imm_models": [{"model": "ca"}, {"model": "cv"}]}),
            "tracker.imm_models[0].model",
        ),
        (
            json!({"imm_models": [{"model": "cv"}, {"model": "ct"}]}),
            "tracker.imm_models[1].turn_rate_dps",
        ),
        (
            json!({"imm_models": [{"model": "cv"}, {"model": "ct", "turn_rate_dps": 0.0}]}),
            "tracker.imm_models[1].turn_rate_dps",
        ),
        (
            json!({"imm_models": [{"model": "cv", "mean_sojourn_s": 0.0}, {"model": "cv"}]}),
            "tracker.imm_models[0].mean_sojourn_s",
        ),
        (
            json!({"imm_models": [{"model": "cv", "initial_probability": 1.5},
                                  {"model": "cv", "initial_probability": 0.5}]}),
            "tracker.imm_models[0].initial_probability",
        ),
        (
            json!({"imm_models": [{"model": "cv", "initial_probability": 0.3},
                                  {"model": "cv", "initial_probability": 0.3}]}),
            "tracker.imm_models",
        ),
        (
            json!({"imm_models": [{"model": "cv", "sigma_a_mps2": -1.0}, {"model": "cv"}]}),
            "tracker.imm_models[0].sigma_a_mps2",
        ),
    ];
    for (tracker, field) in cases {
        req["tracker"] = tracker.clone();
        let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
        assert_eq!(problem_fields(&body), vec![field], "{tracker}");
    }
    // gRPC: INVALID_ARGUMENT naming the same field.
    let mut p = proto_request(&small_request());
    p.plots.clear();
    let tracker = p.tracker.get_or_insert_with(Default::default);
    tracker.imm_models = vec![
        pb::ImmModel {
            model: "cv".into(),
            ..Default::default()
        },
        pb::ImmModel {
            model: "ct".into(),
            turn_rate_dps: Some(90.0),
            ..Default::default()
        },
    ];
    let status = client(&app).await.track(p).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    assert_eq!(
        grpc_fields(&status),
        ["tracker.imm_models[1].turn_rate_dps"]
    );
    // A session created with a bad model set does not exist.
    let mut create = session_create(&with_height(request(false, 7)));
    create["tracker"] = json!({"imm_models": [{"model": "ct", "turn_rate_dps": 3.0}]});
    let res = app.post_json("/v1/sessions", &create).await;
    let body = assert_problem(res, 422).await;
    assert_eq!(problem_fields(&body), vec!["tracker.imm_models"]);
}

// ------------------------------------------------------------ sessions

/// The create request of a plot_fusion session for a batch request.
pub(crate) fn session_create(req: &Value) -> Value {
    json!({
        "kind": "plot_fusion",
        "origin": req["origin"],
        "radars": req["radars"],
        "tracker": req["tracker"],
    })
}

pub(crate) async fn create_session(app: &TestApp, body: &Value) -> Value {
    let response = app.post_json("/v1/sessions", body).await;
    assert_eq!(response.status(), 201);
    response.json().await.unwrap()
}

/// A plot_fusion session of `req`'s network fed `req`'s plots in batches
/// of `size` (in order, no flush): its id and its state at the end.
pub(crate) async fn session_fed_in_batches(
    app: &TestApp,
    req: &Value,
    size: usize,
) -> (String, Value) {
    let created = create_session(app, &session_create(req)).await;
    let id = created["id"].as_str().unwrap().to_string();
    for (i, plots) in batches(req, size).into_iter().enumerate() {
        let body = json!({"sequence": i + 1, "plots": plots});
        app.post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
    }
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    (id, state)
}

/// The plots in time order, cut into batches of `size`.
fn batches(req: &Value, size: usize) -> Vec<Vec<Value>> {
    req["plots"]
        .as_array()
        .unwrap()
        .chunks(size)
        .map(<[Value]>::to_vec)
        .collect()
}

#[tokio::test]
async fn a_session_fed_in_batches_ends_with_the_batch_endpoints_tracks() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    let whole = app.post_ok(PATH, &req).await;
    let created = create_session(&app, &session_create(&req)).await;
    assert_eq!(created["kind"], "plot_fusion");
    assert_eq!(created["plot_fusion"]["mode"], "serial");
    assert!(created.get("method").is_none());
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    let chunks = batches(&req, 13);
    let n = chunks.len();
    let mut initiated = 0;
    for (i, plots) in chunks.into_iter().enumerate() {
        // No flush: the tracks always hold every plot received.
        let body = json!({"sequence": i + 1, "plots": plots});
        let u = app.post_ok(&path, &body).await;
        assert_eq!(u["duplicate"], false);
        assert_eq!(u["warnings"], json!([]));
        assert!(u.get("instants").is_none());
        let pf = &u["plot_fusion"];
        for t in pf["tracks"].as_array().unwrap() {
            if t["change"] == "initiated" {
                initiated += 1;
            }
        }
        assert_eq!(pf["late_within_lag"], 0);
        assert_eq!(pf["corrected_from_t"], Value::Null);
    }
    assert!(initiated >= 3);
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(state["plot_fusion"]["tracks"], whole["tracks"]);
    assert_eq!(state["plot_fusion"]["counters"], whole["counters"]);
    assert_eq!(state["batches"].as_u64().unwrap(), n as u64);

    // A retry of the last batch is a duplicate with the same update.
    let list = app.get_ok("/v1/sessions").await;
    assert_eq!(list["sessions"][0]["kind"], "plot_fusion");
}

/// The plots with an arrival time each: t plus a delay of 0–6 s spread
/// over the plots, every 9th held up 8 s more (at most 14 s late, within
/// the default lag of 15 s); in 1-s batches of arrival.
fn arrivals(req: &Value) -> Vec<Vec<Value>> {
    let mut plots: Vec<(f64, Value)> = req["plots"]
        .as_array()
        .unwrap()
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut delay = ((i * 7919) % 1000) as f64 / 1000.0 * 6.0;
            if i % 9 == 4 {
                delay += 8.0;
            }
            (f(&p["t"]) + delay, p.clone())
        })
        .collect();
    plots.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out: Vec<Vec<Value>> = Vec::new();
    let mut second = f64::NEG_INFINITY;
    for (arrival, p) in plots {
        if arrival >= second + 1.0 || out.is_empty() {
            second = arrival.floor();
            out.push(Vec::new());
        }
        out.last_mut().unwrap().push(p);
    }
    out
}

#[tokio::test]
async fn late_and_reordered_plots_within_the_lag_end_with_the_batch_calls_tracks() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    let created = create_session(&app, &session_create(&req)).await;
    assert_eq!(created["plot_fusion"]["max_lag_s"], 15.0);
    assert_eq!(created["plot_fusion"]["late_before_t"], Value::Null);
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    let chunks = arrivals(&req);
    let (mut within, mut corrected, mut received) = (0, 0, Vec::new());
    let n = chunks.len();
    for (i, plots) in chunks.into_iter().enumerate() {
        let newest = received
            .iter()
            .map(|p: &Value| f(&p["t"]))
            .fold(f64::NEG_INFINITY, f64::max);
        let older = plots.iter().filter(|p| f(&p["t"]) < newest).count();
        let earliest = plots
            .iter()
            .map(|p| f(&p["t"]))
            .filter(|&t| t < newest)
            .fold(f64::INFINITY, f64::min);
        received.extend(plots.iter().cloned());
        let u = app
            .post_ok(&path, &json!({"sequence": i + 1, "plots": plots}))
            .await;
        assert_eq!(u["warnings"], json!([]), "batch {i}");
        let pf = &u["plot_fusion"];
        assert_eq!(pf["late_plots"], json!([]));
        assert_eq!(pf["late_within_lag"], older);
        within += older;
        if older > 0 {
            assert_eq!(f(&pf["corrected_from_t"]), earliest);
        }
        corrected += pf["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|t| t["change"] == "corrected")
            .count();
        // Half-way and at the end: the batch call over every plot received.
        if i == n / 2 || i + 1 == n {
            let mut so_far = req.clone();
            so_far["plots"] = json!(received);
            let whole = app.post_ok(PATH, &so_far).await;
            let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
            assert_eq!(
                state["plot_fusion"]["tracks"], whole["tracks"],
                "after batch {i}"
            );
            assert_eq!(state["plot_fusion"]["counters"], whole["counters"]);
            assert!(f(&state["plot_fusion"]["late_before_t"]) <= newest);
        }
    }
    assert!(within > 20, "{within} plots arrived after later ones");
    assert!(corrected > 0);
    assert_eq!(received.len(), req["plots"].as_array().unwrap().len());
}

/// `tracker.late_plots: "retrodict"`: the same arrivals as above, taken
/// without replaying; the session says its policy, and ends with the batch
/// call's tracks within the approximation (the count the same, each
/// position within its σ: these arrivals jitter every plot by 0–6 s and
/// hold one in nine 8 s more, the hardest case for it, 34 m of 64 seen;
/// docs/plot-fusion.md). A value that is neither
/// policy is refused naming the field.
#[tokio::test]
async fn retrodiction_takes_late_plots_and_ends_near_the_batch_calls_tracks() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    let mut create = session_create(&req);
    create["tracker"]["late_plots"] = json!("sideways");
    let response = app.post_json("/v1/sessions", &create).await;
    assert_eq!(response.status(), 422);
    let body: Value = response.json().await.unwrap();
    assert_eq!(body["errors"][0]["field"], "tracker.late_plots", "{body}");
    create["tracker"]["late_plots"] = json!("reprocess");
    create["tracker"]["max_replay_plots"] = json!(5);
    let response = app.post_json("/v1/sessions", &create).await;
    assert_eq!(response.status(), 422);
    let body: Value = response.json().await.unwrap();
    assert_eq!(
        body["errors"][0]["field"], "tracker.max_replay_plots",
        "{body}"
    );
    create["tracker"]
        .as_object_mut()
        .unwrap()
        .remove("max_replay_plots");
    create["tracker"]["late_plots"] = json!("retrodict");
    let created = create_session(&app, &create).await;
    assert_eq!(created["plot_fusion"]["late_plots"], "retrodict");
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    let mut within = 0;
    for (i, plots) in arrivals(&req).into_iter().enumerate() {
        let u = app
            .post_ok(&path, &json!({"sequence": i + 1, "plots": plots}))
            .await;
        assert_eq!(u["plot_fusion"]["late_plots"], json!([]));
        within += u["plot_fusion"]["late_within_lag"].as_u64().unwrap();
    }
    assert!(within > 20, "{within} plots arrived after later ones");
    let whole = app.post_ok(PATH, &req).await;
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let ours = state["plot_fusion"]["tracks"].as_array().unwrap();
    let theirs = whole["tracks"].as_array().unwrap();
    let confirmed = |t: &&Value| t["status"] == "confirmed";
    assert_eq!(
        ours.iter().filter(confirmed).count(),
        theirs.iter().filter(confirmed).count()
    );
    for b in theirs.iter().filter(confirmed) {
        let (x, y) = (f(&b["state"][0]), f(&b["state"][2]));
        let sigma = (f(&b["covariance"][0][0]) + f(&b["covariance"][2][2])).sqrt();
        let nearest = ours
            .iter()
            .filter(confirmed)
            .map(|a| (f(&a["state"][0]) - x).hypot(f(&a["state"][2]) - y))
            .fold(f64::INFINITY, f64::min);
        assert!(nearest <= sigma, "{nearest} m of σ {sigma}");
    }
}

/// The default, `auto`, with a bound of one replayed plot: batches whose
/// late plots would replay more are taken by retrodiction and say so in a
/// warning naming `tracker.max_replay_plots`, with the time since which
/// the tracks are approximate (the session's `approximate_from`); the
/// end is within the approximation of the batch call's tracks.
#[tokio::test]
async fn auto_says_when_its_bound_makes_it_retrodict() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    let mut create = session_create(&req);
    create["tracker"]["max_replay_plots"] = json!(1);
    let created = create_session(&app, &create).await;
    assert_eq!(created["plot_fusion"]["late_plots"], "auto");
    assert_eq!(created["plot_fusion"]["approximate_from"], Value::Null);
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    let mut warned = 0;
    for (i, plots) in arrivals(&req).into_iter().enumerate() {
        let u = app
            .post_ok(&path, &json!({"sequence": i + 1, "plots": plots}))
            .await;
        let said = u["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|w| {
                let w = w.as_str().unwrap();
                w.contains("retrodiction") && w.contains("tracker.max_replay_plots = 1")
            })
            .count();
        if said > 0 {
            let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
            assert!(state["plot_fusion"]["approximate_from"].is_f64(), "{state}");
        }
        warned += said;
    }
    assert!(warned > 0, "no batch retrodicted");
    let whole = app.post_ok(PATH, &req).await;
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let confirmed = |v: &Value| {
        v.as_array()
            .unwrap()
            .iter()
            .filter(|t| t["status"] == "confirmed")
            .count()
    };
    assert_eq!(
        confirmed(&state["plot_fusion"]["tracks"]),
        confirmed(&whole["tracks"])
    );
}

#[tokio::test]
async fn a_lag_out_of_range_is_refused_naming_the_field() {
    let app = spawn_app().await;
    let req = with_height(request(false, 7));
    for bad in [json!(-1.0), json!(121.0), json!("x")] {
        let mut create = session_create(&req);
        create["tracker"]["max_lag_s"] = bad.clone();
        let response = app.post_json("/v1/sessions", &create).await;
        assert!(response.status().is_client_error(), "{bad}");
        let body: Value = response.json().await.unwrap();
        assert!(body.to_string().contains("max_lag_s"), "{bad}: {body}");
    }
    let mut create = session_create(&req);
    create["tracker"]["max_lag_s"] = json!(0.0);
    let created = create_session(&app, &create).await;
    assert_eq!(created["plot_fusion"]["max_lag_s"], 0.0);
    assert!(
        app.get_ok("/v1/sessions").await["sessions"]
            .as_array()
            .unwrap()
            .len()
            == 1
    );
}

#[tokio::test]
async fn a_failed_batch_changes_nothing_and_late_plots_are_counted() {
    let app = spawn_app_with(|s| s.max_batch_reports = 50).await;
    let req = with_height(request(false, 7));
    let created = create_session(&app, &session_create(&req)).await;
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    let chunks = batches(&req, 40);
    let first = app
        .post_ok(
            &path,
            &json!({"sequence": 1, "plots": chunks[0], "flush": true}),
        )
        .await;
    let version = first["version"].as_u64().unwrap();

    // Bad plots: 422 naming the field; the session is unchanged.
    let mut bad = chunks[1].clone();
    bad[3]["radar_id"] = json!("nowhere");
    bad[5]["range_m"] = json!(-1.0);
    let body = assert_problem(
        app.post_json(&path, &json!({"sequence": 2, "plots": bad}))
            .await,
        422,
    )
    .await;
    assert_eq!(
        problem_fields(&body),
        vec!["plots[3].radar_id", "plots[5].range_m"]
    );
    // Too many plots: 413.
    let many: Vec<Value> = chunks[1].iter().chain(&chunks[2]).cloned().collect();
    assert_problem(
        app.post_json(&path, &json!({"sequence": 2, "plots": many}))
            .await,
        413,
    )
    .await;
    // Reports to a plot_fusion session: 422 naming `reports`.
    let body = assert_problem(
        app.post_json(
            &path,
            &json!({"sequence": 2, "reports": [{"node": "a", "track": "1", "t": 0.0,
                     "state": [0.0, 0.0, 0.0, 0.0], "covariance": [[1.0, 0.0, 0.0, 0.0],
                     [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]}]}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(problem_fields(&body), vec!["reports"]);
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(state["version"].as_u64().unwrap(), version);

    // A plot older than the newest minus the lag (15 s) is late: dropped,
    // counted, named.
    let mut plots = chunks[1].clone();
    let mut late = chunks[0][0].clone();
    late["t"] = json!(0.0);
    plots.push(late);
    let u = app
        .post_ok(&path, &json!({"sequence": 2, "plots": plots}))
        .await;
    let last = (plots.len() - 1) as u64;
    assert_eq!(u["plot_fusion"]["late_plots"], json!([last]));
    assert_eq!(u["plot_fusion"]["counters"]["late"], 1);
    let warning = u["warnings"][0].as_str().unwrap();
    assert!(
        warning.contains("late") && warning.contains("tracker.max_lag_s"),
        "{warning}"
    );

    // Fields of the other kind are refused at creation, each named.
    let mut create = session_create(&req);
    create["nodes"] = json!(["a", "b"]);
    create["method"] = json!({"kind": "weighted"});
    let body = assert_problem(app.post_json("/v1/sessions", &create).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["method", "nodes"]);
}

#[tokio::test]
async fn a_grpc_stream_tracks_like_the_batch_call() {
    use radar_fusion::proto::session_service_client::SessionServiceClient;

    let app = spawn_app().await;
    let req = with_height(request(true, 5));
    let whole = client(&app)
        .await
        .track(proto_request(&req))
        .await
        .unwrap()
        .into_inner();
    let p = proto_request(&req);
    let mut sessions = SessionServiceClient::new(app.channel().await);
    let mut tracker = p.tracker.clone().unwrap_or_default();
    tracker.max_lag_s = Some(60.0);
    let open = pb::CreateSessionRequest {
        kind: "plot_fusion".into(),
        plot_fusion: Some(pb::PlotFusionConfig {
            cat062: p.cat062,
            origin: p.origin,
            radars: p.radars.clone(),
            tracker: Some(tracker),
        }),
        ..Default::default()
    };
    let (tx, mut updates) =
        crate::sessions::data::open_stream(&mut sessions, pb::stream_request::Kind::Open(open))
            .await;
    let opened = updates.message().await.unwrap().unwrap();
    let id = opened.session_id.clone();
    assert!(opened.plot_fusion.is_some());
    // Chunks of 25 plots, each pair sent in reverse order: the second
    // chunk of a pair arrives late (within the 60-s lag set above).
    let mut chunks: Vec<&[pb::RadarPlot]> = p.plots.chunks(25).collect();
    for pair in chunks.chunks_mut(2) {
        pair.reverse();
    }
    let n = chunks.len();
    let (mut within, mut corrected) = (0, 0);
    for (i, chunk) in chunks.into_iter().enumerate() {
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
                sequence: Some(i as u64 + 1),
                plots: chunk.to_vec(),
                ..Default::default()
            })),
        })
        .await
        .unwrap();
        let u = updates.message().await.unwrap().unwrap();
        assert!(u.error.is_none(), "{:?}", u.error);
        assert_eq!(u.sequence, Some(i as u64 + 1));
        let pf = u.plot_fusion.expect("a plot_fusion update");
        assert!(pf.late_plots.is_empty());
        within += pf.late_within_lag;
        if pf.late_within_lag > 0 {
            assert!(pf.corrected_from_t.is_some());
        }
        corrected += pf.tracks.iter().filter(|t| t.change == "corrected").count();
    }
    assert!(
        within >= 25 && corrected > 0,
        "{within} late plots, {corrected} corrections"
    );
    // A bad batch is answered in the stream, which goes on.
    let mut bad = p.plots[0].clone();
    bad.radar_id = "zz".into();
    tx.send(pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
            sequence: Some(n as u64 + 1),
            plots: vec![bad],
            ..Default::default()
        })),
    })
    .await
    .unwrap();
    let u = updates.message().await.unwrap().unwrap();
    let error = u.error.expect("refused");
    assert_eq!(error.code_name, "INVALID_ARGUMENT");
    assert_eq!(error.violations[0].field, "plots[0].radar_id");
    drop(tx);
    let state = sessions
        .get_session(pb::GetSessionRequest { session_id: id })
        .await
        .unwrap()
        .into_inner();
    let pf = state.plot_fusion.expect("a plot_fusion state");
    assert_eq!(pf.mode, "serial");
    assert_eq!(pf.max_lag_s, 60.0);
    assert_eq!(pf.late_plots, "auto");
    assert_eq!(pf.approximate_from, None);
    assert_eq!(pf.tracks, whole.tracks);
    // The radars' biases, as the batch call's.
    assert_eq!(pf.registration.len(), 2);
    assert_eq!(pf.registration, whole.registration);
    assert_eq!(pf.counters, whole.counters);
}

#[tokio::test]
async fn extreme_but_valid_values_get_an_answer_or_a_named_error_never_a_500() {
    // Valid radars (one WGS84 3D Doppler, one local 2D Doppler); plots at
    // the edges of what validation lets through.
    let app = spawn_app().await;
    let radars = json!([
        {"id": "a", "kind": "3d", "site": {"lat_deg": 89.9, "lon_deg": 180.0, "height_m": 100000.0},
         "sigma_range_m": 1e-300, "sigma_azimuth_deg": 90.0, "sigma_elevation_deg": 1e-9,
         "sigma_radial_velocity_mps": 1e300, "scan_period_s": 1e-300},
        {"id": "b", "kind": "2d", "site": {"position_m": [1e300, -1e300, 1e300]},
         "sigma_range_m": 1e300, "sigma_azimuth_deg": 1e-300,
         "sigma_radial_velocity_mps": 1e-300, "scan_period_s": 1e300}
    ]);
    let extremes = [
        (0.0, 1e300, 720.0, 89.999, 9.9e4),
        (1e300, 1e-300, -720.0, -89.999, -9.9e4),
        (-1e300, 1.0, 0.0, 0.0, 0.0),
        (1e-300, 5e299, 359.9, 45.0, 1.0),
        (f64::MAX, 1e-10, 1e-300, 1e-300, 1e-300),
    ];
    for tracker in [
        json!({}),
        json!({"mode": "serial", "default_height_m": 1e300}),
        json!({"mode": "parallel", "fusion_period_s": 1e-300, "fusion_epoch_s": -1e300}),
    ] {
        let mut plots = Vec::new();
        for (t, range, az, el, rv) in &extremes {
            for radar in ["a", "b"] {
                let mut p = json!({"radar_id": radar, "t": t, "range_m": range,
                                   "azimuth_deg": az, "radial_velocity_mps": rv});
                if radar == "a" {
                    p["elevation_deg"] = json!(el);
                }
                plots.push(p);
            }
        }
        let body = json!({"origin": {"lat_deg": -89.9, "lon_deg": -180.0},
                          "radars": radars, "plots": plots, "tracker": tracker});
        let status = app.post_json(PATH, &body).await.status();
        assert!(
            status.is_success() || status.is_client_error(),
            "{status} for tracker {tracker}"
        );
    }
    // Ranges beyond 10,000 km and times beyond ±1e12 s are named.
    let body = json!({"radars": radars, "tracker": {"mode": "serial"}, "plots": [
        {"radar_id": "b", "t": 0.0, "range_m": 1e300, "azimuth_deg": 0.0},
        {"radar_id": "b", "t": 1e300, "range_m": 1e3, "azimuth_deg": 0.0}]});
    let problem = assert_problem(app.post_json(PATH, &body).await, 422).await;
    assert_eq!(
        problem_fields(&problem),
        vec!["plots[0].range_m", "plots[1].t"]
    );
}

#[tokio::test]
async fn a_session_says_at_creation_what_was_decided_for_it() {
    // Local sites and no origin; one radar with Doppler, one without; the
    // constant-velocity noise set under the default IMM.
    let app = spawn_app().await;
    let created = create_session(
        &app,
        &json!({"kind": "plot_fusion", "tracker": {"sigma_a_mps2": 2.0}, "radars": [
            {"id": "a", "kind": "2d", "site": {"position_m": [0.0, 0.0]},
             "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.1, "scan_period_s": 4.0,
             "sigma_radial_velocity_mps": 1.0},
            {"id": "b", "kind": "2d", "site": {"position_m": [1000.0, 0.0]},
             "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.1, "scan_period_s": 5.0}]}),
    )
    .await;
    assert_eq!(created["plot_fusion"]["mode"], "serial");
    let warnings: Vec<&str> = created["warnings"]
        .as_array()
        .unwrap()
        .iter()
        .map(|w| w.as_str().unwrap())
        .collect();
    assert!(
        warnings.iter().any(|w| w.contains("origin")),
        "{warnings:?}"
    );
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("tentative") && w.contains("imm_models")),
        "{warnings:?}"
    );
    // A later read carries none.
    let id = created["id"].as_str().unwrap();
    let read = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(read["warnings"], json!([]));
}

/// A request with no plot at all (neither `plots` nor `asterix`) is answered
/// with no track and a warning saying why, never silently.
#[tokio::test]
async fn a_request_without_plots_says_so() {
    let app = spawn_app().await;
    let out = app
        .post_ok(PATH, &json!({"radars": radars_json(&far_radars(), 1e-7)}))
        .await;
    assert_eq!(out["tracks"].as_array().unwrap().len(), 0);
    let warnings = out["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("no plot to track")),
        "{warnings:?}"
    );
}

/// The default scene with radar 2's plots biased by +300 m and +0.3°.
fn biased_request() -> Value {
    biased(with_height(request(false, 7)))
}

/// `req` with radar 2's plots biased by +300 m and +0.3°.
fn biased(mut req: Value) -> Value {
    let id = req["radars"][1]["id"].clone();
    for p in req["plots"].as_array_mut().unwrap() {
        if p["radar_id"] == id {
            p["range_m"] = json!(f(&p["range_m"]) + 300.0);
            p["azimuth_deg"] = json!(f(&p["azimuth_deg"]) + 0.3);
        }
    }
    req
}

#[tokio::test]
async fn a_biased_radar_is_registered_and_tracks_do_not_split() {
    let app = spawn_app().await;
    // Radar 1 declared the reference: radar 2's bias is estimated against it.
    let mut req = biased_request();
    let reference = req["radars"][0]["id"].clone();
    req["tracker"]["registration"] = json!({"reference": [reference]});
    let out = app.post_ok(PATH, &req).await;
    let reg = out["registration"].as_array().unwrap();
    assert_eq!(reg.len(), 2);
    assert_eq!(reg[0]["reference"], true);
    assert_eq!(
        (f(&reg[0]["range_m"]), f(&reg[0]["sigma_range_m"])),
        (0.0, 0.0)
    );
    let b = &reg[1];
    assert_eq!(b["converged"], true, "{b}");
    assert!(f(&b["pairs"]) >= 20.0, "{b}");
    // Within 3σ (plus the first-order model's few metres) of the truth.
    let (r, sr) = (f(&b["range_m"]), f(&b["sigma_range_m"]));
    let (a, sa) = (f(&b["azimuth_deg"]), f(&b["sigma_azimuth_deg"]));
    assert!((r - 300.0).abs() < 3.0 * sr + 10.0, "{b}");
    assert!((a - 0.3).abs() < 3.0 * sa + 0.01, "{b}");
    // One track per target, each on its target.
    check_tracks(&out, 300.0);

    // Without registration the same plots give a worse picture: the
    // tracks lie farther from the targets.
    let mut off = biased_request();
    off["tracker"]["registration"] = json!({"enabled": false});
    let unregistered = app.post_ok(PATH, &off).await;
    assert!(
        unregistered["registration"]
            .as_array()
            .unwrap()
            .iter()
            .all(|b| b["converged"] == false && f(&b["range_m"]) == 0.0)
    );
    let spread = |out: &Value| -> f64 {
        let end = 150.0;
        let live: Vec<_> = targets()
            .into_iter()
            .filter(|g| g.start <= end && end <= g.end)
            .collect();
        out["tracks"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|t| t["status"] == "confirmed")
            .map(|t| {
                live.iter()
                    .map(|g| {
                        let p = g.at(f(&t["t"]));
                        (f(&t["state"][0]) - p[0]).hypot(f(&t["state"][2]) - p[1])
                    })
                    .fold(f64::INFINITY, f64::min)
            })
            .fold(0.0, f64::max)
    };
    assert!(
        spread(&out) < spread(&unregistered),
        "{} {}",
        spread(&out),
        spread(&unregistered)
    );

    // The defaults (no reference) also converge and hold one track per
    // target.
    let out = app.post_ok(PATH, &biased_request()).await;
    assert!(
        out["registration"]
            .as_array()
            .unwrap()
            .iter()
            .all(|b| b["converged"] == true && b["reference"] == false)
    );
    check_tracks(&out, 300.0);
}

/// Parallel mode learns the biases from the plots it fuses at each
/// instant: the +300 m +0.3° radar is registered against the reference
/// and the tracks stay one per target, without the warning that parallel
/// mode learns nothing (which it did before).
#[tokio::test]
async fn parallel_mode_registers_a_biased_radar_too() {
    let app = spawn_app().await;
    // Parallel mode needs every radar's radial velocity.
    let mut req = biased(with_height(request(true, 11)));
    let reference = req["radars"][0]["id"].clone();
    req["tracker"]["mode"] = json!("parallel");
    req["tracker"]["registration"] = json!({"reference": [reference]});
    let out = app.post_ok(PATH, &req).await;
    assert_eq!(out["mode"], "parallel");
    let b = &out["registration"][1];
    assert_eq!(b["converged"], true, "{b}");
    let (r, sr) = (f(&b["range_m"]), f(&b["sigma_range_m"]));
    let (a, sa) = (f(&b["azimuth_deg"]), f(&b["sigma_azimuth_deg"]));
    assert!((r - 300.0).abs() < 3.0 * sr + 10.0, "{b}");
    assert!((a - 0.3).abs() < 3.0 * sa + 0.01, "{b}");
    check_tracks(&out, 300.0);
    let warnings = out["warnings"].as_array().unwrap();
    assert!(
        !warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("parallel mode")),
        "{warnings:?}"
    );
}

#[tokio::test]
async fn bad_registration_options_are_named_and_a_session_keeps_its_estimates() {
    let app = spawn_app().await;
    let cases = [
        (
            json!({"registration": {"reference": ["nowhere"]}}),
            None,
            "tracker.registration.reference[0]",
        ),
        (
            json!({"registration": {"max_pair_dt_s": -1.0}}),
            None,
            "tracker.registration.max_pair_dt_s",
        ),
        (
            json!({"registration": {"time_constant_s": 0.0}}),
            None,
            "tracker.registration.time_constant_s",
        ),
        (
            json!({"registration": {"min_pairs": 0}}),
            None,
            "tracker.registration.min_pairs",
        ),
        (
            json!({}),
            Some(json!({"sigma_range_m": -5.0})),
            "radars[0].bias.sigma_range_m",
        ),
        (
            json!({}),
            Some(json!({"azimuth_deg": 30.0})),
            "radars[0].bias.azimuth_deg",
        ),
    ];
    for (tracker, bias, field) in cases {
        let mut req = biased_request();
        req["tracker"] = tracker;
        if let Some(b) = bias {
            req["radars"][0]["bias"] = b;
        }
        let response = app.post_json(PATH, &req).await;
        assert_eq!(response.status(), 422, "{field}");
        let p = assert_problem(response, 422).await;
        assert_eq!(problem_fields(&p), vec![field.to_string()], "{p}");
        let p = assert_problem(
            app.post_json("/v1/sessions", &session_create(&req)).await,
            422,
        )
        .await;
        assert_eq!(problem_fields(&p), vec![field.to_string()], "{p}");
    }
    // Every radar a reference while estimating: refused.
    let mut req = biased_request();
    let ids: Vec<Value> = req["radars"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["id"].clone())
        .collect();
    req["tracker"]["registration"] = json!({"reference": ids});
    let p = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(
        problem_fields(&p),
        vec!["tracker.registration.reference".to_string()]
    );
    assert!(
        app.get_ok("/v1/sessions").await["sessions"]
            .as_array()
            .unwrap()
            .is_empty()
    );

    // A known bias is applied from the start, with its σ.
    let mut req = biased_request();
    req["radars"][1]["bias"] = json!({"range_m": 300.0, "azimuth_deg": 0.3, "sigma_range_m": 10.0});
    req["tracker"]["registration"] = json!({"enabled": false});
    let out = app.post_ok(PATH, &req).await;
    let b = &out["registration"][1];
    assert_eq!((f(&b["range_m"]), f(&b["sigma_range_m"])), (300.0, 10.0));
    assert!((f(&b["azimuth_deg"]) - 0.3).abs() < 1e-12);
    check_tracks(&out, 300.0);

    // A session: the estimates are in its updates and its state, kept
    // (stored) across batches, and equal to the batch call's at the end.
    let req = biased_request();
    let whole = app.post_ok(PATH, &req).await;
    let created = create_session(&app, &session_create(&req)).await;
    assert_eq!(
        created["plot_fusion"]["registration"][1]["converged"],
        false
    );
    let id = created["id"].as_str().unwrap().to_string();
    let path = format!("/v1/sessions/{id}/batches");
    for (i, chunk) in batches(&req, 40).into_iter().enumerate() {
        let u = app
            .post_ok(&path, &json!({"sequence": i + 1, "plots": chunk}))
            .await;
        assert_eq!(
            u["plot_fusion"]["registration"].as_array().unwrap().len(),
            2
        );
    }
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    assert_eq!(state["plot_fusion"]["registration"], whole["registration"]);
    assert_eq!(state["plot_fusion"]["tracks"], whole["tracks"]);

    // `/metrics` shows each radar's estimate for the session, and forgets
    // the session when it is deleted.
    let sample =
        |text: &str, name: &str, radar: &str| crate::helpers::radar_gauge(text, name, &id, radar);
    let text = app.metrics_text().await;
    let b = &whole["registration"][1];
    let radar = b["radar"].as_str().unwrap();
    assert_eq!(
        sample(&text, "fusion_session_radar_range_bias_metres", radar),
        Some(f(&b["range_m"])),
        "{text}"
    );
    assert_eq!(
        sample(
            &text,
            "fusion_session_radar_azimuth_bias_sigma_degrees",
            radar
        ),
        Some(f(&b["sigma_azimuth_deg"]))
    );
    assert_eq!(
        sample(&text, "fusion_session_radar_registration_pairs", radar),
        Some(f(&b["pairs"]))
    );
    assert_eq!(
        sample(&text, "fusion_session_radar_registration_converged", radar),
        Some(1.0)
    );
    let del = app
        .client
        .delete(app.url(&format!("/v1/sessions/{id}")))
        .send()
        .await
        .unwrap();
    assert_eq!(del.status(), 204);
    let text = app.metrics_text().await;
    assert_eq!(
        sample(&text, "fusion_session_radar_range_bias_metres", radar),
        None
    );
}

/// An aircraft flying straight over a 3D radar (the tracker's
/// `an_overflight_of_a_radar_site_does_not_stop_the_tracker` through the
/// server): the answer is a 200 with both aircraft tracked and a warning
/// naming the track that coasted over the site, not an error that would
/// refuse the whole batch (and, in a session, every batch after it).
#[tokio::test]
async fn an_overflight_of_a_radar_site_is_a_warning_not_an_error() {
    let app = spawn_app().await;
    let mut plots = Vec::new();
    for k in 0..=20 {
        let t = 4.0 * f64::from(k);
        for north in [0.0, 40.0] {
            let (e, n, u) = (-4_000.0 + 100.0 * t, north, 3_000.0f64);
            let horizontal = f64::hypot(e, n);
            if horizontal < 1.0 {
                continue; // nothing seen overhead
            }
            plots.push(json!({
                "radar_id": "r", "t": t, "range_m": horizontal.hypot(u),
                "azimuth_deg": e.atan2(n).to_degrees(),
                "elevation_deg": u.atan2(horizontal).to_degrees(),
            }));
        }
    }
    let req = json!({
        "radars": [{"id": "r", "kind": "3d", "site": {"position_m": [0.0, 0.0, 0.0]},
                    "sigma_range_m": 5.0, "sigma_azimuth_deg": 0.0057,
                    "sigma_elevation_deg": 0.0057, "scan_period_s": 4.0,
                    "p_detection": 1.0, "clutter_density": 1e-9}],
        "plots": plots,
        "tracker": {"motion": "cv", "sigma_a_mps2": 0.05},
    });
    let out = app.post_ok(PATH, &req).await;
    let warnings = out["warnings"].to_string();
    assert!(warnings.contains("could not associate track"), "{warnings}");
    let confirmed = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .count();
    assert_eq!(confirmed, 2, "{}", out["tracks"]);
}
