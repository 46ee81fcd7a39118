//! ASTERIX input of the plot-fusion tracker (issue 19): the decoder
//! against an independent encoder's fixture, field for field; the same
//! scene as JSON plots and as ASTERIX giving the same tracks; the batch
//! call over REST and gRPC, sessions, bad input, and the UDP listener.
//!
//! The fixture (`tests/fixtures/asterix/scene.{bin,json}`) is written by
//! `checks/asterix_fixture.py` with libasterix (PyPI): the expected values
//! are that library's decoding, converted to SI there (1 NM = 1852 m,
//! 1 ft = 0.3048 m).

use base64::Engine as _;
use radar_fusion::proto::{self as pb, plot_fusion_service_client::PlotFusionServiceClient};
use serde_json::{Value, json};
use service::plot_fusion::{self as svc, asterix::AsterixInput};
use wire_formats::asterix;

use crate::helpers::{assert_problem, problem_fields, spawn_app, spawn_app_with};

const SCENE_BIN: &[u8] = include_bytes!("../fixtures/asterix/scene.bin");
const SCENE_BIASED_BIN: &[u8] = include_bytes!("../fixtures/asterix/scene_biased.bin");
const SCENE_JSON: &str = include_str!("../fixtures/asterix/scene.json");
/// The fixture's first record is on 2026-12-01 (Unix day 20,788); its
/// times of day run past midnight into 2026-12-02.
const DATE: &str = "2026-12-01";
const DAY_START: f64 = 20_788.0 * 86_400.0;

fn expected() -> Value {
    serde_json::from_str(SCENE_JSON).expect("fixture JSON")
}

fn opt_f64(v: &Value) -> Option<f64> {
    v.as_f64()
}

#[test]
fn the_fixture_decodes_field_for_field_as_libasterix_decodes_it() {
    let want = expected();
    let got = asterix::decode(SCENE_BIN);
    assert!(got.errors.is_empty(), "{:?}", got.errors);
    let records = want["records"].as_array().unwrap();
    let n48 = records.iter().filter(|r| r["category"] == 48).count();
    let n34 = records.len() - n48;
    assert_eq!(got.target_reports.len(), n48);
    assert_eq!(got.service_messages.len(), n34);
    let (mut i48, mut i34) = (0, 0);
    for r in records {
        let offset = r["offset"].as_u64().unwrap() as usize;
        let source = Some((
            r["sac"].as_u64().unwrap() as u8,
            r["sic"].as_u64().unwrap() as u8,
        ));
        let tod = opt_f64(&r["time_of_day_s"]);
        if r["category"] == 34 {
            let m = &got.service_messages[i34];
            i34 += 1;
            assert_eq!(m.offset, offset);
            assert_eq!(m.source, source);
            assert_eq!(m.time_of_day_s, tod);
            assert_eq!(m.message_type, r["message_type"].as_u64().map(|x| x as u8));
            assert_eq!(m.sector_deg, opt_f64(&r["sector_deg"]));
            assert_eq!(m.rotation_period_s, opt_f64(&r["rotation_period_s"]));
            continue;
        }
        let t = &got.target_reports[i48];
        i48 += 1;
        let at = format!("record at {offset}");
        assert_eq!(t.offset, offset, "{at}");
        assert_eq!(t.source, source, "{at}");
        assert_eq!(t.time_of_day_s, tod, "{at}");
        let d = t.descriptor.expect("I048/020");
        assert_eq!(u64::from(d.typ), r["typ"].as_u64().unwrap(), "{at}");
        assert_eq!(d.sim, r["sim"] == 1, "{at}");
        assert_eq!(d.tst, r["tst"].as_u64().map(|x| x == 1), "{at}");
        // Exact: RHO·1852/256 and THETA·360/2¹⁶ are exact in binary.
        assert_eq!(t.range_m, opt_f64(&r["rho_m"]), "{at}");
        assert_eq!(t.azimuth_deg, opt_f64(&r["theta_deg"]), "{at}");
        assert_eq!(
            t.mode_3a.map(|c| format!("{c:04o}")),
            r["mode_3a"].as_str().map(str::to_string),
            "{at}"
        );
        assert_eq!(t.flight_level, opt_f64(&r["flight_level"]), "{at}");
        assert_eq!(t.height_m, opt_f64(&r["height_m"]), "{at}");
        assert_eq!(t.doppler_mps, opt_f64(&r["doppler_mps"]), "{at}");
        assert_eq!(
            t.aircraft_address.map(u64::from),
            r["aircraft_address"].as_u64(),
            "{at}"
        );
        assert_eq!(
            t.track_number.map(u64::from),
            r["track_number"].as_u64(),
            "{at}"
        );
    }
    // The fixture exercises what it claims to.
    let has = |k: &str| records.iter().any(|r| !r[k].is_null());
    for k in [
        "height_m",
        "doppler_mps",
        "mode_3a",
        "flight_level",
        "track_number",
    ] {
        assert!(has(k), "{k}");
    }
    assert!(
        records
            .iter()
            .any(|r| r["doppler_mps"].as_f64() < Some(0.0))
    );
    assert!(records.iter().any(|r| r["tst"] == 1));
}

