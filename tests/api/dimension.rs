//! Dimension fusion (seed 003) over REST and gRPC: a 2D and a 3D radar seeing
//! one target give one system track, both transports agree, and bad input is
//! named by field on both.

use algo::{
    geo::{Ellipsoid, LocalFrame},
    polar::enu_to_polar_3d,
};
use radar_fusion::proto::{self as pb, dimension_service_client::DimensionServiceClient};
use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{TestApp, assert_problem, grpc_fields, problem_fields, spawn_app};

const PATH: &str = "/v1/dimension/fuse";

async fn client(app: &TestApp) -> DimensionServiceClient<tonic::transport::Channel> {
    DimensionServiceClient::new(app.channel().await)
}

fn frame(lat: f64, lon: f64, h: f64) -> LocalFrame {
    LocalFrame::new(Ellipsoid::WGS84, lat.to_radians(), lon.to_radians(), h).unwrap()
}

/// Noise-free plots (t, range, azimuth°, elevation°) of a target moving from
/// `start` at `vel` in the ENU frame of (30°N, 120°E, 0), seen from `site`.
fn plots(site: (f64, f64, f64), period: f64, n: usize, three_d: bool) -> Vec<Value> {
    let centre = frame(30.0, 120.0, 0.0);
    let radar = frame(site.0, site.1, site.2);
    let (start, vel) = ([100_000.0, 110_000.0, 7000.0], [-300.0, 0.0, 0.0]);
    (0..n)
        .map(|k| {
            let t = k as f64 * period;
            let p = [start[0] + vel[0] * t, start[1] + vel[1] * t, start[2]];
            let l = centre.position_to(&radar, p).unwrap();
            let [r, az, el] = enu_to_polar_3d(l[0], l[1], l[2]).unwrap();
            let mut plot = json!({"t": t, "range_m": r, "azimuth_deg": az.to_degrees()});
            if three_d {
                plot["elevation_deg"] = json!(el.to_degrees());
            }
            plot
        })
        .collect()
}

fn scene() -> Value {
    json!({
        "origin": {"lat_deg": 30.0, "lon_deg": 120.0, "height_m": 0.0},
        "methods": ["lifting", "splitting"],
        "n0": 4, "k": 3, "significance": 0.001, "preset_altitude_m": 7000.0,
        "radars": [
            {"id": "r3", "kind": "3d", "site": {"lat_deg": 30.0, "lon_deg": 120.0, "height_m": 0.0},
             "sigma_range_m": 100.0, "sigma_azimuth_deg": 0.5, "sigma_elevation_deg": 0.25,
             "scan_period_s": 10.0,
             "tracks": [{"id": "a", "plots": plots((30.0, 120.0, 0.0), 10.0, 15, true)}]},
            {"id": "r2", "kind": "2d", "site": {"lat_deg": 30.1, "lon_deg": 120.1, "height_m": 100.0},
             "sigma_range_m": 500.0, "sigma_azimuth_deg": 0.5, "scan_period_s": 15.0,
             "tracks": [{"id": "b", "plots": plots((30.1, 120.1, 100.0), 15.0, 10, false)}]}
        ]
    })
}

#[tokio::test]
async fn one_target_is_one_system_track_under_lifting_and_splitting() {
    let app = spawn_app().await;
    let out = app.post_ok(PATH, &scene()).await;
    assert_eq!(
        out["state_layout"],
        json!(["x", "vx", "y", "vy", "z", "vz"])
    );
    assert!(out["timing"]["compute_us"].as_f64().unwrap() >= 0.0);
    assert_eq!(out["warnings"], json!([]));
    let results = out["results"].as_array().unwrap();
    assert_eq!(results.len(), 2);
    for (r, method) in results.iter().zip(["lifting", "splitting"]) {
        assert_eq!(r["method"], method);
        let pair = &r["pairs"][0];
        // N₀ = 4 hits, then three χ² passes: T = 3 → hold.
        assert_eq!(pair["period"], "hold", "{method}: {pair}");
        assert_eq!(
            (pair["tests"].clone(), pair["hits"].clone()),
            (json!(4), json!(4))
        );
        assert_eq!(pair["check_counter"], 3);
        assert_eq!(r["uncorrelated"], json!([]));
        let st = &r["system_tracks"].as_array().unwrap();
        assert_eq!(st.len(), 1);
        assert_eq!(
            st[0]["members"],
            json!([{"radar": "r3", "track": "a"}, {"radar": "r2", "track": "b"}])
        );
        assert_eq!(st[0]["altitude_known"], true);
        let last = st[0]["samples"].as_array().unwrap().last().unwrap().clone();
        assert!(last["height_m"].is_f64());
        // Both tracks see the target at the end: a 3D member contributes.
        assert_eq!(last["altitude"], "measured");
        assert_eq!(last["covariance"].as_array().unwrap().len(), 6);
    }
}

