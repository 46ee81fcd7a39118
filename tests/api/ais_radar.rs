//! AIS–radar association (seed 004) over REST and gRPC. Scenes are built
//! with a known radar bias: ships on straight lines in the radar's plane,
//! AIS positions mapped to WGS84 with the plane's inverse projection (checked
//! against published coordinates in `algo::bias::projection`), radar
//! samples at the AIS times as biased polar measurements, so the bias must
//! come back to rounding.

use algo::bias::projection::LocalPlane;
use algo::geo::Ellipsoid;
use eval::ais::{PositionReport, nmea_checksum};
use radar_fusion::proto::{self as pb, ais_radar_service_client::AisRadarServiceClient};
use serde_json::{Value, json};
use tonic_types::StatusExt;

use crate::helpers::{assert_problem, problem_fields, spawn_app};

const LAT0: f64 = 37.5;
const LON0: f64 = 121.4;
const BIAS_RANGE_M: f64 = 800.0;
const BIAS_AZ_DEG: f64 = 0.7;

struct Ship {
    east: f64,
    north: f64,
    ve: f64,
    vn: f64,
}

fn ships(n: usize) -> Vec<Ship> {
    (0..n)
        .map(|k| Ship {
            east: -9000.0 + 4500.0 * (k % 4) as f64,
            north: 4000.0 + 5000.0 * (k / 4) as f64 + 700.0 * (k % 2) as f64,
            ve: 4.0 - k as f64,
            vn: 2.0 + 0.5 * k as f64,
        })
        .collect()
}

fn times() -> Vec<f64> {
    (0..15).map(|k| 1_700_000_000.0 + 10.0 * k as f64).collect()
}

/// Radar tracks r0.. of every ship, AIS reports of the ships with `with_ais`.
fn scene(n: usize, with_ais: &[bool]) -> (Value, Value) {
    let plane = LocalPlane::new(Ellipsoid::WGS84, LAT0.to_radians(), LON0.to_radians()).unwrap();
    let mut tracks = Vec::new();
    let mut reports = Vec::new();
    for (k, s) in ships(n).iter().enumerate() {
        let t0 = times()[0];
        let pos = |t: f64| [s.east + s.ve * (t - t0), s.north + s.vn * (t - t0)];
        let samples: Vec<Value> = times()
            .iter()
            .map(|&t| {
                let p = pos(t);
                let range = p[0].hypot(p[1]) + BIAS_RANGE_M;
                let az = p[0].atan2(p[1]).to_degrees() + BIAS_AZ_DEG;
                json!({"t": t, "range_m": range, "azimuth_deg": az.rem_euclid(360.0)})
            })
            .collect();
        tracks.push(json!({"id": format!("r{k}"), "samples": samples}));
        if with_ais[k] {
            for &t in &times() {
                let (lat, lon) = plane.inverse(pos(t));
                reports.push(json!({"mmsi": 412_000_000 + k as u32, "t": t,
                    "lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees()}));
            }
        }
    }
    (Value::Array(tracks), Value::Array(reports))
}

#[tokio::test]
async fn rest_recovers_the_bias_and_leaves_ships_without_ais_alone() {
    let app = spawn_app().await;
    let with = [true, true, true, true, true, false, true, true];
    let (tracks, reports) = scene(8, &with);
    let response = app
        .post_json(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0},
                    "radar_tracks": tracks, "ais_reports": reports}),
        )
        .await;
    assert_eq!(response.status(), 200);
    let body: Value = response.json().await.unwrap();
    let bias = &body["bias"];
    assert!(
        (bias["range_m"].as_f64().unwrap() - BIAS_RANGE_M).abs() < 1e-6,
        "{bias}"
    );
    assert!((bias["azimuth_deg"].as_f64().unwrap() - BIAS_AZ_DEG).abs() < 1e-9);
    let assoc = body["associations"].as_array().unwrap();
    assert_eq!(assoc.len(), 7);
    for a in assoc {
        let k: u32 = a["radar_track_id"].as_str().unwrap()[1..].parse().unwrap();
        assert_eq!(a["mmsi"].as_u64().unwrap(), u64::from(412_000_000 + k));
        assert!(a["distance_after_m"].as_f64().unwrap() < 1e-5);
    }
    assert_eq!(body["unassociated_radar_tracks"], json!(["r5"]));
    assert_eq!(body["unassociated_mmsis"], json!([]));
    assert!(body["mean_error_before_m"].as_f64().unwrap() > 500.0);
    let c = &body["compensated_tracks"][0]["samples"][0];
    assert!(c["lat_deg"].as_f64().unwrap() > LAT0);
    assert!(["cfar", "bias_search"].contains(&body["path"].as_str().unwrap()));
    assert!(body["timing"]["compute_us"].as_f64().unwrap() >= 0.0);
    assert!(body["warnings"].is_array());
    let q = &body["quality"];
    assert_eq!(q["reliable"], json!(true), "{q}");
    for flag in ["at_bound", "search_widened", "ambiguous", "inconsistent"] {
        assert_eq!(q[flag], json!(false), "{flag}: {q}");
    }
    assert_eq!(body["unassociable_mmsis"], json!([]));
}