/// The fixture's two radars as the request declares them: A (25/1) 2D,
/// B (25/2) 3D with Doppler, local sites 40 km apart.
fn radars() -> Value {
    json!([
        {"id": "a", "kind": "2d", "site": {"position_m": [-20000.0, 0.0]},
         "sigma_range_m": 60.0, "sigma_azimuth_deg": 0.08, "scan_period_s": 4.0,
         "sac": 25, "sic": 1},
        {"id": "b", "kind": "3d", "site": {"position_m": [20000.0, 0.0]},
         "sigma_range_m": 60.0, "sigma_azimuth_deg": 0.08, "sigma_elevation_deg": 0.2,
         "sigma_radial_velocity_mps": 2.0, "scan_period_s": 5.0, "sac": 25, "sic": 2}
    ])
}

fn tracker() -> Value {
    json!({"default_height_m": 3000.0})
}

/// The scene as JSON plots, from libasterix's decoding: the time of day
/// plus the date, plus a day when it falls far below the record before
/// (the roll-over); radar B's elevation from its measured height over its
/// site (height 0): sin ε = h/ρ.
fn json_plots() -> Vec<Value> {
    let want = expected();
    let mut out = Vec::new();
    let mut day = DAY_START;
    let mut previous = f64::NEG_INFINITY;
    for r in want["records"].as_array().unwrap() {
        if r["category"] != 48 || r["tst"] == 1 || r["sic"] == 9 {
            continue;
        }
        let tod = r["time_of_day_s"].as_f64().unwrap();
        if tod < previous - 43_200.0 {
            day += 86_400.0;
        }
        previous = tod;
        let rho = r["rho_m"].as_f64().unwrap();
        let mut p = json!({
            "radar_id": if r["sic"] == 1 { "a" } else { "b" },
            "t": day + tod, "range_m": rho, "azimuth_deg": r["theta_deg"],
        });
        if r["sic"] == 2 {
            let h = r["height_m"].as_f64().unwrap();
            p["elevation_deg"] = json!((h / rho).asin().to_degrees());
            p["radial_velocity_mps"] = r["doppler_mps"].clone();
        }
        // The secondary fields as libasterix decoded them (the fixture's
        // replies are validated and ungarbled).
        if let Some(code) = r["mode_3a"].as_str() {
            p["mode_3a"] = json!(code);
        }
        if let Some(fl) = r["flight_level"].as_f64() {
            p["flight_level"] = json!(fl);
        }
        if let Some(a) = r["aircraft_address"].as_u64() {
            p["mode_s_address"] = json!(format!("{a:06X}"));
        }
        let detection = match r["typ"].as_u64() {
            Some(1) => Some("primary"),
            Some(2 | 4 | 5) => Some("secondary"),
            Some(3 | 6 | 7) => Some("combined"),
            _ => None,
        };
        if let Some(d) = detection {
            p["detection"] = json!(d);
        }
        out.push(p);
    }
    out
}

fn b64(data: &[u8]) -> String {
    base64::engine::general_purpose::STANDARD.encode(data)
}

/// The ASTERIX fixture scene as a batch request for CAT062 out (an origin
/// for WGS-84 positions, the fusion centre's SAC/SIC).
pub(crate) fn cat062_request() -> Value {
    json!({"radars": radars(), "tracker": tracker(),
           "origin": {"lat_deg": 47.45, "lon_deg": 8.56, "height_m": 0.0},
           "asterix": {"data": b64(SCENE_BIN), "date": DATE},
           "cat062": {"sac": 25, "sic": 200, "service_id": 7}})
}

