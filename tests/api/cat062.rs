//! CAT062 out through the real servers: the batch call's `cat062`, gRPC's
//! bytes, a session's updates, bad options. The records are read by
//! [`decode`], a reader written here from the CAT062 1.20 specification
//! (UAP, item sizes, compound and extended items), not from the encoder;
//! libasterix is the full oracle (`checks/cat062_service_oracle.sh`).

use base64::Engine as _;
use radar_fusion::proto::plot_fusion_service_client::PlotFusionServiceClient;
use serde_json::{Value, json};

use crate::helpers::{assert_problem, problem_fields, spawn_app};
use crate::plot_fusion::plot_scene;

/// What the tests read of one record.
#[derive(Debug, Default, Clone, PartialEq)]
pub(crate) struct Record {
    pub sac_sic: Option<(u8, u8)>,
    pub service_id: Option<u8>,
    /// I062/070, seconds.
    pub time_of_day: Option<f64>,
    /// I062/105, degrees.
    pub lat_lon: Option<(f64, f64)>,
    /// I062/100, metres.
    pub xy: Option<(f64, f64)>,
    /// I062/185, m/s.
    pub velocity: Option<(f64, f64)>,
    pub track_number: Option<u16>,
    /// I062/080 octets.
    pub status: Vec<u8>,
    /// I062/290 PSR age, s.
    pub psr_age: Option<f64>,
    /// I062/290 TRK age, s.
    pub track_age: Option<f64>,
    /// I062/290 ES age (1090 ES ADS-B), s.
    pub es_age: Option<f64>,
    /// I062/290 MLT age (multilateration), s.
    pub mlt_age: Option<f64>,
    /// I062/130, ft.
    pub altitude_ft: Option<f64>,
    /// I062/500 APC (x, y), m.
    pub apc: Option<(f64, f64)>,
    /// I062/340 SID.
    pub sensor: Option<(u8, u8)>,
    /// I062/340 POS (NM, °).
    pub polar: Option<(f64, f64)>,
    /// I062/060 (V, G, CH, code).
    pub mode_3a: Option<(bool, bool, bool, u16)>,
    /// I062/245 STI and characters, and I062/380 ID (the same 6 octets).
    pub callsign: Option<(u8, [u8; 6])>,
    pub derived_id: Option<[u8; 6]>,
    /// I062/380 ADR.
    pub address: Option<u32>,
    /// I062/136, FL.
    pub measured_fl: Option<f64>,
}

impl Record {
    /// I062/080 CNF (bit 2 of the first octet): tentative.
    pub(crate) fn tentative(&self) -> bool {
        self.status.first().is_some_and(|o| o & 0x02 != 0)
    }
    /// TSE (bit 7 of the first extension): the last message.
    pub(crate) fn last_message(&self) -> bool {
        self.status.get(1).is_some_and(|o| o & 0x40 != 0)
    }
    /// TSB (bit 6 of the first extension): the first message.
    pub(crate) fn first_message(&self) -> bool {
        self.status.get(1).is_some_and(|o| o & 0x20 != 0)
    }
    /// AFF (bit 4 of the first extension): ADS-B data inconsistent with
    /// other surveillance information.
    pub(crate) fn adsb_inconsistent(&self) -> bool {
        self.status.get(1).is_some_and(|o| o & 0x08 != 0)
    }
    /// ADS (bit 4 of the third extension): the last ADS-B update is aged.
    pub(crate) fn adsb_aged(&self) -> bool {
        self.status.get(3).is_some_and(|o| o & 0x08 != 0)
    }
}

fn i24(b: &[u8]) -> i64 {
    let v = (i64::from(b[0]) << 16) | (i64::from(b[1]) << 8) | i64::from(b[2]);
    if v & 0x80_0000 != 0 {
        v - 0x100_0000
    } else {
        v
    }
}
fn i16be(b: &[u8]) -> f64 {
    f64::from(i16::from_be_bytes([b[0], b[1]]))
}
fn i32be(b: &[u8]) -> f64 {
    f64::from(i32::from_be_bytes([b[0], b[1], b[2], b[3]]))
}

