//! The CAT021 (ADS-B) and CAT020 (multilateration) decoders against an
//! independent encoder and decoder, field for field, through the public
//! API only.
//!
//! The fixtures (`tests/fixtures/cat021/{adsb,mlat,mixed}.bin` and
//! `expected.json`) are written by `checks/cat021_fixture.py` with
//! libasterix 0.36.3 (PyPI; CAT021 2.7, CAT020 1.11, CAT048 1.32, CAT034
//! 1.29): the expected values are that library's decoding, converted to
//! SI there (1 ft = 0.3048 m, 1 NM = 1852 m, 1 kt = 1852/3600 m/s), and
//! the derived ones (the precise reception time from FSI, east/north
//! velocity, σ from NACp) are computed there by their own formulas.
//! Values agree to 1e-9 relative: the two sides multiply the same raw
//! integers by the same LSBs, in an order that may differ.

use serde_json::Value;
use wire_formats::asterix::cat021::AirSpeed;
use wire_formats::asterix::{self, AdsbReport, CooperativeReport, Decoded, MlatReport};

const ADSB: &[u8] = include_bytes!("../../../tests/fixtures/cat021/adsb.bin");
const MLAT: &[u8] = include_bytes!("../../../tests/fixtures/cat021/mlat.bin");
const MIXED: &[u8] = include_bytes!("../../../tests/fixtures/cat021/mixed.bin");
const EXPECTED: &str = include_str!("../../../tests/fixtures/cat021/expected.json");

fn expected(file: &str) -> Vec<Value> {
    let all: Value = serde_json::from_str(EXPECTED).expect("fixture JSON");
    all["files"][file].as_array().expect("records").clone()
}

/// Equal to 1e-9 relative (1e-9 absolute below 1).
fn close(got: f64, want: f64) -> bool {
    (got - want).abs() <= 1e-9 * want.abs().max(1.0)
}

#[track_caller]
fn same_f64(got: Option<f64>, want: &Value, what: &str) {
    match (got, want.as_f64()) {
        (None, None) => {}
        (Some(g), Some(w)) if close(g, w) => {}
        (g, w) => panic!("{what}: decoded {g:?}, libasterix {w:?}"),
    }
}

#[track_caller]
fn same_u64(got: Option<u64>, want: &Value, what: &str) {
    assert_eq!(got, want.as_u64(), "{what}");
}

#[track_caller]
fn same_bool(got: Option<bool>, want: &Value, what: &str) {
    assert_eq!(got, want.as_u64().map(|b| b == 1), "{what}");
}

#[track_caller]
fn same_pair(got: Option<(f64, f64)>, want: &Value, what: &str) {
    match (got, want.as_array()) {
        (None, None) => {}
        (Some((a, b)), Some(w)) if w.len() == 2 => {
            same_f64(Some(a), &w[0], what);
            same_f64(Some(b), &w[1], what);
        }
        (g, w) => panic!("{what}: decoded {g:?}, libasterix {w:?}"),
    }
}

fn octal(code: Option<u16>) -> Option<String> {
    code.map(|c| format!("{c:04o}"))
}

