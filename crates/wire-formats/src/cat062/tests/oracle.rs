//! The sample checked by an independent decoder, libasterix
//! (`checks/cat062_oracle.sh`): `tests/fixtures/cat062/sample.bin` is this
//! encoder's output for [`sample_tracks`], `sample_input.json` the same
//! inputs, `sample_decoded.json` libasterix's decoding of the bytes
//! (committed). Regenerate the first two with
//! `cargo test -p formats regenerate_the_cat062_sample -- --ignored`, then
//! `bash checks/cat062_oracle.sh` for the third.

use super::*;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

/// Blocks of the sample: small, so that it holds several.
const SAMPLE_MAX_BLOCK: usize = 200;

fn sample_config() -> Cat062Config {
    Cat062Config {
        sac: 25,
        sic: 100,
        service_id: Some(3),
    }
}

fn sample_tracks() -> Vec<SystemTrack> {
    let f = TrackStatusFlags::default();
    vec![
        // 0: a confirmed 3D multisensor track with everything.
        SystemTrack {
            track_number: 101,
            time_of_day: 45_296.789,
            wgs84: Some((52.308_056, 4.764_167)),
            xy: (-12_345.6, 23_456.7),
            velocity: (-120.3, 85.2),
            status: TrackStatusFlags {
                altitude_source: AltitudeSource::Radar3d,
                ..f
            },
            ages: UpdateAges {
                track: Some(120.0),
                psr: Some(1.2),
                ssr: Some(0.8),
                mode_s: Some(0.8),
                adsb_es: Some(0.5),
                mlat: Some(0.3),
            },
            accuracy: Some(Accuracy {
                xy: Some((35.2, 41.9)),
                xy_covariance_m2: Some(-310.0),
                wgs84: Some((0.000_31, 0.000_52)),
                geometric_altitude: Some(45.0),
                velocity: Some((2.3, 3.1)),
                acceleration: Some((0.6, 0.4)),
                vertical_rate: Some(1.7),
            }),
            height: Some(3_048.0),
            vertical_rate: Some(-5.08),
            last_measurement: Some(LastMeasurement {
                sensor: Some((25, 1)),
                polar: Some((45_000.0, 123.4)),
                height: Some(3_000.0),
            }),
            address: Default::default(),
            measured_flight_level: Default::default(),
            callsign: Default::default(),
            mode_3a: Default::default(),
        },
        // 1: 2D, tentative, first message; its ADS-B inconsistent with
        // the other surveillance (AFF), an MLAT age alone.
        SystemTrack {
            track_number: 102,
            time_of_day: 45_297.0,
            xy: (1_000.0, -2_000.0),
            velocity: (0.0, -10.0),
            status: TrackStatusFlags {
                tentative: true,
                first_message: true,
                adsb_inconsistent: true,
                ..f
            },
            ages: UpdateAges {
                track: Some(2.0),
                ssr: Some(2.0),
                mlat: Some(7.1),
                ..UpdateAges::default()
            },
            ..SystemTrack::default()
        },
        // 2: coasting 2D, negative coordinates, SSR aged.
        SystemTrack {
            track_number: 103,
            time_of_day: 45_297.5,
            wgs84: Some((-33.946_11, 151.177_22)),
            xy: (-50_000.25, -75_000.75),
            velocity: (-200.0, -1.1),
            status: TrackStatusFlags {
                coasting: true,
                ssr_aged: true,
                ..f
            },
            ages: UpdateAges {
                track: Some(30.0),
                psr: Some(10.0),
                ssr: Some(12.25),
                ..UpdateAges::default()
            },
            last_measurement: Some(LastMeasurement {
                sensor: Some((25, 2)),
                ..LastMeasurement::default()
            }),
            ..SystemTrack::default()
        },
        // 3: the last message of a coasting 3D (GNSS height) track.
        SystemTrack {
            track_number: 104,
            time_of_day: 45_298.25,
            wgs84: Some((0.0, -0.000_1)),
            xy: (250.0, -0.5),
            velocity: (30.0, 40.0),
            status: TrackStatusFlags {
                last_message: true,
                coasting: true,
                altitude_source: AltitudeSource::Gnss,
                ..f
            },
            accuracy: Some(Accuracy {
                xy: Some((10.0, 12.5)),
                velocity: Some((0.5, 0.75)),
                ..Accuracy::default()
            }),
            height: Some(10_000.0),
            vertical_rate: Some(15.0),
            ..SystemTrack::default()
        },
        // 4: monosensor, SPI, simulated, just before midnight (wraps to 0).
        SystemTrack {
            track_number: 105,
            time_of_day: 86_399.998,
            xy: (0.4, -0.4),
            velocity: (0.1, -0.1),
            status: TrackStatusFlags {
                monosensor: true,
                spi: true,
                simulated: true,
                ..f
            },
            ..SystemTrack::default()
        },
        // 5: values out of range: x, vx, height, vertical rate are left
        // out (the record keeps its WGS-84 position).
        SystemTrack {
            track_number: 106,
            time_of_day: 100.0,
            wgs84: Some((48.0, 11.0)),
            xy: (5_000_000.0, 100.0),
            velocity: (9_000.0, 0.0),
            status: TrackStatusFlags {
                altitude_source: AltitudeSource::Radar3d,
                ..f
            },
            height: Some(50_000.0),
            vertical_rate: Some(2_000.0),
            ..SystemTrack::default()
        },
        // 6: ages and accuracies above their maxima (saturated).
        SystemTrack {
            track_number: 107,
            time_of_day: 200.0,
            xy: (-1.0, 1.0),
            velocity: (5.0, 5.0),
            ages: UpdateAges {
                track: Some(100.0),
                psr: Some(100.0),
                ssr: Some(100.0),
                mode_s: Some(100.0),
                adsb_es: Some(100.0),
                mlat: Some(64.0),
            },
            accuracy: Some(Accuracy {
                xy: Some((40_000.0, 1e6)),
                xy_covariance_m2: Some(1e9),
                geometric_altitude: Some(1e4),
                velocity: Some((100.0, 100.0)),
                vertical_rate: Some(100.0),
                ..Accuracy::default()
            }),
            height: Some(500.0),
            ..SystemTrack::default()
        },
        // 7: the extremes of every range.
        SystemTrack {
            track_number: 65_535,
            time_of_day: 0.0,
            wgs84: Some((90.0, -180.0)),
            xy: (4_194_303.5, -4_194_304.0),
            velocity: (8_191.75, -8_192.0),
            status: TrackStatusFlags {
                altitude_source: AltitudeSource::Multilateration,
                ..f
            },
            height: Some(45_720.0),
            vertical_rate: Some(-32_768.0 * 6.25 * 0.3048 / 60.0),
            ..SystemTrack::default()
        },
        // 8: below the ellipsoid, descending, PSR, Mode S and ADS-B aged.
        SystemTrack {
            track_number: 0,
            time_of_day: 3_600.0,
            wgs84: Some((-45.5, -73.25)),
            xy: (-300_000.0, 280_000.0),
            velocity: (-0.25, 0.25),
            status: TrackStatusFlags {
                psr_aged: true,
                mode_s_aged: true,
                adsb_aged: true,
                altitude_source: AltitudeSource::Triangulation,
                ..f
            },
            ages: UpdateAges {
                adsb_es: Some(20.0),
                ..UpdateAges::default()
            },
            height: Some(-400.0),
            vertical_rate: Some(-20.0),
            last_measurement: Some(LastMeasurement {
                sensor: Some((25, 3)),
                polar: Some((1_000.0, -45.0)),
                height: Some(-100.0),
            }),
            ..SystemTrack::default()
        },
        // 9: tentative, coasting, last message; negative covariance.
        SystemTrack {
            track_number: 4_096,
            time_of_day: 43_200.123,
            wgs84: Some((-90.0, 179.99)),
            xy: (12.0, 34.0),
            velocity: (-1_000.0, 1_000.0),
            status: TrackStatusFlags {
                tentative: true,
                coasting: true,
                last_message: true,
                ..f
            },
            accuracy: Some(Accuracy {
                xy_covariance_m2: Some(-2.25),
                wgs84: Some((0.01, 0.02)),
                acceleration: Some((1.0, 2.0)),
                ..Accuracy::default()
            }),
            last_measurement: Some(LastMeasurement {
                polar: Some((370_000.0, 359.999)),
                ..LastMeasurement::default()
            }),
            ..SystemTrack::default()
        },
    ]
}