/// An FSPEC-like field: octets while bit 1 (FX) is set; the bits present,
/// numbered from 1 (bit 8 of the first octet).
fn presence(data: &[u8], at: &mut usize) -> Vec<bool> {
    let mut bits = Vec::new();
    loop {
        let o = data[*at];
        *at += 1;
        for b in (1..8).rev() {
            bits.push(o & (1 << b) != 0);
        }
        if o & 1 == 0 {
            return bits;
        }
    }
}

/// A compound item: its primary subfield, then the subfields present, of
/// the sizes given (in order).
fn compound<'a>(data: &'a [u8], at: &mut usize, sizes: &[usize]) -> Vec<Option<&'a [u8]>> {
    let present = presence(data, at);
    let mut out = Vec::new();
    for (i, &size) in sizes.iter().enumerate() {
        if present.get(i).copied().unwrap_or(false) {
            out.push(Some(&data[*at..*at + size]));
            *at += size;
        } else {
            out.push(None);
        }
    }
    out
}

/// Every record of every CAT062 data block in `data`. Panics on anything
/// the service must not write (another category, a LEN that does not
/// match, an item this reader does not know).
pub(crate) fn decode(data: &[u8]) -> Vec<Record> {
    let mut records = Vec::new();
    let mut block = 0;
    while block < data.len() {
        assert_eq!(data[block], 62, "category at {block}");
        let len = usize::from(u16::from_be_bytes([data[block + 1], data[block + 2]]));
        assert!(len > 3 && block + len <= data.len(), "LEN {len} at {block}");
        let end = block + len;
        let mut at = block + 3;
        while at < end {
            records.push(record(data, &mut at));
        }
        assert_eq!(at, end, "records fill the block at {block}");
        block = end;
    }
    records
}