#[tokio::test]
async fn the_scene_as_asterix_gives_the_tracks_of_the_scene_as_json_plots() {
    let app = spawn_app().await;
    let from_json = app
        .post_ok(
            "/v1/plot-fusion/track",
            &json!({"radars": radars(), "plots": json_plots(), "tracker": tracker()}),
        )
        .await;
    let from_asterix = app
        .post_ok(
            "/v1/plot-fusion/track",
            &json!({"radars": radars(), "tracker": tracker(),
                    "asterix": {"data": b64(SCENE_BIN), "date": DATE}}),
        )
        .await;
    assert_eq!(from_asterix["tracks"], from_json["tracks"]);
    assert_eq!(from_asterix["deleted"], from_json["deleted"]);
    assert_eq!(from_asterix["counters"], from_json["counters"]);
    let confirmed = from_json["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .count();
    assert_eq!(confirmed, 3, "{}", from_json["tracks"]);
    // The roll-over: the last track time is after midnight of 2026-12-01.
    let a = &from_asterix["asterix"];
    assert!(a["last_t"].as_f64().unwrap() > DAY_START + 86_400.0, "{a}");
    assert!(a["first_t"].as_f64().unwrap() < DAY_START + 86_400.0, "{a}");
    // Counts, from the fixture: every CAT034 record is a north marker or a
    // sector crossing; one test target, one report of the unknown 25/9.
    let want = expected();
    let records = want["records"].as_array().unwrap();
    let count = |f: &dyn Fn(&Value) -> bool| records.iter().filter(|r| f(r)).count();
    assert_eq!(a["records"], records.len());
    assert_eq!(a["plots"], json_plots().len());
    assert_eq!(a["north_markers"], count(&|r| r["message_type"] == 1));
    assert_eq!(a["sector_crossings"], count(&|r| r["message_type"] == 2));
    assert_eq!(a["unmapped"], 1);
    assert_eq!(a["test_targets"], 1);
    assert_eq!(a["incomplete"], 0);
    assert_eq!(a["errors"], json!([]));
    let warnings = from_asterix["warnings"].to_string();
    assert!(warnings.contains("25/9"), "{warnings}");
}

#[tokio::test]
async fn grpc_takes_asterix_bytes_and_gives_the_rest_answer() {
    let app = spawn_app().await;
    let rest = app
        .post_ok(
            "/v1/plot-fusion/track",
            &json!({"radars": radars(), "tracker": tracker(),
                    "asterix": {"data": b64(SCENE_BIN), "day_start_t": DAY_START}}),
        )
        .await;
    let mut client = PlotFusionServiceClient::new(app.channel().await);
    let radar = |id: &str, kind: &str, x: f64, period: f64, sic: u32| pb::PlotRadar {
        id: id.into(),
        kind: kind.into(),
        site: Some(pb::PlotRadarSite {
            position_m: vec![x, 0.0],
            ..Default::default()
        }),
        sigma_range_m: Some(60.0),
        sigma_azimuth_deg: Some(0.08),
        sigma_elevation_deg: (kind == "3d").then_some(0.2),
        sigma_radial_velocity_mps: (kind == "3d").then_some(2.0),
        scan_period_s: Some(period),
        sac: Some(25),
        sic: Some(sic),
        bias: None,
        ..Default::default()
    };
    let out = client
        .track(pb::PlotFusionRequest {
            radars: vec![
                radar("a", "2d", -20000.0, 4.0, 1),
                radar("b", "3d", 20000.0, 5.0, 2),
            ],
            tracker: Some(pb::TrackerOptions {
                default_height_m: Some(3000.0),
                ..Default::default()
            }),
            asterix: Some(pb::AsterixData {
                data: SCENE_BIN.to_vec(),
                date: Some(DATE.into()),
                day_start_t: None,
            }),
            ..Default::default()
        })
        .await
        .expect("gRPC track")
        .into_inner();
    let rest_tracks = rest["tracks"].as_array().unwrap();
    assert_eq!(out.tracks.len(), rest_tracks.len());
    for (g, r) in out.tracks.iter().zip(rest_tracks) {
        assert_eq!(g.id, r["id"].as_u64().unwrap());
        let state: Vec<f64> = r["state"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(g.state, state);
    }
    let a = out.asterix.expect("asterix summary");
    assert_eq!(a.plots, rest["asterix"]["plots"].as_u64().unwrap());
    assert_eq!(a.unmapped, 1);
    assert!(a.errors.is_empty());
}

#[tokio::test]
async fn bad_asterix_is_listed_by_offset_and_bad_fields_are_named() {
    let app = spawn_app().await;
    // The scene cut in its middle, then garbage of an unknown category.
    let cut = SCENE_BIN.len() / 2;
    let mut data = SCENE_BIN[..cut].to_vec();
    data.extend_from_slice(&[0x07, 0x00, 0x05, 0xAA, 0xBB]);
    let out = app
        .post_ok(
            "/v1/plot-fusion/track",
            &json!({"radars": radars(), "tracker": tracker(),
                    "asterix": {"data": b64(&data), "date": DATE}}),
        )
        .await;
    let errors = out["asterix"]["errors"].as_array().unwrap();
    assert!(!errors.is_empty());
    assert!(
        errors
            .iter()
            .all(|e| (e["offset"].as_u64().unwrap() as usize) < data.len())
    );
    assert!(out["asterix"]["plots"].as_u64().unwrap() > 0);
    assert!(out["warnings"].to_string().contains("ASTERIX error"));

    let bad = |asterix: Value, radars: Value| json!({"radars": radars, "tracker": tracker(), "asterix": asterix});
    for (body, field) in [
        (
            bad(json!({"data": "not base64!", "date": DATE}), radars()),
            "asterix.data",
        ),
        (
            bad(json!({"data": b64(SCENE_BIN)}), radars()),
            "asterix.date",
        ),
        (
            bad(json!({"data": "", "date": "2026-02-30"}), radars()),
            "asterix.date",
        ),
        (
            bad(
                json!({"data": "", "date": DATE, "day_start_t": 0.0}),
                radars(),
            ),
            "asterix.day_start_t",
        ),
        (
            {
                let mut r = radars();
                r[1]["sic"] = json!(1);
                bad(json!({"data": "", "date": DATE}), r)
            },
            "radars[1].sic",
        ),
        (
            {
                let mut r = radars();
                r[0]["sac"] = json!(256);
                bad(json!({"data": "", "date": DATE}), r)
            },
            "radars[0].sac",
        ),
        (
            {
                let mut r = radars();
                r[0].as_object_mut().unwrap().remove("sic");
                bad(json!({"data": "", "date": DATE}), r)
            },
            "radars[0].sic",
        ),
    ] {
        let problem =
            assert_problem(app.post_json("/v1/plot-fusion/track", &body).await, 422).await;
        assert!(
            problem_fields(&problem).contains(&field.to_string()),
            "{field}: {problem}"
        );
    }
}

#[test]
fn a_session_fed_asterix_in_two_batches_gives_the_batch_calls_tracks() {
    let spec = || svc::SpecInput {
        radars: serde_json_radars(),
        tracker: svc::TrackerInput {
            default_height_m: Some(3000.0),
            ..Default::default()
        },
        ..Default::default()
    };
    let whole = svc::track(svc::TrackInput {
        spec: spec(),
        plots: Vec::new(),
        nmea: None,
        asterix: Some(AsterixInput {
            data: SCENE_BIN.to_vec(),
            date: Some(DATE.into()),
            ..Default::default()
        }),
        history: false,
    })
    .unwrap();
    // Cut at a data block boundary; the second batch has no date: its
    // times of day are taken nearest to the session's last frame.
    let cut = block_boundary_near(SCENE_BIN.len() / 2);
    use service::session::{
        Limits, SessionKind,
        plot_fusion::{BatchInput, PlotFusionSession},
    };
    let limits = Limits {
        max_tracks: 100,
        max_batch_reports: 10_000,
    };
    let mut session = PlotFusionSession::create(spec(), &mut Vec::new()).unwrap();
    let mut warnings = Vec::new();
    for (i, part) in [&SCENE_BIN[..cut], &SCENE_BIN[cut..]]
        .into_iter()
        .enumerate()
    {
        let update = session
            .apply(
                &BatchInput {
                    plots: Vec::new(),
                    nmea: None,
                    asterix: Some(AsterixInput {
                        data: part.to_vec(),
                        date: (i == 0).then(|| DATE.to_string()),
                        ..Default::default()
                    }),
                    flush: i == 1,
                },
                &limits,
                &mut warnings,
            )
            .unwrap();
        assert_eq!(update.asterix.unwrap().late, 0);
    }
    let view = session.view().unwrap();
    assert_eq!(view.tracks, whole.tracks);
    assert_eq!(view.counters, whole.counters);
}

/// The request's radars as service inputs (the same as [`radars`]).
fn serde_json_radars() -> Vec<svc::RadarInput> {
    radars()
        .as_array()
        .unwrap()
        .iter()
        .map(|r| svc::RadarInput {
            id: r["id"].as_str().map(str::to_string),
            kind: r["kind"].as_str().map(str::to_string),
            site: Some(svc::SiteInput {
                geodetic: None,
                position_m: Some(
                    r["site"]["position_m"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|x| x.as_f64().unwrap())
                        .collect(),
                ),
            }),
            sigma_range_m: r["sigma_range_m"].as_f64(),
            sigma_azimuth_deg: r["sigma_azimuth_deg"].as_f64(),
            sigma_elevation_deg: r["sigma_elevation_deg"].as_f64(),
            sigma_radial_velocity_mps: r["sigma_radial_velocity_mps"].as_f64(),
            scan_period_s: r["scan_period_s"].as_f64(),
            sac: r["sac"].as_u64().map(|x| x as u32),
            sic: r["sic"].as_u64().map(|x| x as u32),
            ..Default::default()
        })
        .collect()
}

/// The data blocks of the scene (CAT, LEN), in order.
fn blocks() -> Vec<&'static [u8]> {
    blocks_of(SCENE_BIN)
}

fn blocks_of(data: &'static [u8]) -> Vec<&'static [u8]> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < data.len() {
        let len = u16::from_be_bytes([data[pos + 1], data[pos + 2]]) as usize;
        out.push(&data[pos..pos + len]);
        pos += len;
    }
    out
}

fn block_boundary_near(at: usize) -> usize {
    let mut pos = 0;
    for b in blocks() {
        if pos + b.len() > at {
            break;
        }
        pos += b.len();
    }
    pos
}

#[tokio::test]
async fn a_rest_session_batch_takes_asterix_and_reports_it() {
    let app = spawn_app().await;
    let created = app
        .post_json(
            "/v1/sessions",
            &json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker()}),
        )
        .await;
    assert_eq!(created.status(), 201);
    let id = created.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let out = app
        .post_ok(
            &format!("/v1/sessions/{id}/batches"),
            &json!({"sequence": 1, "flush": true,
                    "asterix": {"data": b64(SCENE_BIN), "date": DATE}}),
        )
        .await;
    let a = &out["plot_fusion"]["asterix"];
    assert_eq!(a["plots"], json_plots().len(), "{out}");
    assert_eq!(a["unmapped"], 1);
    let view = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let confirmed = confirmed_in(&view);
    assert_eq!(confirmed, 3, "{view}");
    // A session batch without a date, before any frame, is refused by name.
    let created = app
        .post_json(
            "/v1/sessions",
            &json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker()}),
        )
        .await;
    let id = created.json::<Value>().await.unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let problem = assert_problem(
        app.post_json(
            &format!("/v1/sessions/{id}/batches"),
            &json!({"asterix": {"data": b64(SCENE_BIN)}}),
        )
        .await,
        422,
    )
    .await;
    assert_eq!(problem_fields(&problem), vec!["asterix.date".to_string()]);
}

