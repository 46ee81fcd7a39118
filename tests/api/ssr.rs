//! SSR and Mode S through the real servers: identity and pressure altitude
//! from JSON plots to the tracks on REST, gRPC and a session, warnings for
//! emergency codes, bad fields named on both transports.

use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{assert_problem, grpc_fields, problem_fields, spawn_app};
use crate::plot_fusion::plot_scene::{
    ORIGIN, origin_frame, plots_tagged, radars_json, targets, two_radars,
};
use crate::plot_fusion::{proto_request, session_fed_in_batches};
use radar_fusion::proto::plot_fusion_service_client::PlotFusionServiceClient;

const PATH: &str = "/v1/plot-fusion/track";
const ADDRESSES: [&str; 3] = ["4CA2D1", "3C6586", "A1B2C3"];
const CODES: [&str; 3] = ["1234", "5670", "7700"];
const CALLSIGNS: [&str; 3] = ["EZY12AB", "DLH4K", "N123AB"];

/// The scene's targets fly at 8,000 m: FL 262.47, which Mode S gives to
/// 25 ft as FL 262.5.
const FL: f64 = 262.5;

/// The default scene (two 2D radars, three targets, clutter) with every
/// target plot carrying its aircraft's Mode S reply.
fn request() -> Value {
    let radars = two_radars(false);
    let tag = |i: usize, _t: f64| {
        Some(json!({
            "mode_s_address": ADDRESSES[i], "mode_3a": CODES[i], "callsign": CALLSIGNS[i],
            "flight_level": FL, "detection": "combined",
        }))
    };
    json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots_tagged(&radars, &targets(), 150.0, 1.0, 11, &tag),
    })
}

/// Each confirmed track carries the identity of the target it lies
/// nearest: its address, code, callsign and flight level.
fn check_identities(tracks: &Value) {
    let confirmed: Vec<&Value> = tracks
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .collect();
    assert_eq!(confirmed.len(), 2, "{tracks}");
    for t in confirmed {
        let at = t["t"].as_f64().unwrap();
        let s = &t["state"];
        let nearest = targets()
            .iter()
            .enumerate()
            .filter(|(_, g)| g.start <= at && at <= g.end)
            .min_by(|a, b| {
                let d = |g: &crate::plot_fusion::plot_scene::Target| {
                    let p = g.at(at);
                    (s[0].as_f64().unwrap() - p[0]).hypot(s[2].as_f64().unwrap() - p[1])
                };
                d(a.1).total_cmp(&d(b.1))
            })
            .unwrap()
            .0;
        let id = &t["identity"];
        assert_eq!(id["mode_s_address"]["value"], ADDRESSES[nearest], "{t}");
        assert_eq!(id["mode_3a"]["value"], CODES[nearest], "{t}");
        assert_eq!(id["callsign"]["value"], CALLSIGNS[nearest], "{t}");
        assert!(id["mode_s_address"]["plots"].as_u64().unwrap() >= 3, "{t}");
        let fl = id["pressure_altitude"]["flight_level"].as_f64().unwrap();
        // Every reply says FL 262.5: the filter holds it (within 0.1 FL).
        assert!((fl - FL).abs() < 0.1, "{fl}");
        assert!(id["last_mode_s_t"].as_f64().unwrap() <= at);
    }
}

