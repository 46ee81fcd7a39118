//! Cooperative reports through the real servers: ADS-B beside Mode S
//! radars on REST, gRPC and a session; one track per aircraft, its
//! sources, a spoofed ADS-B flagged with a warning; bad report fields
//! named on both transports.

use serde_json::{Value, json};
use tonic::Code;

use crate::helpers::{assert_problem, grpc_fields, problem_fields, spawn_app};
use crate::plot_fusion::plot_scene::{
    ORIGIN, origin_frame, plots_tagged, radars_json, targets, two_radars,
};
use crate::plot_fusion::{create_session, proto_report, proto_request, session_create};
use radar_fusion::proto as pb;
use radar_fusion::proto::plot_fusion_service_client::PlotFusionServiceClient;

const PATH: &str = "/v1/plot-fusion/track";
const ADDRESSES: [&str; 3] = ["4CA2D1", "3C6586", "A1B2C3"];
/// Target 1's ADS-B is 3 km north of it from this time on (spoofed).
const SPOOF_FROM: f64 = 60.0;
const SPOOF_M: f64 = 3000.0;

/// ADS-B reports of each target every second of its life (offset by
/// 0.1 s per target), NACp 9 (σ 12 m) but without noise, NACv 2, with its
/// address and flight level; target 1's moved 3 km north from
/// [`SPOOF_FROM`].
fn adsb(duration: f64) -> Vec<Value> {
    let frame = origin_frame();
    let mut out = Vec::new();
    for (i, g) in targets().iter().enumerate() {
        let mut t = g.start.max(0.0) + 0.1 * i as f64;
        while t <= duration.min(g.end) {
            let p = g.at(t);
            let north = if i == 1 && t >= SPOOF_FROM {
                SPOOF_M
            } else {
                0.0
            };
            let (lat, lon, h) = frame.enu_to_geodetic([p[0], p[1] + north, p[2]]).unwrap();
            out.push(json!({
                "source": "adsb", "t": t,
                "lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees(),
                "geometric_height_m": h,
                "velocity_east_mps": g.v[0], "velocity_north_mps": g.v[1],
                "nacp": 9, "nacv": 2,
                "mode_s_address": ADDRESSES[i], "flight_level": 262.5,
            }));
            t += 1.0;
        }
    }
    out
}

/// Two 2D Mode S radars (every target plot carries its address) and the
/// targets' ADS-B.
fn request(duration: f64) -> Value {
    let radars = two_radars(false);
    let tag = |i: usize, _t: f64| {
        Some(
            json!({"mode_s_address": ADDRESSES[i], "flight_level": 262.5,
                    "detection": "combined"}),
        )
    };
    json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots_tagged(&radars, &targets(), duration, 1.0, 11, &tag),
        "cooperative": adsb(duration),
    })
}

/// The scene for CAT062 out (`tests/fixtures/cat062/service_cooperative`):
/// 75 s of the two Mode S radars; ADS-B of target 1 (spoofed from
/// [`SPOOF_FROM`]: its track distrusts it) and of target 2 until 50 s
/// (then aged), multilateration of target 2 every 2 s from 40 s (σ 30 m);
/// target 0 has radar plots only.
pub(crate) fn cat062_request() -> Value {
    const DURATION: f64 = 75.0;
    const TARGET_2_ADSB_UNTIL: f64 = 50.0;
    let mut req = request(DURATION);
    let reports = req["cooperative"].as_array_mut().unwrap();
    reports.retain(|r| {
        let address = r["mode_s_address"].as_str().unwrap();
        let t = r["t"].as_f64().unwrap();
        address == ADDRESSES[1] || (address == ADDRESSES[2] && t <= TARGET_2_ADSB_UNTIL)
    });
    let frame = origin_frame();
    let g = &targets()[2];
    let mut t = 40.05;
    while t <= DURATION {
        let p = g.at(t);
        let (lat, lon, h) = frame.enu_to_geodetic(p).unwrap();
        reports.push(json!({
            "source": "mlat", "t": t,
            "lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees(),
            "geometric_height_m": h, "sigma_m": 30.0,
            "mode_s_address": ADDRESSES[2],
        }));
        t += 2.0;
    }
    reports.sort_by(|a, b| {
        a["t"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["t"].as_f64().unwrap())
    });
    req["cat062"] = json!({"sac": 25, "sic": 100, "service_id": 3});
    req
}