fn record(data: &[u8], at: &mut usize) -> Record {
    let fspec = presence(data, at);
    let mut r = Record::default();
    for (i, present) in fspec.iter().enumerate() {
        if !present {
            continue;
        }
        let frn = i + 1;
        let take = |at: &mut usize, n: usize| {
            let s = &data[*at..*at + n];
            *at += n;
            s
        };
        match frn {
            1 => {
                let b = take(at, 2);
                r.sac_sic = Some((b[0], b[1]));
            }
            3 => r.service_id = Some(take(at, 1)[0]),
            4 => {
                let b = take(at, 3);
                let v = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
                r.time_of_day = Some(f64::from(v) / 128.0);
            }
            5 => {
                let b = take(at, 8);
                let lsb = 180.0 / f64::from(1u32 << 25);
                r.lat_lon = Some((i32be(&b[0..4]) * lsb, i32be(&b[4..8]) * lsb));
            }
            6 => {
                let b = take(at, 6);
                r.xy = Some((i24(&b[0..3]) as f64 * 0.5, i24(&b[3..6]) as f64 * 0.5));
            }
            7 => {
                let b = take(at, 4);
                r.velocity = Some((i16be(&b[0..2]) * 0.25, i16be(&b[2..4]) * 0.25));
            }
            12 => {
                let b = take(at, 2);
                r.track_number = Some(u16::from_be_bytes([b[0], b[1]]));
            }
            13 => loop {
                let o = take(at, 1)[0];
                r.status.push(o);
                if o & 1 == 0 {
                    break;
                }
            },
            14 => {
                // TRK PSR SSR MDS ADS(2) ES VDL | UAT LOP MLT, LSB 1/4 s.
                let s = compound(data, at, &[1, 1, 1, 1, 2, 1, 1, 1, 1, 1]);
                let age = |i: usize| s[i].map(|b: &[u8]| f64::from(b[0]) / 4.0);
                r.track_age = age(0);
                r.psr_age = age(1);
                r.es_age = age(5);
                r.mlt_age = age(9);
            }
            18 => r.altitude_ft = Some(i16be(take(at, 2)) * 6.25),
            20 => {
                take(at, 2);
            }
            27 => {
                // APC(4) COV(2) APW(4) AGA ABA ATV(2) AA(2) | ARC.
                let s = compound(data, at, &[4, 2, 4, 1, 1, 2, 2, 1]);
                r.apc = s[0].map(|b| {
                    let u = |x: &[u8]| f64::from(u16::from_be_bytes([x[0], x[1]])) * 0.5;
                    (u(&b[0..2]), u(&b[2..4]))
                });
            }
            28 => {
                // SID(2) POS(4) HEIGHT(2) MDC(2) MDA(2) TYP(1).
                let s = compound(data, at, &[2, 4, 2, 2, 2, 1]);
                r.sensor = s[0].map(|b| (b[0], b[1]));
                r.polar = s[1].map(|b| {
                    let rho = f64::from(u16::from_be_bytes([b[0], b[1]])) / 256.0;
                    let theta = f64::from(u16::from_be_bytes([b[2], b[3]])) * 360.0 / 65_536.0;
                    (rho, theta)
                });
            }
            9 => {
                let w = u16::from_be_bytes(take(at, 2).try_into().unwrap());
                r.mode_3a = Some((
                    w & 0x8000 != 0,
                    w & 0x4000 != 0,
                    w & 0x2000 != 0,
                    w & 0x0FFF,
                ));
            }
            10 => {
                let b = take(at, 7);
                r.callsign = Some((b[0] >> 6, b[1..7].try_into().unwrap()));
            }
            11 => {
                // ADR(3) ID(6); the service writes no other subfield.
                let s = compound(data, at, &[3, 6]);
                r.address = s[0].map(|b| u32::from_be_bytes([0, b[0], b[1], b[2]]));
                r.derived_id = s[1].map(|b| b.try_into().unwrap());
            }
            17 => r.measured_fl = Some(i16be(take(at, 2)) * 0.25),
            other => panic!("FRN {other}: an item the service does not write"),
        }
    }
    r
}

pub(crate) fn b64_decode(s: &str) -> Vec<u8> {
    base64::engine::general_purpose::STANDARD
        .decode(s)
        .expect("base64")
}

/// Half an LSB plus rounding noise.
fn near(a: f64, b: f64, lsb: f64) -> bool {
    (a - b).abs() <= lsb / 2.0 + 1e-9
}