/// `scene()` with a second 2D track, "far", 50 km further in slant range than
/// the target: it never hits the 3D track ("a": 3 σ is 1.5 km in range).
fn scene_with_a_far_track() -> Value {
    let mut body = scene();
    let mut far = plots((30.1, 120.1, 100.0), 15.0, 10, false);
    for p in &mut far {
        p["range_m"] = json!(p["range_m"].as_f64().unwrap() + 50_000.0);
    }
    body["radars"][1]["tracks"]
        .as_array_mut()
        .unwrap()
        .push(json!({"id": "far", "plots": far}));
    body
}

#[tokio::test]
async fn pairs_without_a_hit_are_counted_unless_all_pairs_are_asked() {
    let app = spawn_app().await;
    let short = app.post_ok(PATH, &scene_with_a_far_track()).await;
    let mut body = scene_with_a_far_track();
    body["all_pairs"] = json!(true);
    let all = app.post_ok(PATH, &body).await;
    for (s, a) in short["results"]
        .as_array()
        .unwrap()
        .iter()
        .zip(all["results"].as_array().unwrap())
    {
        // r3/a against r2/b (the same target) and r2/far.
        let listed: Vec<&Value> = s["pairs"].as_array().unwrap().iter().collect();
        assert_eq!(listed.len(), 1, "{}", s["method"]);
        assert_eq!(listed[0]["b"], json!({"radar": "r2", "track": "b"}));
        assert_eq!(s["omitted_pairs"], 1);
        let every = a["pairs"].as_array().unwrap();
        assert_eq!(every.len(), 2);
        assert_eq!(a["omitted_pairs"], 0);
        let far = every.iter().find(|p| p["b"]["track"] == "far").unwrap();
        assert_eq!(far["hits"], 0, "{far}");
        assert_eq!(&every[0], listed[0]);
        assert_eq!(s["system_tracks"], a["system_tracks"]);
    }
}

#[tokio::test]
async fn system_tracks_answer_their_latest_sample_unless_history_is_asked() {
    let app = spawn_app().await;
    let latest = app.post_ok(PATH, &scene()).await;
    let mut body = scene();
    body["history"] = json!(true);
    let full = app.post_ok(PATH, &body).await;
    for (l, f) in latest["results"]
        .as_array()
        .unwrap()
        .iter()
        .zip(full["results"].as_array().unwrap())
    {
        // Pairs and members do not depend on the option.
        assert_eq!(l["pairs"], f["pairs"]);
        let (ls, fs) = (&l["system_tracks"][0], &f["system_tracks"][0]);
        assert_eq!(ls["members"], fs["members"]);
        let one = ls["samples"].as_array().unwrap();
        let all = fs["samples"].as_array().unwrap();
        assert_eq!(one.len(), 1, "{}", l["method"]);
        // The local filters estimate from their second plot: the 3D track
        // at 10, 20, …, 140 s (14 instants), the 2D track at 15, 30, …,
        // 135 s (9); the system track fuses at every instant of either, 14 +
        // 9 − 4 shared (30, 60, 90, 120) = 19.
        assert_eq!(all.len(), 19, "{}", l["method"]);
        let times: Vec<f64> = all.iter().map(|s| s["t"].as_f64().unwrap()).collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]), "{times:?}");
        assert_eq!(&one[0], all.last().unwrap());
    }
}

#[tokio::test]
async fn rest_and_grpc_agree() {
    rest_and_grpc_agree_on(scene(), false).await;
}

#[tokio::test]
async fn rest_and_grpc_agree_on_the_whole_history() {
    rest_and_grpc_agree_on(scene_with_a_far_track(), true).await;
}