fn confirmed(tracks: &Value) -> Vec<&Value> {
    tracks
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["status"] == "confirmed")
        .collect()
}

#[tokio::test]
async fn adsb_beside_mode_s_radars_is_one_track_per_aircraft_and_a_spoof_is_flagged() {
    let app = spawn_app().await;
    let req = request(95.0);
    let out = app.post_ok(PATH, &req).await;
    let tracks = confirmed(&out["tracks"]);
    // Targets 0, 1 and 2 (30–100 s) are alive at 95 s: one track each.
    let mut addresses: Vec<&str> = tracks
        .iter()
        .map(|t| t["identity"]["mode_s_address"]["value"].as_str().unwrap())
        .collect();
    addresses.sort_unstable();
    assert_eq!(
        addresses,
        vec!["3C6586", "4CA2D1", "A1B2C3"],
        "{}",
        out["tracks"]
    );
    let by = |a: &str| {
        *tracks
            .iter()
            .find(|t| t["identity"]["mode_s_address"]["value"] == a)
            .unwrap()
    };
    // Its sources: both radars and ADS-B, each with its last time.
    let sensors: Vec<&str> = by("4CA2D1")["sources"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["sensor"].as_str().unwrap())
        .collect();
    assert_eq!(sensors, vec!["west", "east", "adsb"]);
    let honest = &by("4CA2D1")["self_reported"];
    assert_eq!(honest["trusted"], true, "{honest}");
    assert_eq!(honest["validated"], true, "{honest}");
    // The spoofed aircraft: flagged within 30 s of the spoof, 3 km off,
    // and its track on the radars' positions (truth, not 3 km north).
    let spoofed = by("3C6586");
    let check = &spoofed["self_reported"];
    assert_eq!(check["trusted"], false, "{check}");
    let since = check["distrusted_since_t"].as_f64().unwrap();
    assert!((SPOOF_FROM..=SPOOF_FROM + 30.0).contains(&since), "{since}");
    let d = check["disagreement"]["distance_m"].as_f64().unwrap();
    assert!((d - SPOOF_M).abs() < 600.0, "{d}");
    let at = spoofed["t"].as_f64().unwrap();
    let truth = targets()[1].at(at);
    let s = &spoofed["state"];
    let off = (s[0].as_f64().unwrap() - truth[0]).hypot(s[2].as_f64().unwrap() - truth[1]);
    assert!(off < 600.0, "{off} m from the aircraft");
    let warnings = out["warnings"].to_string();
    assert!(
        warnings.contains(&format!("track {} (address 3C6586)", spoofed["id"])),
        "{warnings}"
    );

    // gRPC: the same tracks, sources and flags.
    let mut client = PlotFusionServiceClient::new(app.channel().await);
    let mut p = proto_request(&req);
    p.tracker = None;
    let g = client.track(p).await.unwrap().into_inner();
    let rest: Vec<(u64, Option<bool>, usize)> = out["tracks"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["id"].as_u64().unwrap(),
                t["self_reported"]["trusted"].as_bool(),
                t["sources"].as_array().map_or(0, Vec::len),
            )
        })
        .collect();
    let grpc: Vec<(u64, Option<bool>, usize)> = g
        .tracks
        .iter()
        .map(|t| {
            (
                t.id,
                t.self_reported.as_ref().map(|v| v.trusted),
                t.sources.len(),
            )
        })
        .collect();
    assert_eq!(rest, grpc);

    // A session fed in batches of one second (the log carries the reports)
    // ends with the batch call's tracks.
    let created = create_session(&app, &session_create(&req)).await;
    let id = created["id"].as_str().unwrap().to_string();
    let mut all: Vec<(f64, &str, &Value)> = Vec::new();
    for p in req["plots"].as_array().unwrap() {
        all.push((p["t"].as_f64().unwrap(), "plots", p));
    }
    for r in req["cooperative"].as_array().unwrap() {
        all.push((r["t"].as_f64().unwrap(), "cooperative", r));
    }
    all.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut sequence = 0;
    for second in all.chunk_by(|a, b| a.0.floor() == b.0.floor()) {
        sequence += 1;
        let pick = |list: &str| -> Vec<&Value> {
            second.iter().filter(|x| x.1 == list).map(|x| x.2).collect()
        };
        let body = json!({"sequence": sequence, "plots": pick("plots"),
                          "cooperative": pick("cooperative")});
        app.post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
    }
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let session = confirmed(&state["plot_fusion"]["tracks"]);
    assert_eq!(session.len(), 3, "{}", state["plot_fusion"]["tracks"]);
    let flagged: Vec<&Value> = session
        .iter()
        .filter(|t| t["self_reported"]["trusted"] == false)
        .copied()
        .collect();
    assert_eq!(flagged.len(), 1);
    assert_eq!(flagged[0]["identity"]["mode_s_address"]["value"], "3C6586");
}