/// Checks one record against its JSON track (the specification's LSBs).
pub(crate) fn assert_matches(rec: &Record, track: &Value, sac_sic: (u8, u8)) {
    let f = |k: &str| track[k].as_f64().unwrap();
    let id = track["id"].as_u64().unwrap();
    assert_eq!(rec.sac_sic, Some(sac_sic));
    assert_eq!(rec.track_number, Some((id % 65_536) as u16), "{track}");
    let tod = f("t").rem_euclid(86_400.0);
    let dt = (rec.time_of_day.unwrap() - tod).abs();
    assert!(
        dt <= 1.0 / 256.0 + 1e-9 || (86_400.0 - dt) <= 1.0 / 256.0,
        "{dt}"
    );
    let deg = 180.0 / f64::from(1u32 << 25);
    let (lat, lon) = rec.lat_lon.expect("I062/105");
    assert!(near(lat, f("lat_deg"), deg), "{lat} vs {}", f("lat_deg"));
    assert!(near(lon, f("lon_deg"), deg), "{lon} vs {}", f("lon_deg"));
    let s = |i: usize| track["state"][i].as_f64().unwrap();
    let (x, y) = rec.xy.expect("I062/100");
    assert!(
        near(x, s(0), 0.5) && near(y, s(2), 0.5),
        "{x} {y} vs {track}"
    );
    let (vx, vy) = rec.velocity.expect("I062/185");
    assert!(near(vx, s(1), 0.25) && near(vy, s(3), 0.25));
    assert_eq!(rec.tentative(), track["status"] == "tentative");
    // PSR age: from the last primary update when a radar's secondary plot
    // updated the track (or no report did), else from its last update
    // without reports, its latest radar with them (docs/plot-fusion.md).
    let identity = track.get("identity");
    let (radar_t, reports) = radar_and_reports(track);
    let last = |name: &str| reports.iter().find(|r| r.0 == name).map(|r| r.1);
    let any_report = !reports.is_empty();
    let psr_t = match identity {
        Some(i) if i.get("last_secondary_t").is_some() || !any_report => {
            i["last_primary_t"].as_f64()
        }
        None if !any_report => Some(f("last_update_t")),
        _ => radar_t,
    };
    let age = |at: Option<f64>| at.map(|a| (f("t") - a).min(63.75));
    for (what, got, want) in [
        ("PSR", rec.psr_age, age(psr_t)),
        ("ES", rec.es_age, age(last("adsb"))),
        ("MLT", rec.mlt_age, age(last("mlat"))),
    ] {
        match want {
            Some(w) => assert!(near(got.unwrap(), w, 0.25), "{what}: {rec:?} {track}"),
            None => assert_eq!(got, None, "{what}: {rec:?}"),
        }
    }
    // AFF while ADS-B is distrusted; ADS when it is older than 12 s.
    let distrusted = track["self_reported"]["trusted"] == false;
    assert_eq!(
        rec.adsb_inconsistent(),
        distrusted && last("adsb").is_some(),
        "{rec:?}"
    );
    assert_eq!(
        rec.adsb_aged(),
        last("adsb").is_some_and(|a| f("t") - a > 12.0),
        "{rec:?}"
    );
    // Identity: I062/060, /380 ADR, /136 as the JSON says.
    let code = identity.and_then(|i| i["mode_3a"]["value"].as_str());
    assert_eq!(
        rec.mode_3a.map(|m| m.3),
        code.map(|c| u16::from_str_radix(c, 8).unwrap()),
        "{rec:?}"
    );
    let address = identity.and_then(|i| i["mode_s_address"]["value"].as_str());
    assert_eq!(
        rec.address,
        address.map(|a| u32::from_str_radix(a, 16).unwrap()),
        "{rec:?}"
    );
    let fl = identity.and_then(|i| i["pressure_altitude"]["measured_flight_level"].as_f64());
    match fl {
        Some(fl) => assert!(near(rec.measured_fl.unwrap(), fl, 0.25), "{rec:?}"),
        None => assert_eq!(rec.measured_fl, None),
    }
    if let Some(start) = track["start_t"].as_f64() {
        let trk = (f("t") - start).min(63.75);
        assert!(near(rec.track_age.unwrap(), trk, 0.25), "{rec:?}");
    }
    let p = |i: usize| {
        track["covariance"][i][i]
            .as_f64()
            .unwrap()
            .sqrt()
            .min(32_767.5)
    };
    let (ax, ay) = rec.apc.expect("I062/500 APC");
    assert!(near(ax, p(0), 0.5) && near(ay, p(2), 0.5));
    match track["height_m"].as_f64() {
        Some(h) => assert!(near(rec.altitude_ft.unwrap(), h / 0.3048, 6.25)),
        None => assert_eq!(rec.altitude_ft, None),
    }
    match track.get("last_plot") {
        Some(lp) => {
            let (rho, theta) = rec.polar.expect("I062/340 POS");
            assert!(near(
                rho,
                lp["range_m"].as_f64().unwrap() / 1852.0,
                1.0 / 256.0
            ));
            let az = lp["azimuth_deg"].as_f64().unwrap();
            let d = (theta - az).abs();
            assert!(
                d.min(360.0 - d) <= 360.0 / 65_536.0 / 2.0 + 1e-9,
                "{theta} vs {az}"
            );
        }
        None => assert_eq!(rec.polar, None),
    }
}