#[tokio::test]
async fn identity_flows_to_the_tracks_on_rest_grpc_and_a_session() {
    let app = spawn_app().await;
    let req = request();
    let out = app.post_ok(PATH, &req).await;
    check_identities(&out["tracks"]);
    // Target 2 squawks 7700 while it lives (30–100 s); it has ended by
    // 150 s, so no warning at the end; the other two do not squawk it.
    let warnings = out["warnings"].to_string();
    assert!(!warnings.contains("7700"), "{warnings}");

    // gRPC: the same identities.
    let mut client = PlotFusionServiceClient::new(app.channel().await);
    let mut p = proto_request(&req);
    p.tracker = None;
    let g = client.track(p).await.unwrap().into_inner();
    let rest: Vec<(u64, String, String)> = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|t| {
            let id = t.get("identity")?;
            Some((
                t["id"].as_u64().unwrap(),
                id["mode_s_address"]["value"].as_str()?.to_string(),
                id["mode_3a"]["value"].as_str()?.to_string(),
            ))
        })
        .collect();
    let grpc: Vec<(u64, String, String)> = g
        .tracks
        .iter()
        .filter_map(|t| {
            let id = t.identity.as_ref()?;
            Some((
                t.id,
                id.mode_s_address.as_ref()?.value.clone(),
                id.mode_3a.as_ref()?.value.clone(),
            ))
        })
        .collect();
    assert!(!rest.is_empty());
    assert_eq!(rest, grpc);

    // A session fed in batches (the log carries the SSR fields) ends with
    // the batch call's tracks, identities included.
    let (_, state) = session_fed_in_batches(&app, &req, 17).await;
    assert_eq!(state["plot_fusion"]["tracks"], out["tracks"]);
}

#[tokio::test]
async fn an_emergency_code_is_a_track_flag_and_a_warning() {
    let app = spawn_app().await;
    let radars = two_radars(false);
    // Target 0 squawks 7700 throughout.
    let tag = |i: usize, _t: f64| {
        Some(json!({"mode_3a": if i == 0 { "7700" } else { CODES[1] }, "flight_level": FL}))
    };
    let req = json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots_tagged(&radars, &targets()[..2], 100.0, 0.0, 3, &tag),
    });
    let out = app.post_ok(PATH, &req).await;
    let flagged: Vec<&Value> = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["identity"]["emergency"] == "emergency")
        .collect();
    assert_eq!(flagged.len(), 1, "{}", out["tracks"]);
    let warnings = out["warnings"].to_string();
    assert!(
        warnings.contains(&format!("track {} squawks 7700", flagged[0]["id"])),
        "{warnings}"
    );
}

#[tokio::test]
async fn bad_ssr_fields_are_named_on_both_transports() {
    let app = spawn_app().await;
    let mut req = request();
    let bad = [
        ("mode_3a", json!("8000")),
        ("flight_level", json!(2000.0)),
        ("mode_s_address", json!("1000000")),
        ("callsign", json!("bad-1")),
        ("detection", json!("psr")),
    ];
    let plots = req["plots"].as_array_mut().unwrap();
    for (i, (field, value)) in bad.iter().enumerate() {
        plots[i][*field] = value.clone();
    }
    plots[5] = json!({"radar_id": plots[5]["radar_id"], "t": plots[5]["t"],
                      "range_m": plots[5]["range_m"], "azimuth_deg": plots[5]["azimuth_deg"],
                      "mode_3a_garbled": true});
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    let want = vec![
        "plots[0].mode_3a",
        "plots[1].flight_level",
        "plots[2].mode_s_address",
        "plots[3].callsign",
        "plots[4].detection",
        "plots[5].mode_3a_garbled",
    ];
    assert_eq!(problem_fields(&body), want);
    let mut p = proto_request(&req);
    p.tracker = None;
    let status = PlotFusionServiceClient::new(app.channel().await)
        .track(p)
        .await
        .unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    assert_eq!(grpc_fields(&status), want);
}