fn fixture_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/cat062")
}

fn sample_bytes() -> (Encoded, Vec<u8>) {
    let e = encode_records(&sample_config(), &sample_tracks(), SAMPLE_MAX_BLOCK);
    let bytes = e.blocks.concat();
    (e, bytes)
}

/// JSON of an f64 (Rust's shortest round-trip form; the sample has no
/// value that is not finite).
fn num(v: f64) -> String {
    format!("{v:?}")
}

fn opt_num(v: Option<f64>) -> String {
    v.map_or("null".into(), num)
}

fn opt_pair(v: Option<(f64, f64)>) -> String {
    v.map_or("null".into(), |(a, b)| format!("[{}, {}]", num(a), num(b)))
}

fn input_json(tracks: &[SystemTrack]) -> String {
    let c = sample_config();
    let mut s = String::new();
    let _ = write!(
        s,
        "{{\n \"generator\": \"crates/wire-formats/src/cat062/tests/oracle.rs (regenerate_the_cat062_sample)\",\n \
         \"config\": {{\"sac\": {}, \"sic\": {}, \"service_id\": {}}},\n \"max_block\": {},\n \"tracks\": [\n",
        c.sac,
        c.sic,
        c.service_id.map_or("null".into(), |v| v.to_string()),
        SAMPLE_MAX_BLOCK
    );
    for (i, t) in tracks.iter().enumerate() {
        let st = &t.status;
        let a = t.ages;
        let acc = t.accuracy.map_or("null".into(), |a| {
            format!(
                "{{\"xy\": {}, \"xy_covariance_m2\": {}, \"wgs84\": {}, \"geometric_altitude\": {}, \
                 \"velocity\": {}, \"acceleration\": {}, \"vertical_rate\": {}}}",
                opt_pair(a.xy),
                opt_num(a.xy_covariance_m2),
                opt_pair(a.wgs84),
                opt_num(a.geometric_altitude),
                opt_pair(a.velocity),
                opt_pair(a.acceleration),
                opt_num(a.vertical_rate)
            )
        });
        let lm = t.last_measurement.map_or("null".into(), |m| {
            format!(
                "{{\"sensor\": {}, \"polar\": {}, \"height\": {}}}",
                m.sensor
                    .map_or("null".into(), |(a, b)| format!("[{a}, {b}]")),
                opt_pair(m.polar),
                opt_num(m.height)
            )
        });
        let _ = write!(
            s,
            "  {{\"track_number\": {}, \"time_of_day\": {}, \"wgs84\": {}, \"xy\": {}, \"velocity\": {},\n   \
             \"status\": {{\"monosensor\": {}, \"spi\": {}, \"altitude_source\": {}, \"tentative\": {}, \
             \"simulated\": {}, \"last_message\": {}, \"first_message\": {}, \
             \"adsb_inconsistent\": {}, \"coasting\": {}, \
             \"psr_aged\": {}, \"ssr_aged\": {}, \"mode_s_aged\": {}, \"adsb_aged\": {}}},\n   \
             \"ages\": {{\"track\": {}, \"psr\": {}, \"ssr\": {}, \"mode_s\": {}, \
             \"adsb_es\": {}, \"mlat\": {}}},\n   \
             \"accuracy\": {},\n   \"height\": {}, \"vertical_rate\": {},\n   \"last_measurement\": {}}}{}\n",
            t.track_number,
            num(t.time_of_day),
            opt_pair(t.wgs84),
            opt_pair(Some(t.xy)),
            opt_pair(Some(t.velocity)),
            st.monosensor,
            st.spi,
            st.altitude_source as u8,
            st.tentative,
            st.simulated,
            st.last_message,
            st.first_message,
            st.adsb_inconsistent,
            st.coasting,
            st.psr_aged,
            st.ssr_aged,
            st.mode_s_aged,
            st.adsb_aged,
            opt_num(a.track),
            opt_num(a.psr),
            opt_num(a.ssr),
            opt_num(a.mode_s),
            opt_num(a.adsb_es),
            opt_num(a.mlat),
            acc,
            opt_num(t.height),
            opt_num(t.vertical_rate),
            lm,
            if i + 1 < tracks.len() { "," } else { "" }
        );
    }
    s.push_str(" ]\n}\n");
    s
}