/// The latest radar's time among a track's `sources`, and its report
/// sensors (`adsb`, `mlat`, `ais`) with theirs (the scenes' radars are
/// `west` and `east`: no radar has a report sensor's name).
fn radar_and_reports(track: &Value) -> (Option<f64>, Vec<(&str, f64)>) {
    let mut radar: Option<f64> = None;
    let mut reports = Vec::new();
    for s in track["sources"].as_array().into_iter().flatten() {
        let name = s["sensor"].as_str().unwrap();
        let t = s["last_t"].as_f64().unwrap();
        if ["adsb", "mlat", "ais"].contains(&name) {
            reports.push((name, t));
        } else {
            radar = Some(radar.map_or(t, |r| r.max(t)));
        }
    }
    (radar, reports)
}

pub(crate) fn request_with_cat062() -> Value {
    let mut req = plot_scene::request(false, 1);
    req["cat062"] = json!({"sac": 25, "sic": 100, "service_id": 3});
    req
}

#[tokio::test]
async fn the_batch_call_answers_each_track_as_a_cat062_record() {
    let app = spawn_app().await;
    let req = request_with_cat062();
    let out = app.post_ok("/v1/plot-fusion/track", &req).await;
    let tracks = out["tracks"].as_array().unwrap();
    assert!(tracks.len() >= 2, "{out}");
    let records = decode(&b64_decode(out["cat062"].as_str().unwrap()));
    assert_eq!(records.len(), tracks.len());
    for (rec, track) in records.iter().zip(tracks) {
        assert_matches(rec, track, (25, 100));
        assert_eq!(rec.service_id, Some(3));
        assert!(!rec.first_message() && !rec.last_message());
    }
    // Serial mode (the default): every confirmed track names its last plot.
    assert!(
        tracks
            .iter()
            .filter(|t| t["status"] == "confirmed")
            .all(|t| t.get("last_plot").is_some())
    );
    // Without the option nothing changes but the field.
    let mut plain = req.clone();
    plain.as_object_mut().unwrap().remove("cat062");
    let without = app.post_ok("/v1/plot-fusion/track", &plain).await;
    assert!(without.get("cat062").is_none());
    assert_eq!(without["tracks"], out["tracks"]);
    // gRPC answers the same bytes.
    let mut grpc = PlotFusionServiceClient::new(app.channel().await);
    let p = crate::plot_fusion::proto_request(&req);
    let answer = grpc.track(p).await.unwrap().into_inner();
    assert_eq!(
        answer.cat062.as_deref(),
        Some(&b64_decode(out["cat062"].as_str().unwrap())[..])
    );
}

#[tokio::test]
async fn blocks_split_at_record_boundaries_under_the_size_asked() {
    let app = spawn_app().await;
    let mut req = request_with_cat062();
    req["cat062"]["max_block_bytes"] = json!(64);
    let out = app.post_ok("/v1/plot-fusion/track", &req).await;
    let data = b64_decode(out["cat062"].as_str().unwrap());
    let mut at = 0;
    let mut blocks = 0;
    while at < data.len() {
        let len = usize::from(u16::from_be_bytes([data[at + 1], data[at + 2]]));
        // A record (about 60 bytes) alone may pass 64; two never share one.
        assert_eq!(decode(&data[at..at + len]).len(), 1);
        at += len;
        blocks += 1;
    }
    assert_eq!(blocks, out["tracks"].as_array().unwrap().len());
}