fn check_adsb(r: &AdsbReport, e: &Value) {
    let at = format!("CAT021 record at {}", e["offset"]);
    let at = at.as_str();
    assert_eq!(r.offset as u64, e["offset"].as_u64().unwrap(), "{at}");
    let source = (
        e["sac"].as_u64().unwrap() as u8,
        e["sic"].as_u64().unwrap() as u8,
    );
    assert_eq!(r.source, Some(source), "{at}");
    assert_eq!(
        r.descriptor.is_some(),
        e["descriptor"] == true,
        "{at}: I021/040"
    );
    if let Some(d) = r.descriptor {
        same_u64(Some(d.atp.into()), &e["d_atp"], at);
        same_u64(Some(d.arc.into()), &e["d_arc"], at);
        same_bool(Some(d.rc), &e["d_rc"], at);
        same_bool(Some(d.rab), &e["d_rab"], at);
        same_bool(d.dcr, &e["d_dcr"], at);
        same_bool(d.ground_bit, &e["d_gbs"], at);
        same_bool(d.simulated, &e["d_sim"], at);
        same_bool(d.test, &e["d_tst"], at);
        same_bool(d.saa_not_capable, &e["d_saa"], at);
        same_u64(d.confidence.map(u64::from), &e["d_cl"], at);
        same_bool(d.list_lookup_failed, &e["d_llc"], at);
        same_bool(d.position_check_failed, &e["d_ipc"], at);
        same_bool(d.nogo, &e["d_nogo"], at);
        same_bool(d.cpr_failed, &e["d_cpr"], at);
        same_bool(d.position_jump, &e["d_ldpj"], at);
        same_bool(d.range_check_failed, &e["d_rcf"], at);
    }
    same_u64(r.track_number.map(u64::from), &e["track_number"], at);
    same_f64(r.toa_position_s, &e["toa_position_s"], at);
    same_f64(r.toa_velocity_s, &e["toa_velocity_s"], at);
    same_f64(r.tomr_position_s, &e["tomr_position_s"], at);
    same_f64(r.tomr_velocity_s, &e["tomr_velocity_s"], at);
    same_f64(r.tort_s, &e["tort_s"], at);
    let p = r.tomr_position_precise;
    same_u64(p.map(|p| p.fsi.into()), &e["tomr_position_fsi"], at);
    same_f64(p.map(|p| p.fraction_s), &e["tomr_position_fraction_s"], at);
    same_f64(
        r.tomr_position_precise_s(),
        &e["tomr_position_precise_s"],
        at,
    );
    let v = r.tomr_velocity_precise;
    same_u64(v.map(|v| v.fsi.into()), &e["tomr_velocity_fsi"], at);
    same_f64(v.map(|v| v.fraction_s), &e["tomr_velocity_fraction_s"], at);
    same_f64(
        r.tomr_velocity_precise_s(),
        &e["tomr_velocity_precise_s"],
        at,
    );
    same_f64(r.position_deg.map(|p| p.0), &e["lat_deg"], at);
    same_f64(r.position_deg.map(|p| p.1), &e["lon_deg"], at);
    same_f64(r.position_high_res_deg.map(|p| p.0), &e["lat_hr_deg"], at);
    same_f64(r.position_high_res_deg.map(|p| p.1), &e["lon_hr_deg"], at);
    let ias = r.air_speed.and_then(|a| match a {
        AirSpeed::Ias { mps } => Some(mps),
        AirSpeed::Mach(_) => None,
    });
    let mach = r.air_speed.and_then(|a| match a {
        AirSpeed::Mach(m) => Some(m),
        AirSpeed::Ias { .. } => None,
    });
    same_f64(ias, &e["ias_mps"], at);
    same_f64(mach, &e["mach"], at);
    same_f64(r.true_airspeed_mps.map(|t| t.value), &e["tas_mps"], at);
    same_bool(r.true_airspeed_mps.map(|t| t.exceeded), &e["tas_re"], at);
    same_u64(r.address.map(u64::from), &e["address"], at);
    same_f64(
        r.geometric_height_m.map(|h| h.value),
        &e["geometric_height_m"],
        at,
    );
    assert_eq!(
        r.geometric_height_m.map(|h| h.exceeded),
        e["geometric_height_greater_than"].as_bool(),
        "{at}"
    );
    let q = r.quality;
    same_u64(q.map(|q| q.nucr_nacv.into()), &e["q_nucrnacv"], at);
    same_u64(q.map(|q| q.nucp_nic.into()), &e["q_nucpnic"], at);
    same_bool(q.and_then(|q| q.nic_baro), &e["q_nicbaro"], at);
    same_u64(q.and_then(|q| q.sil).map(u64::from), &e["q_sil"], at);
    same_u64(q.and_then(|q| q.nacp).map(u64::from), &e["q_nacp"], at);
    same_bool(q.and_then(|q| q.sil_per_sample), &e["q_sils"], at);
    same_u64(q.and_then(|q| q.sda).map(u64::from), &e["q_sda"], at);
    same_u64(q.and_then(|q| q.gva).map(u64::from), &e["q_gva"], at);
    same_u64(q.and_then(|q| q.pic).map(u64::from), &e["q_pic"], at);
    same_bool(r.mops.map(|m| m.not_supported), &e["mops_vns"], at);
    same_u64(r.mops.map(|m| m.version.into()), &e["mops_vn"], at);
    same_u64(r.mops.map(|m| m.link.into()), &e["mops_ltt"], at);
    assert_eq!(
        octal(r.mode_3a),
        e["mode_3a"].as_str().map(str::to_string),
        "{at}"
    );
    same_f64(r.flight_level, &e["flight_level"], at);
    let s = r.status;
    same_bool(s.map(|s| s.intent_change), &e["s_icf"], at);
    same_bool(s.map(|s| s.lnav_not_engaged), &e["s_lnav"], at);
    same_bool(s.map(|s| s.military_emergency), &e["s_me"], at);
    same_u64(s.map(|s| s.priority.into()), &e["s_ps"], at);
    same_u64(s.map(|s| s.surveillance.into()), &e["s_ss"], at);
    let b = r.barometric_vertical_rate_mps;
    same_f64(b.map(|b| b.value), &e["bvr_mps"], at);
    same_bool(b.map(|b| b.exceeded), &e["bvr_re"], at);
    let g = r.geometric_vertical_rate_mps;
    same_f64(g.map(|g| g.value), &e["gvr_mps"], at);
    same_bool(g.map(|g| g.exceeded), &e["gvr_re"], at);
    let gv = r.ground_vector;
    same_f64(gv.map(|g| g.speed_mps), &e["gs_mps"], at);
    same_f64(gv.map(|g| g.track_deg), &e["track_deg"], at);
    same_bool(gv.map(|g| g.exceeded), &e["gv_re"], at);
    assert_eq!(r.callsign.as_deref(), e["callsign"].as_str(), "{at}");
    same_u64(
        r.emitter_category.map(u64::from),
        &e["emitter_category"],
        at,
    );
    // The tracker's view.
    same_f64(
        r.time_of_applicability_s(),
        &e["time_of_applicability_s"],
        at,
    );
    let lat_lon = match (&e["lat_hr_deg"], &e["lat_deg"]) {
        (Value::Null, Value::Null) => Value::Null,
        (Value::Null, lat) => serde_json::json!([lat, e["lon_deg"]]),
        (lat, _) => serde_json::json!([lat, e["lon_hr_deg"]]),
    };
    same_pair(r.lat_lon_deg(), &lat_lon, at);
    let height = match e["geometric_height_greater_than"] {
        Value::Bool(true) => Value::Null,
        _ => e["geometric_height_m"].clone(),
    };
    same_f64(CooperativeReport::geometric_height_m(r), &height, at);
    same_pair(r.velocity_en_mps(), &e["velocity_en_mps"], at);
    let sigma = &e["position_sigma_m"];
    same_pair(
        r.position_sigma_m(),
        &if sigma.is_null() {
            Value::Null
        } else {
            serde_json::json!([sigma, sigma])
        },
        at,
    );
    assert_eq!(
        CooperativeReport::callsign(r),
        e["callsign"].as_str(),
        "{at}"
    );
    same_u64(
        CooperativeReport::address(r).map(u64::from),
        &e["address"],
        at,
    );
    same_f64(CooperativeReport::flight_level(r), &e["flight_level"], at);
    assert_eq!(
        r.simulated_or_test(),
        e["simulated_or_test"] == true,
        "{at}"
    );
}