/// A server whose UDP listener feeds a session created from `spec`, the
/// data blocks of `data` sent to it one per datagram, as a radar sends
/// them; returns once the session counts `plots` plots (bounded wait, not
/// a timed assertion), with the `/metrics` text from before the first
/// datagram and the number of datagrams.
async fn feed_the_listener(
    spec: Value,
    data: &'static [u8],
    plots: usize,
) -> (crate::helpers::TestApp, String, usize) {
    // A recording: its times are days from now, so the listener's clock
    // check (`--asterix-max-clock-offset-s`) is off.
    let all = blocks_of(data).into_iter().map(<[u8]>::to_vec).collect();
    feed_datagrams(spec, all, plots, 0.0, &[]).await
}

/// [`feed_the_listener`] with datagrams of one's own, the listener's
/// clock check at `max_clock_offset_s` and its sources `allow`.
async fn feed_datagrams(
    spec: Value,
    all: Vec<Vec<u8>>,
    plots: usize,
    max_clock_offset_s: f64,
    allow: &[&str],
) -> (crate::helpers::TestApp, String, usize) {
    // A free port: bound and released (the listener binds it next).
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let dir = std::env::temp_dir().join(format!("asterix-udp-{}-{port}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec_path = dir.join("session.json");
    std::fs::write(&spec_path, spec.to_string()).unwrap();
    let addr: std::net::SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let app = spawn_app_with(|s| {
        s.asterix_udp = Some(addr);
        s.asterix_session_spec = Some(spec_path.clone());
        s.asterix_max_clock_offset_s = max_clock_offset_s;
        s.asterix_allow = allow.iter().map(|a| a.to_string()).collect();
    })
    .await;
    std::fs::remove_dir_all(&dir).ok();
    let before = app.metrics_text().await;
    let sender = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for b in &all {
        sender.send_to(b, addr).unwrap();
    }
    let mut counted = 0;
    for _ in 0..500 {
        let view = app
            .get_ok(&format!("/v1/sessions/{LISTENER_SESSION}"))
            .await;
        // Counted when accepted, buffered ones included.
        counted = view["plot_fusion"]["counters"]["plots"].as_u64().unwrap();
        if counted as usize >= plots {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert_eq!(counted as usize, plots);
    (app, before, all.len())
}

/// One radar's clock jumps 6 h ahead for one datagram (a glitch, or a
/// forged packet): the listener's clock check (60 s, the default) refuses
/// that report, so the session's newest time and lag horizon do not move,
/// and the good plots after it are kept, none late. (With the check off
/// the report is accepted as a seventh plot, 6 h ahead: every plot after
/// it in a later batch would be late.)
#[tokio::test]
async fn a_datagram_hours_ahead_is_refused_and_moves_nothing() {
    use eval::asterix048::{Report, block, time_of_day};
    let _one_at_a_time = UDP_TESTS.lock().await;
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs_f64();
    // Radar a (SAC 25, SIC 1, 20 km west of the centre): an aircraft 30 km
    // east of it moving away at 25 m/s, a plot every 4-s scan, the last 4 s
    // before now.
    let report = |t: f64, k: usize| Report {
        sac: 25,
        sic: 1,
        time_of_day_s: time_of_day(t),
        range_m: 30_000.0 + 100.0 * k as f64,
        azimuth_deg: 90.0,
    };
    let good: Vec<Vec<u8>> = (0..6)
        .map(|k| block(&[report(now - 24.0 + 4.0 * k as f64, k)]).unwrap())
        .collect();
    let ahead = block(&[report(now + 6.0 * 3600.0, 3)]).unwrap();
    let mut datagrams = good[..3].to_vec();
    datagrams.push(ahead);
    datagrams.extend_from_slice(&good[3..]);
    let spec = json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker()});
    let (app, before, _) = feed_datagrams(spec, datagrams, 6, 60.0, &[]).await;
    let view = app
        .get_ok(&format!("/v1/sessions/{LISTENER_SESSION}"))
        .await;
    assert_eq!(view["plot_fusion"]["counters"]["late"], 0, "{view}");
    let metrics = app.metrics_text().await;
    let value = |name: &str| counter(&metrics, name) - counter(&before, name);
    assert_eq!(value("fusion_asterix_records_total"), 7);
    assert_eq!(value("fusion_asterix_plots_total"), 6);
    assert_eq!(value("fusion_asterix_decode_errors_total"), 1);
}

/// A listener that takes datagrams from 10.0.0.0/8 only refuses those of
/// 127.0.0.1 (counted), and its session receives nothing.
#[tokio::test]
async fn a_listener_refuses_datagrams_from_sources_it_does_not_allow() {
    let _one_at_a_time = UDP_TESTS.lock().await;
    let spec = json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker()});
    let all: Vec<Vec<u8>> = blocks_of(SCENE_BIN)
        .into_iter()
        .map(<[u8]>::to_vec)
        .collect();
    let sent = all.len() as u64;
    let (app, before, _) = feed_datagrams(spec, all, 0, 0.0, &["10.0.0.0/8"]).await;
    let mut refused = 0;
    for _ in 0..500 {
        let metrics = app.metrics_text().await;
        refused = counter(&metrics, "fusion_asterix_refused_datagrams_total")
            - counter(&before, "fusion_asterix_refused_datagrams_total");
        if refused >= sent {
            break;
        }
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
    }
    assert_eq!(refused, sent);
    let view = app
        .get_ok(&format!("/v1/sessions/{LISTENER_SESSION}"))
        .await;
    assert_eq!(view["plot_fusion"]["counters"]["plots"], 0, "{view}");
}