/// Mode C as geometric height: two 3D radars about 200 km out (elevation
/// σ 0.1°: 350 m of height per plot), targets at 8,000 m above the
/// ellipsoid whose transponders report a pressure altitude 60 m lower
/// (QNH about 1020 hPa), quantised to 25 ft. The tracker learns the
/// offset from the radars' heights and puts each confirmed track within
/// 4σ of the offset it reports (a few tens of metres) of 8,000 m; with
/// `mode_c_height.enabled` false the answer has no offset. Without
/// learning, the prior's σ (150 m) is named in a warning with the option
/// that fixes it; a bad prior is a 422 naming it.
#[tokio::test]
async fn mode_c_gives_the_tracks_their_geometric_height() {
    const HEIGHT_M: f64 = 8_000.0;
    const OFFSET_M: f64 = 60.0;
    let app = spawn_app().await;
    let mut radars = two_radars(false);
    for r in &mut radars {
        r.three_d = true;
    }
    let fl = ((HEIGHT_M - OFFSET_M) / 0.3048 / 25.0).round() * 0.25;
    let tag = |i: usize, _t: f64| Some(json!({"mode_s_address": ADDRESSES[i], "flight_level": fl}));
    let req = json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots_tagged(&radars, &targets(), 150.0, 0.0, 5, &tag),
    });
    assert!(
        targets()
            .iter()
            .all(|g| g.p0[2] == HEIGHT_M && g.v[2] == 0.0)
    );
    let out = app.post_ok(PATH, &req).await;
    let po = &out["pressure_offset"];
    let (sigma, sigma_slope, rho) = (
        po["sigma_offset_m"].as_f64().unwrap(),
        po["sigma_slope"].as_f64().unwrap(),
        po["correlation"].as_f64().unwrap(),
    );
    assert!(po["plots"].as_u64().unwrap() > 50, "{po}");
    // σ at the level: √(σ_o² + 2ρ σ_o σ_s h + σ_s² h²).
    let h_p = fl * 30.48;
    let at_level =
        (sigma * sigma + 2.0 * rho * sigma * sigma_slope * h_p + (sigma_slope * h_p).powi(2))
            .sqrt();
    let learnt = po["offset_m"].as_f64().unwrap() + po["slope"].as_f64().unwrap() * h_p;
    assert!((learnt - OFFSET_M).abs() < 4.0 * at_level, "{po}");
    assert!(at_level < 60.0, "{po}");
    let frame = origin_frame();
    let confirmed: Vec<&Value> = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .collect();
    assert_eq!(confirmed.len(), 2, "{}", out["tracks"]);
    for t in confirmed {
        let x: Vec<f64> = t["state"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        let (_, _, h) = frame.enu_to_geodetic([x[0], x[2], x[4]]).unwrap();
        assert!((h - HEIGHT_M).abs() < 4.0 * at_level, "{h} m, {po}");
        // The height's variance is at least the offset's at the level
        // (the common error does not average out).
        let p_zz = t["covariance"][4][4].as_f64().unwrap();
        assert!(p_zz.sqrt() >= 0.99 * at_level, "{p_zz} {po}");
    }
    assert!(
        !out["warnings"].to_string().contains("mode_c_height"),
        "{}",
        out["warnings"]
    );

    // A session fed the same plots in batches (its stored tracker carries
    // the offset's data) ends with the batch call's offset and tracks; over
    // gRPC the session's state says the same.
    let (id, state) = session_fed_in_batches(&app, &req, 23).await;
    assert_eq!(
        state["plot_fusion"]["pressure_offset"],
        out["pressure_offset"]
    );
    assert_eq!(state["plot_fusion"]["tracks"], out["tracks"]);
    let g =
        radar_fusion::proto::session_service_client::SessionServiceClient::new(app.channel().await)
            .get_session(radar_fusion::proto::GetSessionRequest { session_id: id })
            .await
            .unwrap()
            .into_inner();
    let offset = g
        .plot_fusion
        .and_then(|p| p.pressure_offset)
        .expect("the gRPC session state's pressure offset");
    assert_eq!(offset.plots, po["plots"].as_u64().unwrap());

    let mut off = req.clone();
    off["tracker"] = json!({"mode_c_height": {"enabled": false}});
    let out = app.post_ok(PATH, &off).await;
    assert!(out.get("pressure_offset").is_none(), "{out}");

    let mut prior_only = req.clone();
    prior_only["tracker"] = json!({"mode_c_height": {"learn": false}});
    let out = app.post_ok(PATH, &prior_only).await;
    assert_eq!(out["pressure_offset"]["plots"], 0);
    let warnings = out["warnings"].to_string();
    assert!(
        warnings.contains("tracker.mode_c_height.offset_m") && warnings.contains("FL"),
        "{warnings}"
    );

    let mut bad = req.clone();
    bad["tracker"] = json!({"mode_c_height": {"sigma_offset_m": -1.0}});
    let body = assert_problem(app.post_json(PATH, &bad).await, 422).await;
    assert_eq!(
        problem_fields(&body),
        vec!["tracker.mode_c_height.sigma_offset_m"]
    );
}