fn check_mlat(r: &MlatReport, e: &Value) {
    let at = format!("CAT020 record at {}", e["offset"]);
    let at = at.as_str();
    assert_eq!(r.offset as u64, e["offset"].as_u64().unwrap(), "{at}");
    let source = (
        e["sac"].as_u64().unwrap() as u8,
        e["sic"].as_u64().unwrap() as u8,
    );
    assert_eq!(r.source, Some(source), "{at}");
    assert_eq!(
        r.descriptor.is_some(),
        e["descriptor"] == true,
        "{at}: I020/020"
    );
    if let Some(d) = r.descriptor {
        same_bool(Some(d.ssr), &e["d_ssr"], at);
        same_bool(Some(d.mode_s), &e["d_ms"], at);
        same_bool(Some(d.hf), &e["d_hf"], at);
        same_bool(Some(d.vdl4), &e["d_vdl4"], at);
        same_bool(Some(d.uat), &e["d_uat"], at);
        same_bool(Some(d.dme), &e["d_dme"], at);
        same_bool(Some(d.other), &e["d_ot"], at);
        same_bool(d.rab, &e["d_rab"], at);
        same_bool(d.spi, &e["d_spi"], at);
        same_bool(d.chain_2, &e["d_chn"], at);
        same_bool(d.ground_bit, &e["d_gbs"], at);
        same_bool(d.corrupted, &e["d_crt"], at);
        same_bool(d.simulated, &e["d_sim"], at);
        same_bool(d.test, &e["d_tst"], at);
        same_u64(d.cf.map(u64::from), &e["d_cf"], at);
    }
    same_f64(r.time_of_day_s, &e["time_of_day_s"], at);
    same_f64(r.position_deg.map(|p| p.0), &e["lat_deg"], at);
    same_f64(r.position_deg.map(|p| p.1), &e["lon_deg"], at);
    same_f64(r.position_xy_m.map(|p| p.0), &e["x_m"], at);
    same_f64(r.position_xy_m.map(|p| p.1), &e["y_m"], at);
    same_u64(r.track_number.map(u64::from), &e["track_number"], at);
    assert_eq!(
        octal(r.mode_3a),
        e["mode_3a"].as_str().map(str::to_string),
        "{at}"
    );
    let f = r.mode_3a_flags;
    same_bool(f.map(|f| !f.validated), &e["mode_3a_v"], at);
    same_bool(f.map(|f| f.garbled), &e["mode_3a_g"], at);
    same_bool(f.map(|f| f.smoothed), &e["mode_3a_l"], at);
    same_f64(r.velocity_xy_mps.map(|v| v.0), &e["vx_mps"], at);
    same_f64(r.velocity_xy_mps.map(|v| v.1), &e["vy_mps"], at);
    same_f64(r.flight_level, &e["flight_level"], at);
    let f = r.flight_level_flags;
    same_bool(f.map(|f| !f.validated), &e["flight_level_v"], at);
    same_bool(f.map(|f| f.garbled), &e["flight_level_g"], at);
    same_u64(r.address.map(u64::from), &e["address"], at);
    assert_eq!(r.callsign.as_deref(), e["callsign"].as_str(), "{at}");
    same_u64(r.callsign_source.map(u64::from), &e["callsign_sti"], at);
    same_f64(r.geometric_height_m, &e["geometric_height_m"], at);
    assert_eq!(
        r.accuracy.is_some(),
        e["accuracy"] == true,
        "{at}: I020/500"
    );
    let a = r.accuracy.unwrap_or_default();
    match (a.dop, e["dop"].as_array()) {
        (None, None) => {}
        (Some(d), Some(w)) => {
            same_f64(Some(d.x), &w[0], at);
            same_f64(Some(d.y), &w[1], at);
            same_u64(Some(d.xy_raw.into()), &w[2], at);
        }
        (g, w) => panic!("{at}: DOP {g:?}, libasterix {w:?}"),
    }
    match (a.sdp, e["sdp"].as_array()) {
        (None, None) => {}
        (Some(s), Some(w)) => {
            same_f64(Some(s.sigma_x_m), &w[0], at);
            same_f64(Some(s.sigma_y_m), &w[1], at);
            same_u64(Some(s.xy_raw.into()), &w[2], at);
        }
        (g, w) => panic!("{at}: SDP {g:?}, libasterix {w:?}"),
    }
    same_f64(a.sigma_height_m, &e["sdh_m"], at);
    // The tracker's view.
    same_f64(r.time_of_applicability_s(), &e["time_of_day_s"], at);
    let lat_lon = if e["lat_deg"].is_null() {
        Value::Null
    } else {
        serde_json::json!([e["lat_deg"], e["lon_deg"]])
    };
    same_pair(r.lat_lon_deg(), &lat_lon, at);
    let v = if e["vx_mps"].is_null() {
        Value::Null
    } else {
        serde_json::json!([e["vx_mps"], e["vy_mps"]])
    };
    same_pair(r.velocity_en_mps(), &v, at);
    same_pair(r.position_sigma_m(), &e["position_sigma_m"], at);
    same_f64(
        CooperativeReport::geometric_height_m(r),
        &e["geometric_height_m"],
        at,
    );
    assert_eq!(
        r.simulated_or_test(),
        e["simulated_or_test"] == true,
        "{at}"
    );
}