/// The session the listener creates (its id is fixed by the listener).
const LISTENER_SESSION: &str = "00000000000000000000000000000048";

#[tokio::test]
async fn the_udp_listener_feeds_its_session_from_datagrams_on_loopback() {
    let _one_at_a_time = UDP_TESTS.lock().await;
    let spec = json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker()});
    let (app, before, datagrams) = feed_the_listener(spec, SCENE_BIN, json_plots().len()).await;
    let view = app
        .get_ok(&format!("/v1/sessions/{LISTENER_SESSION}"))
        .await;
    let confirmed = confirmed_in(&view);
    assert_eq!(confirmed, 3, "{view}");
    let metrics = app.metrics_text().await;
    let value = |name: &str| counter(&metrics, name) - counter(&before, name);
    assert_eq!(value("fusion_asterix_datagrams_total") as usize, datagrams);
    let records = expected()["records"].as_array().unwrap().len();
    assert_eq!(value("fusion_asterix_records_total") as usize, records);
    assert_eq!(value("fusion_asterix_decode_errors_total"), 0);
    // Every applied batch observed once in the latency histogram: at
    // least one batch, at most one per datagram (their sizes depend on
    // how the datagrams met the pushes, so only the bounds are asserted).
    let batches = value("fusion_asterix_latency_seconds_count") as usize;
    assert!((1..=datagrams).contains(&batches), "{batches} batches");
    assert!(
        metrics.contains("fusion_asterix_latency_seconds_bucket{le=\"1\"}"),
        "{metrics}"
    );
}