#[test]
#[ignore = "writes tests/fixtures/cat062/sample.bin and sample_input.json"]
fn regenerate_the_cat062_sample() {
    let (_, bytes) = sample_bytes();
    let dir = fixture_dir();
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("sample.bin"), &bytes).unwrap();
    std::fs::write(dir.join("sample_input.json"), input_json(&sample_tracks())).unwrap();
}

#[test]
fn the_committed_sample_is_what_the_encoder_writes() {
    let (_, bytes) = sample_bytes();
    let dir = fixture_dir();
    assert_eq!(
        std::fs::read(dir.join("sample.bin")).unwrap(),
        bytes,
        "sample.bin is stale: regenerate it (module docs) and re-run the oracle"
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("sample_input.json")).unwrap(),
        input_json(&sample_tracks())
    );
}

/// A JSON value (the tiny reader of the decoded fixture).
#[derive(Debug, Clone, PartialEq)]
enum Json {
    Null,
    Bool(bool),
    Num(f64),
    Str(String),
    Arr(Vec<Json>),
    Obj(BTreeMap<String, Json>),
}

impl Json {
    fn get(&self, key: &str) -> Option<&Json> {
        match self {
            Json::Obj(m) => m.get(key),
            _ => None,
        }
    }

    fn num(&self) -> f64 {
        match self {
            Json::Num(v) => *v,
            other => panic!("not a number: {other:?}"),
        }
    }