/// Checks every record of `d` against the fixture's records of `file`, in
/// data order, whatever their category.
fn check_file(d: &Decoded, file: &str) {
    assert!(d.errors.is_empty(), "{file}: {:?}", d.errors);
    let want = expected(file);
    let count = |cat: u64| want.iter().filter(|r| r["category"] == cat).count();
    assert_eq!(d.adsb_reports.len(), count(21), "{file}");
    assert_eq!(d.mlat_reports.len(), count(20), "{file}");
    assert_eq!(d.target_reports.len(), count(48), "{file}");
    assert_eq!(d.service_messages.len(), count(34), "{file}");
    let (mut i21, mut i20, mut i48, mut i34) = (0, 0, 0, 0);
    for e in &want {
        match e["category"].as_u64() {
            Some(21) => {
                check_adsb(&d.adsb_reports[i21], e);
                i21 += 1;
            }
            Some(20) => {
                check_mlat(&d.mlat_reports[i20], e);
                i20 += 1;
            }
            Some(48) => {
                let t = &d.target_reports[i48];
                i48 += 1;
                assert_eq!(t.offset as u64, e["offset"].as_u64().unwrap());
                same_f64(t.time_of_day_s, &e["time_of_day_s"], "CAT048");
                same_u64(t.source.map(|s| s.1.into()), &e["sic"], "CAT048");
            }
            Some(34) => {
                let m = &d.service_messages[i34];
                i34 += 1;
                assert_eq!(m.offset as u64, e["offset"].as_u64().unwrap());
                same_u64(m.message_type.map(u64::from), &e["message_type"], "CAT034");
            }
            other => panic!("{file}: unexpected category {other:?}"),
        }
    }
}