#[tokio::test]
async fn bad_report_fields_are_named_on_both_transports() {
    let app = spawn_app().await;
    let mut req = request(20.0);
    let reports = req["cooperative"].as_array_mut().unwrap();
    reports[0].as_object_mut().unwrap().remove("nacp");
    reports[1]["source"] = json!("gps");
    reports[2]["lat_deg"] = json!(100.0);
    reports[3]["nacv"] = json!(0);
    reports[4]["mode_s_address"] = json!("XYZ");
    // A radar may not be named as a kind of report.
    let mut reserved = request(20.0);
    reserved["radars"][0]["id"] = json!("adsb");
    let body = assert_problem(app.post_json(PATH, &reserved).await, 422).await;
    assert!(
        problem_fields(&body).contains(&"radars[0].id".to_string()),
        "{body}"
    );
    // Parallel mode takes radar plots only: each report named.
    let mut parallel = request(20.0);
    parallel["tracker"] = json!({"mode": "parallel"});
    for r in parallel["radars"].as_array_mut().unwrap() {
        r["sigma_radial_velocity_mps"] = json!(1.0);
    }
    let body = assert_problem(app.post_json(PATH, &parallel).await, 422).await;
    let fields = problem_fields(&body);
    assert!(
        fields.iter().any(|f| f == "cooperative[0].source"),
        "{fields:?}"
    );
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    let want = vec![
        "cooperative[0].nacp",
        "cooperative[1].source",
        "cooperative[2].lat_deg",
        "cooperative[3].nacv",
        "cooperative[4].mode_s_address",
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

/// A gRPC stream session fed one second of plots and reports a batch
/// (`PushBatchRequest.cooperative`): the picture at the end has one track
/// per aircraft, the spoofed one flagged, the others' sources radar and
/// ADS-B.
#[tokio::test]
async fn a_grpc_stream_takes_cooperative_reports() {
    use radar_fusion::proto::session_service_client::SessionServiceClient;

    let app = spawn_app().await;
    let req = request(95.0);
    let p = proto_request(&req);
    let mut sessions = SessionServiceClient::new(app.channel().await);
    let open = pb::CreateSessionRequest {
        kind: "plot_fusion".into(),
        plot_fusion: Some(pb::PlotFusionConfig {
            cat062: None,
            origin: p.origin,
            radars: p.radars.clone(),
            tracker: None,
        }),
        ..Default::default()
    };
    let (tx, mut updates) =
        crate::sessions::data::open_stream(&mut sessions, pb::stream_request::Kind::Open(open))
            .await;
    let opened = updates.message().await.unwrap().unwrap();
    let id = opened.session_id.clone();
    let second = |t: f64| t.floor() as i64;
    let mut seconds: Vec<i64> = p.plots.iter().map(|x| second(x.t.unwrap())).collect();
    seconds.extend(p.cooperative.iter().map(|r| second(r.t)));
    seconds.sort_unstable();
    seconds.dedup();
    for (i, s) in seconds.into_iter().enumerate() {
        let plots = p
            .plots
            .iter()
            .filter(|x| second(x.t.unwrap()) == s)
            .cloned()
            .collect();
        let cooperative = req["cooperative"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| second(r["t"].as_f64().unwrap()) == s)
            .map(proto_report)
            .collect();
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(pb::PushBatchRequest {
                sequence: Some(i as u64 + 1),
                plots,
                cooperative,
                ..Default::default()
            })),
        })
        .await
        .unwrap();
        let u = updates.message().await.unwrap().unwrap();
        assert!(u.error.is_none(), "{:?}", u.error);
    }
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let tracks = confirmed(&state["plot_fusion"]["tracks"]);
    assert_eq!(tracks.len(), 3, "{}", state["plot_fusion"]["tracks"]);
    for t in &tracks {
        let address = t["identity"]["mode_s_address"]["value"].as_str().unwrap();
        assert_eq!(
            t["self_reported"]["trusted"] == false,
            address == "3C6586",
            "{t}"
        );
        let sources = t["sources"].to_string();
        assert!(sources.contains("adsb"), "{sources}");
    }
}