/// The same request over both transports, with `history` and `all_pairs`
/// both set to `full`: every pair's and every sample's fields agree.
async fn rest_and_grpc_agree_on(s: Value, full: bool) {
    let app = spawn_app().await;
    let mut body = s.clone();
    body["history"] = json!(full);
    body["all_pairs"] = json!(full);
    let rest = app.post_ok(PATH, &body).await;
    let site = |v: &Value| pb::DimensionSite {
        lat_deg: v["lat_deg"].as_f64(),
        lon_deg: v["lon_deg"].as_f64(),
        height_m: v["height_m"].as_f64(),
    };
    let req = pb::DimensionFuseRequest {
        origin: Some(site(&s["origin"])),
        methods: vec!["lifting".into(), "splitting".into()],
        n0: Some(4),
        k: Some(3),
        significance: Some(0.001),
        preset_altitude_m: Some(7000.0),
        history: full,
        all_pairs: full,
        radars: s["radars"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| pb::DimensionRadar {
                id: r["id"].as_str().map(Into::into),
                kind: r["kind"].as_str().map(Into::into),
                site: Some(site(&r["site"])),
                sigma_range_m: r["sigma_range_m"].as_f64(),
                sigma_azimuth_deg: r["sigma_azimuth_deg"].as_f64(),
                sigma_elevation_deg: r["sigma_elevation_deg"].as_f64(),
                scan_period_s: r["scan_period_s"].as_f64(),
                tracks: r["tracks"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|t| pb::DimensionTrack {
                        id: t["id"].as_str().map(Into::into),
                        plots: t["plots"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|p| pb::DimensionPlot {
                                t: p["t"].as_f64(),
                                range_m: p["range_m"].as_f64(),
                                azimuth_deg: p["azimuth_deg"].as_f64(),
                                elevation_deg: p["elevation_deg"].as_f64(),
                            })
                            .collect(),
                    })
                    .collect(),
            })
            .collect(),
        ..Default::default()
    };
    let grpc = client(&app).await.fuse(req).await.unwrap().into_inner();
    assert_eq!(grpc.results.len(), 2);
    for (g, r) in grpc.results.iter().zip(rest["results"].as_array().unwrap()) {
        assert_eq!(g.method, r["method"]);
        assert_eq!(g.omitted_pairs, r["omitted_pairs"].as_u64().unwrap());
        assert_eq!(g.pairs.len(), r["pairs"].as_array().unwrap().len());
        for (gp, rp) in g.pairs.iter().zip(r["pairs"].as_array().unwrap()) {
            assert_eq!(gp.period, rp["period"]);
            assert_eq!(gp.hits, rp["hits"]);
            assert_eq!(gp.mean_statistic, rp["mean_statistic"].as_f64());
        }
        // With the far track and all_pairs, its pair is listed too.
        assert_eq!(g.pairs.len(), if full { 2 } else { 1 });
        // The far track is a system track of its own.
        assert_eq!(g.system_tracks.len(), if full { 2 } else { 1 });
        let k = g
            .system_tracks
            .iter()
            .position(|st| st.members.len() == 2)
            .unwrap();
        assert_eq!(g.system_tracks[k].id, r["system_tracks"][k]["id"]);
        let (gs, rs) = (
            &g.system_tracks[k].samples,
            &r["system_tracks"][k]["samples"],
        );
        assert_eq!(gs.len(), rs.as_array().unwrap().len());
        // 19 fused instants (see above), or the latest one.
        assert_eq!(gs.len(), if full { 19 } else { 1 });
        for (a, b) in gs.iter().zip(rs.as_array().unwrap()) {
            assert_eq!(a.t, b["t"].as_f64().unwrap());
            let bs: Vec<f64> = b["state"]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect();
            assert_eq!(a.state, bs);
            assert_eq!(a.height_m, b["height_m"].as_f64());
            assert_eq!(a.altitude, b["altitude"].as_str().unwrap());
            assert!(["measured", "lifted", "assumed"].contains(&a.altitude.as_str()));
            assert_eq!(a.covariance.as_ref().unwrap().values.len(), 36);
        }
    }
}