/// Radar B of the scene biased by +300 m and +0.3° (`scene_biased.bin`,
/// written by libasterix from the same draws): through the listener, with
/// radar A the reference, B's bias is estimated within 3σ (plus a few
/// metres of the first-order model: I048/110 gives a height, so the
/// elevation the tracker derives from the biased range is itself off by
/// up to 0.1°), the three aircraft stay three tracks, and `/metrics`
/// shows the estimate.
#[tokio::test]
async fn the_udp_listener_registers_a_biased_radar() {
    let _one_at_a_time = UDP_TESTS.lock().await;
    let mut t = tracker();
    t["registration"] = json!({"reference": ["a"]});
    let spec = json!({"kind": "plot_fusion", "radars": radars(), "tracker": t});
    let (app, _, _) = feed_the_listener(spec, SCENE_BIASED_BIN, json_plots().len()).await;
    let view = app
        .get_ok(&format!("/v1/sessions/{LISTENER_SESSION}"))
        .await;
    assert_eq!(confirmed_in(&view), 3, "{view}");
    let reg = view["plot_fusion"]["registration"].as_array().unwrap();
    assert_eq!(reg.len(), 2);
    assert_eq!(reg[0]["reference"], true);
    let b = &reg[1];
    assert_eq!(b["converged"], true, "{b}");
    let f = |v: &Value| v.as_f64().unwrap();
    assert!(
        (f(&b["range_m"]) - 300.0).abs() < 3.0 * f(&b["sigma_range_m"]) + 15.0,
        "{b}"
    );
    assert!(
        (f(&b["azimuth_deg"]) - 0.3).abs() < 3.0 * f(&b["sigma_azimuth_deg"]) + 0.01,
        "{b}"
    );
    let metrics = app.metrics_text().await;
    let shown = crate::helpers::radar_gauge(
        &metrics,
        "fusion_session_radar_range_bias_metres",
        LISTENER_SESSION,
        "b",
    );
    assert_eq!(shown, Some(f(&b["range_m"])), "{metrics}");
}