/// Two ships reporting by AIS (SOG/COG, the position-accuracy flag) every
/// 6 s beside the radars' aircraft: a track each, which carries its MMSI
/// on both transports; an MMSI of ten digits is refused naming it.
#[tokio::test]
async fn ais_reports_give_each_ship_its_mmsi() {
    let app = spawn_app().await;
    let frame = origin_frame();
    let ships = [
        (227_006_760u64, [2_000.0, -3_000.0], 10.0f64, 45.0f64),
        (244_630_000u64, [-4_000.0, 1_000.0], 6.0f64, 270.0f64),
    ];
    let mut reports = Vec::new();
    for (k, (mmsi, p0, sog_kn, cog_deg)) in ships.iter().enumerate() {
        let v = sog_kn * 1852.0 / 3600.0;
        let (ve, vn) = (
            v * cog_deg.to_radians().sin(),
            v * cog_deg.to_radians().cos(),
        );
        let mut t = 0.5 + k as f64;
        while t <= 120.0 {
            let (lat, lon, _) = frame
                .enu_to_geodetic([p0[0] + ve * t, p0[1] + vn * t, 0.0])
                .unwrap();
            reports.push(json!({
                "source": "ais", "t": t, "lat_deg": lat.to_degrees(),
                "lon_deg": lon.to_degrees(), "sog_kn": sog_kn, "cog_deg": cog_deg,
                "position_accurate": true, "mmsi": mmsi,
            }));
            t += 6.0;
        }
    }
    let mut req = request(120.0);
    req["cooperative"] = json!(reports);
    let out = app.post_ok(PATH, &req).await;
    let mut mmsis: Vec<u64> = confirmed(&out["tracks"])
        .iter()
        .filter_map(|t| t["mmsi"].as_u64())
        .collect();
    mmsis.sort_unstable();
    assert_eq!(mmsis, vec![227_006_760, 244_630_000], "{}", out["tracks"]);
    for t in confirmed(&out["tracks"]) {
        if t.get("mmsi").is_some() {
            assert_eq!(t["sources"][0]["sensor"], "ais", "{t}");
        }
    }
    let mut p = proto_request(&req);
    p.tracker = None;
    let g = PlotFusionServiceClient::new(app.channel().await)
        .track(p)
        .await
        .unwrap()
        .into_inner();
    let mut grpc: Vec<u32> = g.tracks.iter().filter_map(|t| t.mmsi).collect();
    grpc.sort_unstable();
    assert_eq!(grpc, vec![227_006_760, 244_630_000]);

    req["cooperative"][0]["mmsi"] = json!(2_270_067_600u64);
    let body = assert_problem(app.post_json(PATH, &req).await, 422).await;
    assert_eq!(problem_fields(&body), vec!["cooperative[0].mmsi"]);
}