    fn arr(&self) -> &[Json] {
        match self {
            Json::Arr(v) => v,
            other => panic!("not an array: {other:?}"),
        }
    }

    /// `raw` of a decoded element at `path` (item, then subitem names).
    fn raw(&self, path: &[&str]) -> Option<i64> {
        let mut v = self;
        for k in path {
            v = v.get(k)?;
        }
        Some(v.get("raw")?.num() as i64)
    }

    /// `value` (the quantity, in the specification's unit) at `path`.
    fn value(&self, path: &[&str]) -> Option<f64> {
        let mut v = self;
        for k in path {
            v = v.get(k)?;
        }
        Some(v.get("value")?.num())
    }
}

/// A reader of the JSON the oracle writes (objects, arrays, strings
/// without escapes beyond `\"` and `\\` and `\uXXXX`, numbers, literals).
struct Reader<'a> {
    s: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn ws(&mut self) {
        while self.pos < self.s.len() && self.s[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    fn eat(&mut self, c: u8) {
        self.ws();
        assert_eq!(self.s[self.pos], c, "at byte {}", self.pos);
        self.pos += 1;
    }

    fn string(&mut self) -> String {
        self.eat(b'"');
        let mut out = Vec::new();
        loop {
            let c = self.s[self.pos];
            self.pos += 1;
            match c {
                b'"' => break,
                b'\\' => {
                    let e = self.s[self.pos];
                    self.pos += 1;
                    match e {
                        b'u' => {
                            let hex = std::str::from_utf8(&self.s[self.pos..self.pos + 4]).unwrap();
                            let ch = char::from_u32(u32::from_str_radix(hex, 16).unwrap()).unwrap();
                            out.extend_from_slice(ch.to_string().as_bytes());
                            self.pos += 4;
                        }
                        b'n' => out.push(b'\n'),
                        other => out.push(other),
                    }
                }
                other => out.push(other),
            }
        }
        String::from_utf8(out).unwrap()
    }

    fn value(&mut self) -> Json {
        self.ws();
        match self.s[self.pos] {
            b'{' => {
                self.pos += 1;
                let mut m = BTreeMap::new();
                self.ws();
                if self.s[self.pos] == b'}' {
                    self.pos += 1;
                    return Json::Obj(m);
                }
                loop {
                    let k = self.string();
                    self.eat(b':');
                    let v = self.value();
                    m.insert(k, v);
                    self.ws();
                    let c = self.s[self.pos];
                    self.pos += 1;
                    if c == b'}' {
                        return Json::Obj(m);
                    }
                    assert_eq!(c, b',');
                }
            }
            b'[' => {
                self.pos += 1;
                let mut v = Vec::new();
                self.ws();
                if self.s[self.pos] == b']' {
                    self.pos += 1;
                    return Json::Arr(v);
                }
                loop {
                    v.push(self.value());
                    self.ws();
                    let c = self.s[self.pos];
                    self.pos += 1;
                    if c == b']' {
                        return Json::Arr(v);
                    }
                    assert_eq!(c, b',');
                }
            }
            b'"' => Json::Str(self.string()),
            b't' => {
                self.pos += 4;
                Json::Bool(true)
            }
            b'f' => {
                self.pos += 5;
                Json::Bool(false)
            }
            b'n' => {
                self.pos += 4;
                Json::Null
            }
            _ => {
                let start = self.pos;
                while self.pos < self.s.len()
                    && matches!(
                        self.s[self.pos],
                        b'-' | b'+' | b'.' | b'e' | b'E' | b'0'..=b'9'
                    )
                {
                    self.pos += 1;
                }
                let t = std::str::from_utf8(&self.s[start..self.pos]).unwrap();
                Json::Num(t.parse().unwrap_or_else(|_| panic!("number {t:?}")))
            }
        }
    }
}

fn parse_json(s: &str) -> Json {
    let mut r = Reader {
        s: s.as_bytes(),
        pos: 0,
    };
    let v = r.value();
    r.ws();
    assert_eq!(r.pos, s.len(), "trailing data");
    v
}

#[test]
fn the_json_reader_reads_what_it_must() {
    let v = parse_json(r#" {"a": [1, -2.5e3, true, false, null], "b\"": {"c": "\u00b0"}} "#);
    assert_eq!(v.get("a").unwrap().arr()[1], Json::Num(-2500.0));
    assert_eq!(v.get("b\"").unwrap().get("c"), Some(&Json::Str("°".into())));
}

/// Checks of one track against its decoded record.
struct Check<'a> {
    rec: &'a Json,
    track: usize,
    skipped: Vec<&'static str>,
    saturated: Vec<&'static str>,
    compared: usize,
}

impl Check<'_> {
    fn items(&self) -> &Json {
        self.rec.get("items").unwrap()
    }

    /// The decoded value at `path` is `expected` within half its LSB (the
    /// rounding), or absent when the encoder left `name` out.
    fn near(&mut self, name: &'static str, path: &[&str], expected: Option<f64>, half_lsb: f64) {
        let got = self.items().value(path);
        let expected = if self.skipped.contains(&name) {
            None
        } else {
            expected
        };
        match (expected, got) {
            (None, None) => {}
            (Some(e), Some(g)) => assert!(
                (e - g).abs() <= half_lsb * (1.0 + 1e-9),
                "track {}: {name} {path:?}: libasterix decoded {g}, the input was {e}",
                self.track
            ),
            (e, g) => panic!(
                "track {}: {name} {path:?}: input {e:?}, decoded {g:?}",
                self.track
            ),
        }
        self.compared += 1;
    }

    fn exact(&mut self, path: &[&str], expected: Option<i64>) {
        assert_eq!(
            self.items().raw(path),
            expected,
            "track {}: {path:?}",
            self.track
        );
        self.compared += 1;
    }

    /// A subfield with "maximum value or above": the value, or the
    /// maximum when the encoder saturated it.
    fn capped(&mut self, name: &'static str, path: &[&str], v: Option<f64>, max: f64, lsb: f64) {
        let expected = if self.saturated.contains(&name) {
            v.map(|_| max)
        } else {
            v
        };
        self.near(name, path, expected, lsb / 2.0);
    }
}