#[tokio::test]
async fn bad_cat062_options_are_named() {
    let app = spawn_app().await;
    for (cat062, field) in [
        (json!({"sac": 256, "sic": 1}), "cat062.sac"),
        (json!({"sac": 1, "sic": 1000}), "cat062.sic"),
        (
            json!({"sac": 1, "sic": 1, "service_id": 256}),
            "cat062.service_id",
        ),
        (
            json!({"sac": 1, "sic": 1, "max_block_bytes": 10}),
            "cat062.max_block_bytes",
        ),
        (
            json!({"sac": 1, "sic": 1, "max_block_bytes": 70000}),
            "cat062.max_block_bytes",
        ),
    ] {
        let mut req = request_with_cat062();
        req["cat062"] = cat062;
        let problem = assert_problem(app.post_json("/v1/plot-fusion/track", &req).await, 422).await;
        assert_eq!(
            problem_fields(&problem),
            vec![field.to_string()],
            "{problem}"
        );
    }
    // Without an origin and with local sites there is no WGS-84 position.
    let local = json!({
        "radars": [{"id": "a", "kind": "2d", "site": {"position_m": [0.0, 0.0]},
                    "sigma_range_m": 50.0, "sigma_azimuth_deg": 0.1,
                    "scan_period_s": 4.0}],
        "cat062": {"sac": 1, "sic": 1}
    });
    let problem = assert_problem(app.post_json("/v1/plot-fusion/track", &local).await, 422).await;
    assert_eq!(problem_fields(&problem), vec!["cat062".to_string()]);
    // A session refuses the same, and holds nothing.
    let mut create = json!({"kind": "plot_fusion", "cat062": {"sac": 300, "sic": 1}});
    create["radars"] = request_with_cat062()["radars"].clone();
    create["origin"] = json!({"lat_deg": 47.0, "lon_deg": 8.0});
    let problem = assert_problem(app.post_json("/v1/sessions", &create).await, 422).await;
    assert_eq!(problem_fields(&problem), vec!["cat062.sac".to_string()]);
    let list = app.get_ok("/v1/sessions").await;
    assert_eq!(list["sessions"].as_array().map_or(0, Vec::len), 0, "{list}");
}

#[tokio::test]
async fn a_session_sends_changed_tracks_first_and_last_messages() {
    let app = spawn_app().await;
    let req = request_with_cat062();
    let mut create = json!({"kind": "plot_fusion"});
    for k in ["origin", "radars", "cat062"] {
        create[k] = req[k].clone();
    }
    let created = app.post_json("/v1/sessions", &create).await;
    assert_eq!(created.status(), 201);
    let created: Value = created.json().await.unwrap();
    let id = created["id"].as_str().unwrap().to_string();
    let mut plots: Vec<Value> = req["plots"].as_array().unwrap().clone();
    plots.sort_by(|a, b| {
        a["t"]
            .as_f64()
            .unwrap()
            .total_cmp(&b["t"].as_f64().unwrap())
    });
    let mut seen = std::collections::HashSet::new();
    let mut firsts = 0;
    let chunks: Vec<&[Value]> = plots.chunks(plots.len() / 5 + 1).collect();
    for (k, chunk) in chunks.iter().enumerate() {
        let body = json!({"sequence": k + 1, "plots": chunk, "flush": k + 1 == chunks.len()});
        let u = app
            .post_ok(&format!("/v1/sessions/{id}/batches"), &body)
            .await;
        let u = &u["plot_fusion"];
        let records = decode(&b64_decode(u["cat062"].as_str().unwrap()));
        let tracks = u["tracks"].as_array().unwrap();
        let deleted = u["deleted"].as_array().unwrap();
        assert_eq!(records.len(), tracks.len() + deleted.len());
        for (rec, c) in records.iter().zip(tracks) {
            assert_matches(rec, &c["track"], (25, 100));
            // The first record of a new track (initiated, or confirmed in
            // the batch that started it) is flagged TSB.
            let new = c["change"] == "initiated"
                || (c["change"] == "confirmed" && !seen.contains(&rec.track_number));
            assert_eq!(rec.first_message(), new, "{c}");
            // TSB once per track, on its first record.
            if rec.first_message() {
                firsts += 1;
                assert!(seen.insert(rec.track_number), "TSB twice");
            }
            assert!(!rec.last_message());
        }
        for (rec, t) in records[tracks.len()..].iter().zip(deleted) {
            assert_matches(rec, t, (25, 100));
            assert!(rec.last_message(), "TSE for deleted {t}");
        }
    }
    assert!(firsts >= 2);
}