/// Issue 17: a ship with a single AIS report can never be associated (a
/// pair needs two common instants); the answer lists it and says why.
#[tokio::test]
async fn a_single_ais_report_is_listed_as_unassociable_with_a_warning() {
    let app = spawn_app().await;
    let (tracks, mut reports) = scene(4, &[true; 4]);
    let one = reports.as_array().unwrap()[20].clone();
    let mut single = one.clone();
    single["mmsi"] = json!(999_000_001u32);
    reports.as_array_mut().unwrap().push(single);
    let body = app
        .post_ok(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0}, "radar_tracks": tracks, "ais_reports": reports}),
        )
        .await;
    assert_eq!(body["unassociable_mmsis"], json!([999_000_001u32]));
    assert_eq!(body["associations"].as_array().unwrap().len(), 4);
    let warnings = body["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("1 with a single report")),
        "{warnings:?}"
    );
}

#[tokio::test]
async fn rest_all_ships_without_ais_and_no_ships() {
    let app = spawn_app().await;
    let (tracks, _) = scene(3, &[false; 3]);
    let body: Value = app
        .post_json(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0}, "radar_tracks": tracks}),
        )
        .await
        .json()
        .await
        .unwrap();
    assert_eq!(body["path"], "none");
    assert!(body["bias"].is_null());
    assert_eq!(
        body["unassociated_radar_tracks"].as_array().unwrap().len(),
        3
    );
    assert!(!body["warnings"].as_array().unwrap().is_empty());
    let response = app
        .post_json(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0}}),
        )
        .await;
    assert_eq!(response.status(), 200);
}

#[tokio::test]
async fn one_ship_is_associated_with_a_warning_that_the_bias_is_barely_determined() {
    let app = spawn_app().await;
    let (tracks, reports) = scene(1, &[true]);
    let body = app
        .post_ok(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0}, "radar_tracks": tracks, "ais_reports": reports}),
        )
        .await;
    assert_eq!(body["associations"].as_array().unwrap().len(), 1);
    assert_eq!(body["bias"]["pairs_used"], 1);
    let warnings = body["warnings"].as_array().unwrap();
    assert!(
        warnings
            .iter()
            .any(|w| w.as_str().unwrap().contains("rests on 1 associated ship")),
        "{warnings:?}"
    );
}

#[tokio::test]
async fn rest_reports_bad_nmea_lines_and_bad_fields() {
    let app = spawn_app().await;
    let (tracks, _) = scene(2, &[false; 2]);
    let response = app
        .post_json(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": LAT0, "lon_deg": LON0}, "radar_tracks": tracks,
                    "nmea": ["hello", "!AIVDM,1,1,,B,177KQJ5000G?tO`K>RA1wUbN0TKH,0*5C"]}),
        )
        .await;
    assert_eq!(response.status(), 200);
    let body: Value = response.json().await.unwrap();
    let errors = body["nmea"]["errors"].as_array().unwrap();
    // Line 0 is garbage; line 1 decodes but has no tag-block time.
    assert_eq!(errors[0]["line"], 0);
    assert_eq!(errors[1]["line"], 1);
    assert_eq!(body["nmea"]["positions"], 1);

    let response = app
        .post_json(
            "/v1/ais-radar/associate",
            &json!({"site": {"lat_deg": 95.0, "lon_deg": LON0},
                    "radar_tracks": [
                        {"id": "a", "samples": [{"t": 5.0, "range_m": 1000.0, "azimuth_deg": 10.0},
                                                {"t": 4.0, "range_m": 1000.0, "azimuth_deg": 10.0}]},
                        {"id": "b", "samples": [{"t": 1.0, "east_m": 1.0, "north_m": 2.0}]}],
                    "ais_reports": [{"mmsi": 1, "t": 0.0, "lat_deg": 37.0, "lon_deg": 200.0}],
                    "options": {"cfar_k": -1.0}}),
        )
        .await;
    let body = assert_problem(response, 422).await;
    let fields = problem_fields(&body);
    for f in [
        "site.lat_deg",
        "radar_tracks[0].samples[1].t",
        "radar_tracks[1].samples",
        "ais_reports[0].lon_deg",
        "options.cfar_k",
    ] {
        assert!(fields.contains(&f.to_string()), "{f} not in {fields:?}");
    }
}