const FT: f64 = 0.3048;

#[test]
fn libasterix_decodes_the_sample_to_its_inputs() {
    let text = std::fs::read_to_string(fixture_dir().join("sample_decoded.json")).unwrap();
    let decoded = parse_json(&text);
    let (e, bytes) = sample_bytes();
    let blocks = decoded.get("blocks").unwrap().arr();
    assert_eq!(blocks.len(), e.blocks.len());
    let records: Vec<&Json> = blocks
        .iter()
        .flat_map(|b| b.get("records").unwrap().arr())
        .collect();
    assert_eq!(
        decoded.get("bytes").unwrap().num() as usize,
        bytes.len(),
        "sample_decoded.json is not of the current sample.bin"
    );
    let tracks = sample_tracks();
    assert_eq!(records.len(), tracks.len());
    let c = sample_config();
    let mut compared = 0;
    let lsb_wgs = 180.0 / 33_554_432.0;
    for (i, (t, rec)) in tracks.iter().zip(&records).enumerate() {
        let of = |list: &[Skip]| {
            list.iter()
                .filter(|s| s.track_index == i)
                .map(|s| s.item)
                .collect::<Vec<_>>()
        };
        let mut k = Check {
            rec,
            track: i,
            skipped: of(&e.skipped),
            saturated: of(&e.saturated),
            compared: 0,
        };
        k.exact(&["010", "SAC"], Some(c.sac.into()));
        k.exact(&["010", "SIC"], Some(c.sic.into()));
        k.exact(&["015"], c.service_id.map(i64::from));
        k.exact(&["040"], Some(t.track_number.into()));
        // Time modulo the day, within 1/256 s (one record wraps to 0).
        let tod = k.items().value(&["070"]).unwrap();
        let want = t.time_of_day.rem_euclid(86_400.0);
        let d = (tod - want).rem_euclid(86_400.0);
        assert!(
            d.min(86_400.0 - d) <= 1.0 / 256.0,
            "track {i}: time {tod} vs {want}"
        );
        k.compared += 1;
        let lat = t.wgs84.map(|p| p.0);
        let lon = t.wgs84.map(|p| p.1);
        let wgs_skipped = k.skipped.iter().any(|s| s.starts_with("I062/105"));
        k.near(
            "I062/105 LAT",
            &["105", "LAT"],
            lat.filter(|_| !wgs_skipped),
            lsb_wgs / 2.0,
        );
        k.near(
            "I062/105 LON",
            &["105", "LON"],
            lon.filter(|_| !wgs_skipped),
            lsb_wgs / 2.0,
        );
        let xy_skipped = k.skipped.iter().any(|s| s.starts_with("I062/100"));
        let xy = Some(t.xy).filter(|_| !xy_skipped);
        k.near("I062/100 X", &["100", "X"], xy.map(|p| p.0), 0.25);
        k.near("I062/100 Y", &["100", "Y"], xy.map(|p| p.1), 0.25);
        let v_skipped = k.skipped.iter().any(|s| s.starts_with("I062/185"));
        let v = Some(t.velocity).filter(|_| !v_skipped);
        k.near("I062/185 VX", &["185", "VX"], v.map(|p| p.0), 0.125);
        k.near("I062/185 VY", &["185", "VY"], v.map(|p| p.1), 0.125);
        let height = t.height.filter(|_| !k.skipped.contains(&"I062/130"));
        k.near("I062/130", &["130"], height.map(|h| h / FT), 6.25 / 2.0);
        k.near(
            "I062/220",
            &["220"],
            t.vertical_rate.map(|v| v / FT * 60.0),
            6.25 / 2.0,
        );
        // I062/080: every flag, MRH/SRC by I062/130, and the octets.
        let s = &t.status;
        let b = |v: bool| Some(i64::from(v));
        k.exact(&["080", "MON"], b(s.monosensor));
        k.exact(&["080", "SPI"], b(s.spi));
        k.exact(&["080", "MRH"], b(height.is_some()));
        let src = if height.is_some() {
            s.altitude_source as i64
        } else {
            0
        };
        k.exact(&["080", "SRC"], Some(src));
        k.exact(&["080", "CNF"], b(s.tentative));
        let ext1 = s.simulated || s.last_message || s.first_message || s.adsb_inconsistent;
        let ext3 = s.coasting || s.psr_aged || s.ssr_aged || s.mode_s_aged || s.adsb_aged;
        let octets = if ext3 {
            4
        } else if ext1 {
            2
        } else {
            1
        };
        assert_eq!(
            k.items().get("080").unwrap().get("_octets").unwrap().num() as i64,
            octets,
            "track {i}: I062/080 octets"
        );
        k.compared += 1;
        let when = |present: bool, v: bool| if present { b(v) } else { None };
        k.exact(&["080", "SIM"], when(octets >= 2, s.simulated));
        k.exact(&["080", "TSE"], when(octets >= 2, s.last_message));
        k.exact(&["080", "TSB"], when(octets >= 2, s.first_message));
        k.exact(&["080", "AFF"], when(octets >= 2, s.adsb_inconsistent));
        k.exact(&["080", "CST"], when(octets >= 4, s.coasting));
        k.exact(&["080", "PSR"], when(octets >= 4, s.psr_aged));
        k.exact(&["080", "SSR"], when(octets >= 4, s.ssr_aged));
        k.exact(&["080", "MDS"], when(octets >= 4, s.mode_s_aged));
        k.exact(&["080", "ADS"], when(octets >= 4, s.adsb_aged));
        // I062/290.
        let a = t.ages;
        for (name, sub, v) in [
            ("I062/290 TRK", "TRK", a.track),
            ("I062/290 PSR", "PSR", a.psr),
            ("I062/290 SSR", "SSR", a.ssr),
            ("I062/290 MDS", "MDS", a.mode_s),
            ("I062/290 ES", "ES", a.adsb_es),
            ("I062/290 MLT", "MLT", a.mlat),
        ] {
            k.capped(name, &["290", sub], v, 63.75, 0.25);
        }
        // I062/500.
        let acc = t.accuracy.unwrap_or_default();
        let p = |v: Option<(f64, f64)>, first: bool| v.map(|p| if first { p.0 } else { p.1 });
        k.capped(
            "I062/500 APC X",
            &["500", "APC", "X"],
            p(acc.xy, true),
            32_767.5,
            0.5,
        );
        k.capped(
            "I062/500 APC Y",
            &["500", "APC", "Y"],
            p(acc.xy, false),
            32_767.5,
            0.5,
        );
        let cov = acc.xy_covariance_m2.map(|c| c.signum() * c.abs().sqrt());
        k.capped("I062/500 COV", &["500", "COV"], cov, 16_383.5, 0.5);
        k.capped(
            "I062/500 APW LAT",
            &["500", "APW", "LAT"],
            p(acc.wgs84, true),
            65_535.0 * lsb_wgs,
            lsb_wgs,
        );
        k.capped(
            "I062/500 APW LON",
            &["500", "APW", "LON"],
            p(acc.wgs84, false),
            65_535.0 * lsb_wgs,
            lsb_wgs,
        );
        k.capped(
            "I062/500 AGA",
            &["500", "AGA"],
            acc.geometric_altitude.map(|v| v / FT),
            255.0 * 6.25,
            6.25,
        );
        k.capped(
            "I062/500 ATV X",
            &["500", "ATV", "X"],
            p(acc.velocity, true),
            63.75,
            0.25,
        );
        k.capped(
            "I062/500 ATV Y",
            &["500", "ATV", "Y"],
            p(acc.velocity, false),
            63.75,
            0.25,
        );
        k.capped(
            "I062/500 AA X",
            &["500", "AA", "X"],
            p(acc.acceleration, true),
            63.75,
            0.25,
        );
        k.capped(
            "I062/500 AA Y",
            &["500", "AA", "Y"],
            p(acc.acceleration, false),
            63.75,
            0.25,
        );
        k.capped(
            "I062/500 ARC",
            &["500", "ARC"],
            acc.vertical_rate.map(|v| v / FT * 60.0),
            255.0 * 6.25,
            6.25,
        );
        // I062/340.
        let m = t.last_measurement.unwrap_or_default();
        k.exact(&["340", "SID", "SAC"], m.sensor.map(|s| s.0.into()));
        k.exact(&["340", "SID", "SIC"], m.sensor.map(|s| s.1.into()));
        let pos_skipped = k.skipped.iter().any(|s| s.starts_with("I062/340 POS"));
        let polar = m.polar.filter(|_| !pos_skipped);
        k.near(
            "I062/340 POS RHO",
            &["340", "POS", "RHO"],
            polar.map(|p| p.0 / 1852.0),
            1.0 / 512.0,
        );
        let theta = polar.map(|p| p.1.rem_euclid(360.0));
        let got = k.items().value(&["340", "POS", "THETA"]);
        if let (Some(w), Some(g)) = (theta, got) {
            let d = (g - w).rem_euclid(360.0);
            assert!(
                d.min(360.0 - d) <= 360.0 / 131_072.0,
                "track {i}: THETA {g} vs {w}"
            );
        } else {
            assert_eq!(theta.is_some(), got.is_some(), "track {i}: THETA");
        }
        k.compared += 1;
        k.near(
            "I062/340 HEIGHT",
            &["340", "HEIGHT"],
            m.height.map(|h| h / FT),
            12.5,
        );
        compared += k.compared;
    }
    // Every one of the 50 checks above, for each of the 10 records.
    assert_eq!(compared, 50 * tracks.len());
}