#[test]
fn the_adsb_fixture_decodes_field_for_field_as_libasterix_decodes_it() {
    check_file(&asterix::decode(ADSB), "adsb.bin");
}

#[test]
fn the_mlat_fixture_decodes_field_for_field_as_libasterix_decodes_it() {
    check_file(&asterix::decode(MLAT), "mlat.bin");
}

#[test]
fn a_datagram_of_all_four_categories_gives_each_its_records() {
    let d = asterix::decode(MIXED);
    assert_eq!(d.blocks, 6);
    check_file(&d, "mixed.bin");
}

#[test]
fn the_fixture_exercises_what_it_claims() {
    // Guards against a regenerated fixture that silently drops a case:
    // negative heights, "greater than", RE bits, FSI 1 and 2, Mach, a
    // high-resolution position, simulated/test targets, each /500
    // subfield alone or together.
    let a = asterix::decode(ADSB).adsb_reports;
    assert!(
        a.iter()
            .any(|r| r.geometric_height_m.is_some_and(|h| h.value < 0.0))
    );
    assert!(
        a.iter()
            .any(|r| r.geometric_height_m.is_some_and(|h| h.exceeded))
    );
    assert!(
        a.iter()
            .any(|r| r.ground_vector.is_some_and(|g| g.exceeded))
    );
    assert!(
        a.iter()
            .any(|r| r.true_airspeed_mps.is_some_and(|t| t.exceeded))
    );
    for fsi in 0..=3 {
        assert!(
            a.iter()
                .flat_map(|r| [r.tomr_position_precise, r.tomr_velocity_precise])
                .flatten()
                .any(|p| p.fsi == fsi),
            "FSI {fsi}"
        );
    }
    assert!(
        a.iter()
            .any(|r| matches!(r.air_speed, Some(AirSpeed::Mach(_))))
    );
    assert!(a.iter().any(|r| r.position_high_res_deg.is_some()));
    assert!(a.iter().any(|r| r.simulated_or_test()));
    assert!(a.iter().any(|r| r.quality.is_some_and(|q| q.pic.is_some())));
    let m = asterix::decode(MLAT).mlat_reports;
    assert!(
        m.iter()
            .any(|r| r.geometric_height_m.is_some_and(|h| h < 0.0))
    );
    let acc: Vec<_> = m.iter().filter_map(|r| r.accuracy).collect();
    assert!(
        acc.iter()
            .any(|a| a.dop.is_some() && a.sdp.is_some() && a.sigma_height_m.is_some())
    );
    assert!(acc.iter().any(|a| a.dop.is_none() && a.sdp.is_some()));
    assert!(
        acc.iter()
            .any(|a| a.sdp.is_none() && a.sigma_height_m.is_some())
    );
    assert!(m.iter().any(|r| r.simulated_or_test()));
}