fn grpc_sample(t: f64, range: f64, az: f64) -> pb::RadarSample {
    pb::RadarSample {
        t: Some(t),
        range_m: Some(range),
        azimuth_deg: Some(az),
        ..Default::default()
    }
}

#[tokio::test]
async fn grpc_associates_from_nmea_with_tag_blocks() {
    let app = spawn_app().await;
    let mut client = AisRadarServiceClient::connect(format!("http://{}", app.grpc_addr))
        .await
        .unwrap();
    let plane = LocalPlane::new(Ellipsoid::WGS84, LAT0.to_radians(), LON0.to_radians()).unwrap();
    let mut tracks = Vec::new();
    let mut nmea = Vec::new();
    for (k, s) in ships(5).iter().enumerate() {
        let t0 = times()[0];
        let mut samples = Vec::new();
        for &t in &times() {
            let at = |t: f64| [s.east + s.ve * (t - t0), s.north + s.vn * (t - t0)];
            let p = at(t);
            samples.push(grpc_sample(
                t,
                p[0].hypot(p[1]) + BIAS_RANGE_M,
                (p[0].atan2(p[1]).to_degrees() + BIAS_AZ_DEG).rem_euclid(360.0),
            ));
            // AIS as type 1 sentences (1/10000 minute ≈ 0.19 m resolution)
            // sent half a second after the radar sample; the tag block
            // truncates the receive time to the whole second t, which the
            // service takes at the middle of its second, t + 0.5.
            let (lat, lon) = plane.inverse(at(t + 0.5));
            let report = eval::ais::AisReport {
                t,
                mmsi: 235_000_000 + k as u32,
                lat_deg: lat.to_degrees(),
                lon_deg: lon.to_degrees(),
                sog_knots: 10.0,
                cog_deg: 0.0,
                target: k,
            };
            let tag = format!("c:{}", t as i64);
            nmea.push(format!(
                "\\{tag}*{:02X}\\{}",
                nmea_checksum(&tag),
                PositionReport::from_report(&report).sentence('A')
            ));
        }
        tracks.push(pb::RadarTrack {
            id: format!("r{k}"),
            samples,
        });
    }
    let out = client
        .associate(pb::AssociateRequest {
            site: Some(pb::RadarSite {
                lat_deg: Some(LAT0),
                lon_deg: Some(LON0),
            }),
            radar_tracks: tracks,
            nmea,
            ..Default::default()
        })
        .await
        .unwrap()
        .into_inner();
    assert_eq!(out.associations.len(), 5);
    assert!(
        out.associations
            .iter()
            .all(|a| a.mmsi - 235_000_000 == a.radar_track_id[1..].parse::<u32>().unwrap())
    );
    let b = out.bias.unwrap();
    // Positions are quantised to ~0.2 m, so the estimate is good to ~0.1 m.
    assert!((b.range_m - BIAS_RANGE_M).abs() < 0.5, "{}", b.range_m);
    assert!((b.azimuth_deg - BIAS_AZ_DEG).abs() < 0.01);
    assert_eq!(out.nmea.unwrap().positions, 75);
    assert!(out.timing.is_some());
    let q = out.quality.unwrap();
    assert!(
        q.reliable && !q.at_bound && !q.ambiguous && !q.inconsistent,
        "{q:?}"
    );
}

#[tokio::test]
async fn grpc_bad_input_names_the_field() {
    let app = spawn_app().await;
    let mut client = AisRadarServiceClient::connect(format!("http://{}", app.grpc_addr))
        .await
        .unwrap();
    let status = client
        .associate(pb::AssociateRequest {
            site: Some(pb::RadarSite {
                lat_deg: Some(f64::NAN),
                lon_deg: Some(LON0),
            }),
            radar_tracks: vec![pb::RadarTrack {
                id: "x".into(),
                samples: vec![grpc_sample(0.0, 1000.0, 5.0)],
            }],
            ..Default::default()
        })
        .await
        .unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument);
    let fields: Vec<String> = status
        .get_details_bad_request()
        .unwrap()
        .field_violations
        .into_iter()
        .map(|v| v.field)
        .collect();
    assert!(fields.contains(&"site.lat_deg".to_string()), "{fields:?}");
    assert!(
        fields.contains(&"radar_tracks[0].samples".to_string()),
        "{fields:?}"
    );
}

#[tokio::test]
async fn health_reports_the_ais_radar_service() {
    use tonic_health::pb::{HealthCheckRequest, health_client::HealthClient};
    let app = spawn_app().await;
    let mut health = HealthClient::new(app.channel().await);
    let response = health
        .check(HealthCheckRequest {
            service: "radar.fusion.v1.AisRadarService".into(),
        })
        .await
        .unwrap()
        .into_inner();
    // 1 = SERVING.
    assert_eq!(response.status, 1);
}