/// The UDP listener tests run one at a time: the metrics recorder is one
/// per process, so each counts its own datagrams as a difference.
static UDP_TESTS: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// A counter's value in a `/metrics` text (0 before its first increment).
fn counter(metrics: &str, name: &str) -> u64 {
    metrics
        .lines()
        .find(|l| l.starts_with(name))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

/// Confirmed tracks in a plot_fusion session's view.
fn confirmed_in(view: &Value) -> usize {
    view["plot_fusion"]["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .count()
}

#[tokio::test]
async fn asterix_in_gives_cat062_datagrams_out_on_loopback() {
    let _one_at_a_time = UDP_TESTS.lock().await;
    let dir = std::env::temp_dir().join(format!("asterix-out-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let spec_path = dir.join("session.json");
    // The radars' local sites about an origin (for I062/105), the fusion
    // centre's SAC/SIC, blocks of at most 200 bytes in datagrams of 400.
    std::fs::write(
        &spec_path,
        json!({"kind": "plot_fusion", "radars": radars(), "tracker": tracker(),
               "origin": {"lat_deg": 47.45, "lon_deg": 8.56, "height_m": 0.0},
               "cat062": {"sac": 25, "sic": 200, "max_block_bytes": 200}})
        .to_string(),
    )
    .unwrap();
    let receiver = tokio::net::UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let out = receiver.local_addr().unwrap();
    let port = std::net::UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let addr: std::net::SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
    let app = spawn_app_with(|s| {
        s.asterix_udp = Some(addr);
        s.asterix_session_spec = Some(spec_path.clone());
        s.asterix_out_udp = Some(out);
        s.asterix_out_max_datagram = 400;
        // A recording: no clock check.
        s.asterix_max_clock_offset_s = 0.0;
    })
    .await;
    let before = app.metrics_text().await;
    let sender = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for b in blocks() {
        sender.send_to(b, addr).unwrap();
    }
    // Read datagrams until the last record of each confirmed track of the
    // session's view has the view's state (bounded wait).
    let id = "00000000000000000000000000000048";
    let mut last: std::collections::HashMap<u16, crate::cat062::Record> = Default::default();
    let mut datagrams = 0u64;
    let mut records = 0usize;
    let mut buf = vec![0u8; 65_536];
    let mut done = false;
    for _ in 0..400 {
        while let Ok(Ok(n)) = tokio::time::timeout(
            std::time::Duration::from_millis(20),
            receiver.recv(&mut buf),
        )
        .await
        {
            assert!(n <= 400, "datagram of {n} bytes");
            datagrams += 1;
            for r in crate::cat062::decode(&buf[..n]) {
                assert_eq!(r.sac_sic, Some((25, 200)));
                records += 1;
                last.insert(r.track_number.unwrap(), r);
            }
        }
        let view = app.get_ok(&format!("/v1/sessions/{id}")).await;
        let tracks = view["plot_fusion"]["tracks"].as_array().unwrap().clone();
        let confirmed: Vec<&Value> = tracks
            .iter()
            .filter(|t| t["status"] == "confirmed")
            .collect();
        let plots = view["plot_fusion"]["counters"]["plots"].as_u64().unwrap();
        if plots as usize >= json_plots().len()
            && confirmed.len() == 3
            && confirmed.iter().all(|t| {
                last.get(&((t["id"].as_u64().unwrap() % 65_536) as u16))
                    .is_some_and(|r| {
                        r.xy.unwrap().0 == (t["state"][0].as_f64().unwrap() * 2.0).round() / 2.0
                    })
            })
        {
            for t in &confirmed {
                let r = &last[&((t["id"].as_u64().unwrap() % 65_536) as u16)];
                crate::cat062::assert_matches(r, t, (25, 200));
            }
            done = true;
            break;
        }
    }
    assert!(
        done,
        "the session's confirmed tracks did not all arrive as CAT062"
    );
    // Every datagram sent has arrived once the socket stays quiet (no
    // input is left to push).
    while let Ok(Ok(n)) = tokio::time::timeout(
        std::time::Duration::from_millis(300),
        receiver.recv(&mut buf),
    )
    .await
    {
        datagrams += 1;
        records += crate::cat062::decode(&buf[..n]).len();
    }
    let metrics = app.metrics_text().await;
    let value = |name: &str| counter(&metrics, name) - counter(&before, name);
    assert_eq!(value("fusion_cat062_datagrams_total"), datagrams);
    assert_eq!(value("fusion_cat062_records_total") as usize, records);
    std::fs::remove_dir_all(&dir).ok();
}