/// Ships under a lone coastal radar (2D, primary, 3-s scan) that measures
/// 150 m long in range and 0.3° clockwise in azimuth, and their AIS as
/// NMEA lines with tag blocks (Unix times; `time_offset_s` takes them to
/// the plots' scale). `(request, ships' MMSIs)`.
fn coastal_scene(duration: f64) -> (Value, Vec<u64>) {
    use eval::ais::PositionReport;
    const EPOCH: f64 = 1_700_000_000.0;
    let frame = origin_frame();
    // (MMSI, start e/n (m), SOG (kn), COG (°)).
    let ships = [
        (235_070_762u64, [3_000.0, 5_000.0], 8.0f64, 120.0f64),
        (227_273_000u64, [-6_000.0, 2_000.0], 12.0, 30.0),
        (311_855_000u64, [1_000.0, -7_000.0], 5.0, 250.0),
    ];
    let at = |k: usize, t: f64| {
        let (_, p0, sog, cog) = ships[k];
        let v = sog * 1852.0 / 3600.0;
        let c = cog.to_radians();
        [p0[0] + v * c.sin() * t, p0[1] + v * c.cos() * t]
    };
    let (bias_r, bias_az) = (150.0, 0.3f64);
    let mut plots = Vec::new();
    let mut scan = 0.0;
    let mut n = 0.0f64;
    while scan < duration {
        for k in 0..ships.len() {
            let p = at(k, scan);
            let az = p[0].atan2(p[1]).rem_euclid(std::f64::consts::TAU);
            let t = scan + 3.0 * az / std::f64::consts::TAU;
            let p = at(k, t);
            n += 1.0;
            // Deterministic noise of about σ (20 m, 0.1°).
            plots.push(json!({
                "radar_id": "coast", "t": t,
                "range_m": p[0].hypot(p[1]) + bias_r + 20.0 * (n * 1.7).sin(),
                "azimuth_deg": p[0].atan2(p[1]).to_degrees() + bias_az + 0.1 * (n * 2.3).cos(),
            }));
        }
        scan += 3.0;
    }
    // Each ship's AIS every 10 s, fixed at the middle of a whole second
    // and received in the next (tag block c: one second later).
    let mut lines = Vec::new();
    let mut t = 0.5;
    while t < duration {
        for (k, ship) in ships.iter().enumerate() {
            let tk = t + k as f64;
            let p = at(k, tk);
            let (lat, lon, _) = frame.enu_to_geodetic([p[0], p[1], 0.0]).unwrap();
            let unix = EPOCH + tk;
            let mut r = PositionReport::from_report(&eval::ais::AisReport {
                mmsi: ship.0 as u32,
                t: unix,
                lat_deg: lat.to_degrees(),
                lon_deg: lon.to_degrees(),
                sog_knots: ship.2,
                cog_deg: ship.3,
                target: k,
            });
            r.accuracy = true;
            let c = format!("c:{}", unix.floor() as u64 + 1);
            let sum = eval::ais::nmea_checksum(&c);
            lines.push(format!("\\{c}*{sum:02X}\\{}", r.sentence('A')));
        }
        t += 10.0;
    }
    let req = json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": [{
            "id": "coast", "kind": "2d",
            "site": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
            "sigma_range_m": 20.0, "sigma_azimuth_deg": 0.1, "scan_period_s": 3.0,
            "p_detection": 0.95, "clutter_density": 1e-8,
        }],
        "plots": plots,
        "nmea": {"lines": lines, "time_offset_s": EPOCH},
    });
    (req, ships.iter().map(|s| s.0).collect())
}