/// The requests of the libasterix fixtures: the seed-001 scene of the
/// plot-fusion tests, the ASTERIX fixture scene and the cooperative scene
/// (ADS-B and multilateration beside Mode S radars).
fn fixture_requests() -> [(&'static str, Value); 3] {
    [
        ("service_seed001", request_with_cat062()),
        ("service_asterix", crate::asterix::cat062_request()),
        ("service_cooperative", crate::cooperative::cat062_request()),
    ]
}

#[tokio::test]
async fn a_track_updated_by_adsb_carries_an_es_age_and_a_radar_only_track_none() {
    let app = spawn_app().await;
    let req = crate::cooperative::cat062_request();
    let out = app.post_ok("/v1/plot-fusion/track", &req).await;
    let tracks = out["tracks"].as_array().unwrap();
    let records = decode(&b64_decode(out["cat062"].as_str().unwrap()));
    assert_eq!(records.len(), tracks.len());
    for (rec, track) in records.iter().zip(tracks) {
        assert_matches(rec, track, (25, 100));
    }
    let by = |address: &str| {
        let i = tracks
            .iter()
            .position(|t| {
                t["status"] == "confirmed" && t["identity"]["mode_s_address"]["value"] == address
            })
            .unwrap_or_else(|| panic!("no track of {address}: {out}"));
        (&tracks[i], &records[i])
    };
    let source = |t: &Value, name: &str| {
        t["sources"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["sensor"] == name)
            .map(|s| s["last_t"].as_f64().unwrap())
    };
    // Target 0: the radars only. No ES or MLT age, no ADS-B flag; its
    // PSR age from its radar plots.
    let (t0, r0) = by("4CA2D1");
    assert_eq!(source(t0, "adsb"), None, "{t0}");
    assert_eq!((r0.es_age, r0.mlt_age), (None, None), "{r0:?}");
    assert!(!r0.adsb_inconsistent() && !r0.adsb_aged());
    assert!(r0.psr_age.is_some());
    // Target 1: ADS-B every second, spoofed from 60 s and distrusted
    // (AFF): its ES age is that of the last report that updated it, the
    // last honest one (the spoofed ones disagree and update nothing).
    let (t1, r1) = by("3C6586");
    assert_eq!(t1["self_reported"]["trusted"], false, "{t1}");
    assert!(r1.adsb_inconsistent(), "{r1:?}");
    let last = source(t1, "adsb").unwrap();
    assert!((59.0..60.0).contains(&last), "{t1}");
    let es = t1["t"].as_f64().unwrap() - last;
    assert!(near(r1.es_age.unwrap(), es, 0.25), "{r1:?}");
    assert_eq!(r1.adsb_aged(), es > 12.0);
    assert_eq!(r1.mlt_age, None);
    // Target 2: ADS-B until 50 s (at 75 s, about 25 s old: ADS aged) and
    // multilateration every 2 s (an MLT age of at most 2 s).
    let (t2, r2) = by("A1B2C3");
    let last = source(t2, "adsb").unwrap();
    assert!((49.0..=50.0).contains(&last), "{t2}");
    let es = t2["t"].as_f64().unwrap() - last;
    assert!(es > 12.0 && near(r2.es_age.unwrap(), es, 0.25), "{r2:?}");
    assert!(r2.adsb_aged() && !r2.adsb_inconsistent(), "{r2:?}");
    assert!(r2.mlt_age.unwrap() <= 2.25, "{r2:?}");
}

fn fixture_path(name: &str, suffix: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures/cat062")
        .join(format!("{name}{suffix}.json"))
}

/// Writes each fixture request with the service's answer (tracks and
/// cat062); then `bash checks/cat062_service_oracle.sh` decodes them with
/// libasterix, compares and writes `*_decoded.json`.
#[tokio::test]
#[ignore = "writes tests/fixtures/cat062/service_*.json"]
async fn regenerate_the_service_cat062_fixtures() {
    let app = spawn_app().await;
    for (name, req) in fixture_requests() {
        let out = app.post_ok("/v1/plot-fusion/track", &req).await;
        let fixture = json!({
            "request": req,
            "answer": {"tracks": out["tracks"], "cat062": out["cat062"]},
        });
        std::fs::write(fixture_path(name, ""), format!("{fixture:#}\n")).unwrap();
    }
}

/// libasterix's decoding of the service's CAT062 (committed by
/// `checks/cat062_service_oracle.sh`, which also compared every field with
/// the JSON): the service still answers those bytes for those requests,
/// and libasterix's values are the JSON's (track number, time, position,
/// velocity, status), within half an LSB.
#[tokio::test]
async fn libasterix_reads_what_the_json_answer_says() {
    let app = spawn_app().await;
    for (name, req) in fixture_requests() {
        let read = |suffix: &str| -> Value {
            let path = fixture_path(name, suffix);
            serde_json::from_str(&std::fs::read_to_string(&path).unwrap())
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        };
        let fixture = read("");
        let decoded = read("_decoded");
        assert_eq!(fixture["request"], req, "{name}: the fixture's request");
        let out = app.post_ok("/v1/plot-fusion/track", &req).await;
        assert!(
            out["cat062"] == fixture["answer"]["cat062"]
                && out["tracks"] == fixture["answer"]["tracks"],
            "{name}: the answer changed; regenerate with `cargo test --test api \
             regenerate_the_service_cat062_fixtures -- --ignored` and `bash \
             checks/cat062_service_oracle.sh`, and read its verdict"
        );
        let records: Vec<&Value> = decoded["blocks"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|b| b["records"].as_array().unwrap())
            .collect();
        let tracks = out["tracks"].as_array().unwrap();
        assert_eq!(records.len(), tracks.len(), "{name}");
        assert!(tracks.len() >= 2, "{name}");
        let deg = 180.0 / f64::from(1u32 << 25);
        for (r, t) in records.iter().zip(tracks) {
            let it = &r["items"];
            let v = |path: &[&str]| -> f64 {
                let mut x = it;
                for k in path {
                    x = &x[*k];
                }
                x["value"].as_f64().or(x["raw"].as_f64()).unwrap()
            };
            let f = |k: &str| t[k].as_f64().unwrap();
            let s = |i: usize| t["state"][i].as_f64().unwrap();
            assert_eq!(v(&["040"]), (t["id"].as_u64().unwrap() % 65_536) as f64);
            assert_eq!(v(&["010", "SAC"]), req["cat062"]["sac"].as_f64().unwrap());
            let tod = f("t").rem_euclid(86_400.0);
            assert!(
                (v(&["070"]) - tod).abs() <= 1.0 / 256.0 + 1e-9,
                "{name} {t}"
            );
            assert!(near(v(&["105", "LAT"]), f("lat_deg"), deg));
            assert!(near(v(&["105", "LON"]), f("lon_deg"), deg));
            assert!(near(v(&["100", "X"]), s(0), 0.5) && near(v(&["100", "Y"]), s(2), 0.5));
            assert!(near(v(&["185", "VX"]), s(1), 0.25) && near(v(&["185", "VY"]), s(3), 0.25));
            assert_eq!(v(&["080", "CNF"]) == 1.0, t["status"] == "tentative");
        }
    }
}