#[tokio::test]
async fn bad_input_names_every_field_over_rest() {
    let app = spawn_app().await;
    let mut body = scene();
    body["methods"] = json!(["lifting", "stretching"]);
    body["radars"][0]["site"]["lat_deg"] = json!(95.0);
    // 3D radar: a plot without elevation; 2D radar: a plot with one.
    body["radars"][0]["tracks"][0]["plots"][2]
        .as_object_mut()
        .unwrap()
        .remove("elevation_deg");
    body["radars"][1]["tracks"][0]["plots"][1]["elevation_deg"] = json!(1.0);
    body["radars"][1]["tracks"][0]["plots"][3]["range_m"] = json!(-5.0);
    body["radars"][1]["tracks"][0]["plots"][5]["t"] = json!(0.0);
    let problem = assert_problem(app.post_json(PATH, &body).await, 422).await;
    let mut fields = problem_fields(&problem);
    fields.sort();
    assert_eq!(
        fields,
        vec![
            "methods[1]",
            "radars[0].site.lat_deg",
            "radars[0].tracks[0].plots[2].elevation_deg",
            "radars[1].tracks[0].plots[1].elevation_deg",
            "radars[1].tracks[0].plots[3].range_m",
            "radars[1].tracks[0].plots[5].t",
        ]
    );
    // An unknown field is a 422 naming it, as for every endpoint.
    let mut body = scene();
    body["radars"][0]["bias"] = json!(1.0);
    assert_problem(app.post_json(PATH, &body).await, 422).await;
}

#[tokio::test]
async fn bad_input_names_the_field_over_grpc_including_nan() {
    let app = spawn_app().await;
    let plot = |t: f64, range: f64| pb::DimensionPlot {
        t: Some(t),
        range_m: Some(range),
        azimuth_deg: Some(10.0),
        elevation_deg: None,
    };
    let req = pb::DimensionFuseRequest {
        methods: vec!["mapping".into()],
        radars: vec![pb::DimensionRadar {
            id: Some("r2".into()),
            kind: Some("2d".into()),
            site: Some(pb::DimensionSite {
                lat_deg: Some(30.0),
                lon_deg: Some(f64::NAN),
                height_m: Some(0.0),
            }),
            sigma_range_m: Some(500.0),
            sigma_azimuth_deg: Some(0.5),
            sigma_elevation_deg: None,
            scan_period_s: Some(15.0),
            tracks: vec![pb::DimensionTrack {
                id: Some("b".into()),
                plots: vec![plot(0.0, 1e5), plot(15.0, f64::NAN), plot(10.0, 1e5)],
            }],
        }],
        ..Default::default()
    };
    let status = client(&app).await.fuse(req).await.unwrap_err();
    assert_eq!(status.code(), Code::InvalidArgument);
    let mut fields = grpc_fields(&status);
    fields.sort();
    assert_eq!(
        fields,
        vec![
            "radars[0].site.lon_deg",
            "radars[0].tracks[0].plots[1].range_m",
            "radars[0].tracks[0].plots[2].t",
        ]
    );
}

#[tokio::test]
async fn too_many_pair_samples_is_a_422_naming_radars() {
    // Two radars with 100 tracks of 300 plots each: 100·100 pairs × 600
    // plots = 6·10⁶ > 5·10⁶ pair samples. Validation rejects it before any
    // computation.
    let app = spawn_app().await;
    let plots: Vec<Value> = (0..300)
        .map(|k| json!({"t": k as f64, "range_m": 1e5, "azimuth_deg": 10.0}))
        .collect();
    let tracks: Vec<Value> = (0..100)
        .map(|i| json!({"id": format!("t{i}"), "plots": plots}))
        .collect();
    let radar = |id: &str| {
        json!({"id": id, "kind": "2d", "site": {"lat_deg": 30.0, "lon_deg": 120.0, "height_m": 0.0},
               "sigma_range_m": 500.0, "sigma_azimuth_deg": 0.5, "scan_period_s": 15.0, "tracks": tracks})
    };
    let body = json!({"radars": [radar("a"), radar("b")]});
    let problem = assert_problem(app.post_json(PATH, &body).await, 422).await;
    assert_eq!(problem_fields(&problem), vec!["radars"]);
}

/// Radars that hold no tracks (a normal moment of a network) are answered,
/// and the answer says there was nothing to fuse.
#[tokio::test]
async fn radars_without_tracks_are_said() {
    let app = spawn_app().await;
    let mut req = scene();
    for r in req["radars"].as_array_mut().unwrap() {
        r["tracks"] = json!([]);
    }
    let out: Value = app.post_ok(PATH, &req).await;
    assert!(
        out["warnings"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| w.as_str().unwrap().contains("holds a track")),
        "{out}"
    );
}