fn sorted_mmsis(tracks: &[&Value]) -> Vec<u64> {
    let mut m: Vec<u64> = tracks.iter().filter_map(|t| t["mmsi"].as_u64()).collect();
    m.sort_unstable();
    m
}

#[tokio::test]
async fn ais_nmea_beside_a_coastal_radar_registers_it_on_every_transport() {
    let app = spawn_app().await;
    let (req, mut mmsis) = coastal_scene(600.0);
    mmsis.sort_unstable();
    let out = app.post_ok(PATH, &req).await;
    let tracks = confirmed(&out["tracks"]);
    // One track per ship, each with its MMSI and both sources: no radar
    // duplicate of an AIS track.
    assert_eq!(tracks.len(), 3, "{}", out["tracks"]);
    assert_eq!(sorted_mmsis(&tracks), mmsis);
    for t in &tracks {
        let sources: Vec<&str> = t["sources"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["sensor"].as_str().unwrap())
            .collect();
        assert!(
            sources.contains(&"coast") && sources.contains(&"ais"),
            "{t}"
        );
    }
    // The lone radar registered against AIS: 150 m and 0.3°.
    let b = &out["registration"][0];
    assert_eq!(b["converged"], true, "{b}");
    let (r, az) = (
        b["range_m"].as_f64().unwrap(),
        b["azimuth_deg"].as_f64().unwrap(),
    );
    assert!((r - 150.0).abs() < 30.0, "{b}");
    assert!((az - 0.3).abs() < 0.05, "{b}");
    // Every line used (the accuracy estimator's warnings may stand: the
    // scene's detections are certain, and its noise is not Gaussian).
    assert!(
        !out["warnings"].to_string().contains("nmea"),
        "{}",
        out["warnings"]
    );

    // gRPC: the same ships.
    let g = PlotFusionServiceClient::new(app.channel().await)
        .track(proto_request(&req))
        .await
        .unwrap()
        .into_inner();
    let mut grpc: Vec<u64> = g
        .tracks
        .iter()
        .filter_map(|t| t.mmsi.map(u64::from))
        .collect();
    grpc.sort_unstable();
    assert_eq!(grpc, mmsis);

    // A REST session fed 30-s batches of plots and NMEA lines ends with
    // the same ships.
    let created = create_session(&app, &session_create(&req)).await;
    let id = created["id"].as_str().unwrap();
    let lines = req["nmea"]["lines"].as_array().unwrap();
    let plots = req["plots"].as_array().unwrap();
    let unix = |l: &Value| -> f64 {
        let s = l.as_str().unwrap();
        s[3..s.find('*').unwrap()].parse::<f64>().unwrap() - 1_700_000_000.0
    };
    for (sequence, from) in (0..600).step_by(30).enumerate() {
        let within = |t: f64| (from as f64..from as f64 + 30.0).contains(&t);
        let body = json!({
            "sequence": sequence + 1,
            "plots": plots.iter().filter(|p| within(p["t"].as_f64().unwrap())).collect::<Vec<_>>(),
            "nmea": {
                "lines": lines.iter().filter(|l| within(unix(l))).collect::<Vec<_>>(),
                "time_offset_s": 1_700_000_000.0,
            },
        });
        app.post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
    }
    let state = app.get_ok(&format!("/v1/sessions/{id}")).await;
    let session = confirmed(&state["plot_fusion"]["tracks"]);
    assert_eq!(
        sorted_mmsis(&session),
        mmsis,
        "{}",
        state["plot_fusion"]["tracks"]
    );
    assert_eq!(session.len(), 3);

    // Lines it cannot use are counted, named by index.
    let mut bad = req.clone();
    bad["nmea"]["lines"][0] = json!("!AIVDM,1,1,,A,177KQJ5000G?tO`K>RA1wUbN0TKH,0*00");
    let out = app.post_ok(PATH, &bad).await;
    let w = out["warnings"].to_string();
    assert!(w.contains("nmea.lines[0]") && w.contains("checksum"), "{w}");
}
