//! Cooperative reports (ADS-B) in the tracker, alone and beside a Mode S
//! radar: one track per aircraft, its sources, outages, spoofing.

use super::tests::{Lcg, Target};
use super::*;

const ADDRESS_A: u32 = 0x3C_6586;
const ADDRESS_B: u32 = 0x40_0A1F;

/// A 2D Mode S radar at the origin: 100 m in range, 1.5 mrad (≈ 45 m
/// across at 30 km), a 4-s scan.
fn mode_s_radar() -> RadarSpec {
    RadarSpec {
        site: [0.0, 0.0, 0.0],
        sigma_range: 100.0,
        sigma_azimuth: 1.5e-3,
        sigma_elevation: None,
        sigma_radial_velocity: None,
        scan_period: 4.0,
        detection_probability: 0.99,
        clutter_density: 1e-7,
    }
}

fn config() -> TrackerConfig {
    let mut c = TrackerConfig::new(2, vec![mode_s_radar()]);
    c.motion = Motion::ConstantVelocity;
    c.sigma_a = [0.5; 3];
    c
}

/// Two aircraft 8 km apart flying east and north-east at 200 m/s.
fn aircraft() -> [(Target, u32); 2] {
    [
        (
            Target {
                p0: [-20_000.0, 30_000.0, 0.0],
                v: [200.0, 0.0, 0.0],
            },
            ADDRESS_A,
        ),
        (
            Target {
                p0: [-20_000.0, 22_000.0, 0.0],
                v: [141.0, 141.0, 0.0],
            },
            ADDRESS_B,
        ),
    ]
}

fn identity(address: u32) -> Identity {
    Identity {
        address: Some(address),
        mode_c: Some(ModeC {
            flight_level: 350.0,
            validated: true,
            garbled: false,
        }),
        detection: Some(Detection::Secondary),
        ..Default::default()
    }
}

/// ADS-B reports of each aircraft every second in [from, to), σ 10 m
/// (NACp 9 claims an EPU under 30 m: σ = 30/2.45 = 12 m) and 1 m/s, with
/// `offset(t, address)` added to the reported position (a spoof).
fn adsb(
    cfg: &TrackerConfig,
    span: (f64, f64),
    offset: &dyn Fn(f64, u32) -> [f64; 2],
    rng: &mut Lcg,
) -> Vec<Plot> {
    let sensor = cfg.report_sensor(ReportKind::Adsb);
    let mut out = Vec::new();
    let mut t = span.0;
    while t < span.1 {
        for (i, (target, address)) in aircraft().iter().enumerate() {
            // Each aircraft's reports at its own times.
            let ti = t + 0.37 * i as f64;
            let p = target.at(ti);
            let o = offset(ti, *address);
            let report = Report {
                kind: ReportKind::Adsb,
                position: [
                    p[0] + o[0] + 10.0 * rng.normal(),
                    p[1] + o[1] + 10.0 * rng.normal(),
                    0.0,
                ],
                sigma_horizontal: 10.0,
                sigma_vertical: None,
                velocity: Some([target.v[0] + rng.normal(), target.v[1] + rng.normal(), 0.0]),
                sigma_velocity: 1.0,
                sigma_vertical_velocity: None,
            };
            out.push(Plot::report(sensor, ti, report, identity(*address)));
        }
        t += 1.0;
    }
    out
}

/// The radar's Mode S plots of each aircraft every scan in [0, to)
/// (beam-timed: each at the time the beam crosses it).
fn radar_plots(to: f64, rng: &mut Lcg) -> Vec<Plot> {
    biased_radar_plots(to, [0.0; 2], rng)
}

/// As [`radar_plots`], the radar measuring ρ + `bias[0]`, θ + `bias[1]`.
fn biased_radar_plots(to: f64, bias: [f64; 2], rng: &mut Lcg) -> Vec<Plot> {
    let r = mode_s_radar();
    let mut out = Vec::new();
    let mut scan = 0.0;
    while scan < to {
        for (target, address) in aircraft() {
            let p0 = target.at(scan);
            let az0 = p0[0].atan2(p0[1]).rem_euclid(std::f64::consts::TAU);
            let t = scan + r.scan_period * az0 / std::f64::consts::TAU;
            let p = target.at(t);
            out.push(Plot {
                radar: 0,
                t,
                range: p[0].hypot(p[1]) + bias[0] + r.sigma_range * rng.normal(),
                azimuth: p[0].atan2(p[1]) + bias[1] + r.sigma_azimuth * rng.normal(),
                elevation: None,
                radial_velocity: None,
                identity: identity(address),
                report: None,
            });
        }
        scan += r.scan_period;
    }
    out
}

fn run(cfg: &TrackerConfig, mut plots: Vec<Plot>) -> Tracker {
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    // In one-second batches, as a session takes them.
    let end = plots.last().map_or(0.0, |p| p.t);
    let mut from = 0;
    let mut t = 1.0;
    while from < plots.len() {
        let to = from + plots[from..].partition_point(|p| p.t < t);
        tracker.process(&plots[from..to]).unwrap();
        from = to;
        t += 1.0;
    }
    tracker.flush().unwrap();
    assert!(end > 0.0);
    tracker
}

fn track_of(tracker: &Tracker, address: u32) -> Vec<TrackOutput> {
    tracker
        .confirmed_tracks()
        .into_iter()
        .filter(|t| t.identity.address.is_some_and(|a| a.value == address))
        .collect()
}

fn error(track: &TrackOutput, target: &Target) -> f64 {
    let p = target.at(track.t);
    (track.state[0] - p[0]).hypot(track.state[2] - p[1])
}

#[test]
fn adsb_reports_alone_track_each_aircraft_once() {
    let cfg = config();
    let mut rng = Lcg(7);
    let tracker = run(&cfg, adsb(&cfg, (0.0, 60.0), &|_, _| [0.0; 2], &mut rng));
    let tracks = tracker.confirmed_tracks();
    assert_eq!(tracks.len(), 2, "{tracks:#?}");
    for (target, address) in aircraft() {
        let mine = track_of(&tracker, address);
        assert_eq!(mine.len(), 1);
        // σ 10 m per report, 1 m/s velocity: a few metres after a minute.
        assert!(
            error(&mine[0], &target) < 30.0,
            "{}",
            error(&mine[0], &target)
        );
        let sensors: Vec<usize> = mine[0].detections.iter().map(|h| h.radar).collect();
        assert_eq!(sensors, vec![cfg.report_sensor(ReportKind::Adsb)]);
    }
}

#[test]
fn a_radar_plot_and_an_adsb_report_of_one_address_update_one_track() {
    let cfg = config();
    let mut rng = Lcg(11);
    let mut plots = adsb(&cfg, (0.0, 80.0), &|_, _| [0.0; 2], &mut rng);
    plots.extend(radar_plots(80.0, &mut rng));
    let tracker = run(&cfg, plots);
    let tracks = tracker.confirmed_tracks();
    assert_eq!(tracks.len(), 2, "{tracks:#?}");
    for (target, address) in aircraft() {
        let mine = track_of(&tracker, address);
        assert_eq!(mine.len(), 1);
        let sensors: Vec<usize> = mine[0].detections.iter().map(|h| h.radar).collect();
        assert_eq!(sensors, vec![0, cfg.report_sensor(ReportKind::Adsb)]);
        assert!(mine[0].identity.validation.trusted());
        assert!(mine[0].identity.validation.validated(mine[0].t));
        assert!(error(&mine[0], &target) < 30.0);
    }
}

#[test]
fn a_spoofed_adsb_is_distrusted_and_its_track_follows_the_radar() {
    let cfg = config();
    let mut rng = Lcg(13);
    // Aircraft A's ADS-B jumps 3 km north at 40 s.
    let onset = 40.0;
    let spoof = |t: f64, a: u32| {
        if a == ADDRESS_A && t >= onset {
            [0.0, 3000.0]
        } else {
            [0.0; 2]
        }
    };
    let mut plots = adsb(&cfg, (0.0, 120.0), &spoof, &mut rng);
    plots.extend(radar_plots(120.0, &mut rng));
    let tracker = run(&cfg, plots);
    let tracks = tracker.confirmed_tracks();
    assert_eq!(tracks.len(), 2, "one track per aircraft: {tracks:#?}");
    let a = &track_of(&tracker, ADDRESS_A)[0];
    let v = a.identity.validation;
    let since = v.distrusted_since.expect("flagged");
    assert!(
        since >= onset && since - onset <= 30.0,
        "flagged at {since}"
    );
    let d = v.last_disagreement.unwrap();
    assert!((d.distance - 3000.0).abs() < 500.0, "{d:?}");
    // On the radar (σ ≈ 100 m), not on the spoofed positions 3 km away.
    assert!(
        error(a, &aircraft()[0].0) < 400.0,
        "{}",
        error(a, &aircraft()[0].0)
    );
    // The other aircraft is untouched.
    let b = &track_of(&tracker, ADDRESS_B)[0];
    assert!(b.identity.validation.trusted());
    assert!(error(b, &aircraft()[1].0) < 30.0);
}

#[test]
fn a_spoof_that_ends_is_trusted_again() {
    let cfg = config();
    let mut rng = Lcg(17);
    let spoof = |t: f64, a: u32| {
        if a == ADDRESS_A && (40.0..70.0).contains(&t) {
            [2500.0, 0.0]
        } else {
            [0.0; 2]
        }
    };
    let mut plots = adsb(&cfg, (0.0, 120.0), &spoof, &mut rng);
    plots.extend(radar_plots(120.0, &mut rng));
    let tracker = run(&cfg, plots);
    assert_eq!(tracker.confirmed_tracks().len(), 2);
    let a = &track_of(&tracker, ADDRESS_A)[0];
    assert!(a.identity.validation.trusted());
    assert!(error(a, &aircraft()[0].0) < 30.0);
}

#[test]
fn an_adsb_outage_under_radar_keeps_the_track() {
    let cfg = config();
    let mut rng = Lcg(19);
    let mut plots = adsb(&cfg, (0.0, 30.0), &|_, _| [0.0; 2], &mut rng);
    plots.extend(adsb(&cfg, (70.0, 100.0), &|_, _| [0.0; 2], &mut rng));
    plots.extend(radar_plots(100.0, &mut rng));
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    let (before, after): (Vec<Plot>, Vec<Plot>) = plots.iter().partition(|p| p.t < 50.0);
    tracker.process(&before).unwrap();
    let ids: Vec<u64> = tracker.confirmed_tracks().iter().map(|t| t.id).collect();
    assert_eq!(ids.len(), 2);
    tracker.process(&after).unwrap();
    tracker.flush().unwrap();
    let later: Vec<u64> = tracker.confirmed_tracks().iter().map(|t| t.id).collect();
    assert_eq!(ids, later, "the same tracks through the outage");
}

#[test]
fn an_adsb_only_track_ends_when_its_reports_stop() {
    let cfg = config();
    let mut rng = Lcg(23);
    let mut plots = adsb(&cfg, (0.0, 30.0), &|_, _| [0.0; 2], &mut rng);
    // Aircraft B alone goes on reporting (its frames move the time).
    plots.extend(
        adsb(&cfg, (30.0, 70.0), &|_, _| [0.0; 2], &mut rng)
            .into_iter()
            .filter(|p| p.identity.address == Some(ADDRESS_B)),
    );
    let tracker = run(&cfg, plots);
    // A's track coasted: a miss every 5 s from 35 s, deleted at the third
    // (3 consecutive misses with one radar): gone by 70 s.
    assert!(track_of(&tracker, ADDRESS_A).is_empty());
    assert_eq!(track_of(&tracker, ADDRESS_B).len(), 1);
}

#[test]
fn a_bad_report_is_refused_naming_its_field() {
    let cfg = config();
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    let sensor = cfg.report_sensor(ReportKind::Adsb);
    let good = Report {
        kind: ReportKind::Adsb,
        position: [0.0, 1000.0, 0.0],
        sigma_horizontal: 10.0,
        sigma_vertical: None,
        velocity: None,
        sigma_velocity: 0.0,
        sigma_vertical_velocity: None,
    };
    let bad = |r: Report, sensor: usize| Plot::report(sensor, 1.0, r, Identity::default());
    let cases = [
        (
            bad(
                Report {
                    sigma_horizontal: 0.0,
                    ..good
                },
                sensor,
            ),
            "report.sigma_horizontal",
        ),
        (
            bad(
                Report {
                    position: [f64::NAN, 0.0, 0.0],
                    ..good
                },
                sensor,
            ),
            "report.position",
        ),
        (
            bad(
                Report {
                    velocity: Some([1.0, 2.0, 0.0]),
                    ..good
                },
                sensor,
            ),
            "report.sigma_velocity",
        ),
        (bad(good, cfg.report_sensor(ReportKind::Mlat)), "radar"),
    ];
    for (plot, field) in cases {
        match tracker.process(&[plot]) {
            Err(AlgoError::InvalidParameter { what, .. } | AlgoError::NonFinite { what }) => {
                assert_eq!(what, field)
            }
            other => panic!("{field}: {other:?}"),
        }
    }
    assert_eq!(tracker.counters().plots, 0);
}

#[test]
fn a_spoof_from_the_start_is_caught_by_the_radar() {
    let cfg = config();
    let mut rng = Lcg(29);
    // Aircraft A's ADS-B is 3 km north from its first report: its track
    // starts on the ADS-B (reports come every second, the radar every 4 s),
    // and the Mode S radar's plots of its address disagree with it.
    let spoof = |_: f64, a: u32| {
        if a == ADDRESS_A {
            [0.0, 3000.0]
        } else {
            [0.0; 2]
        }
    };
    let mut plots = adsb(&cfg, (0.0, 120.0), &spoof, &mut rng);
    plots.extend(radar_plots(120.0, &mut rng));
    let tracker = run(&cfg, plots);
    assert_eq!(
        tracker.confirmed_tracks().len(),
        2,
        "one track per aircraft"
    );
    let a = &track_of(&tracker, ADDRESS_A)[0];
    assert!(!a.identity.validation.trusted());
    assert!(
        error(a, &aircraft()[0].0) < 400.0,
        "{}",
        error(a, &aircraft()[0].0)
    );
}

#[test]
fn an_adsb_only_track_that_loses_its_aircraft_takes_it_again() {
    let cfg = config();
    let mut rng = Lcg(31);
    // Aircraft A's reports jump 1.5 km east at 30 s (no radar): its track
    // is set at them after two, not doubled.
    let jump = |t: f64, a: u32| {
        if a == ADDRESS_A && t >= 30.0 {
            [1500.0, 0.0]
        } else {
            [0.0; 2]
        }
    };
    let tracker = run(&cfg, adsb(&cfg, (0.0, 60.0), &jump, &mut rng));
    assert_eq!(tracker.confirmed_tracks().len(), 2);
    let a = &track_of(&tracker, ADDRESS_A)[0];
    let p = aircraft()[0].0.at(a.t);
    let off = (a.state[0] - p[0] - 1500.0).hypot(a.state[2] - p[1]);
    assert!(off < 50.0, "{off} m from the reported positions");
    assert!(a.identity.validation.trusted());
}

#[test]
fn reports_far_noisier_than_they_claim_start_one_track() {
    let cfg = config();
    // Aircraft A's reports are 300 m off at random while they claim 10 m
    // (a NACp that lies): its reports rarely gate its own track, yet one
    // address is one aircraft.
    for seed in [37, 41, 43] {
        let mut rng = Lcg(seed);
        let mut noise = Lcg(seed + 1);
        let mut plots = adsb(&cfg, (0.0, 90.0), &|_, _| [0.0; 2], &mut rng);
        for p in plots.iter_mut() {
            if p.identity.address == Some(ADDRESS_A) {
                let r = p.report.as_mut().unwrap();
                r.position[0] += 300.0 * noise.normal();
                r.position[1] += 300.0 * noise.normal();
            }
        }
        plots.extend(radar_plots(90.0, &mut rng));
        plots.sort_by(|a, b| a.t.total_cmp(&b.t));
        let mut tracker = Tracker::new(cfg.clone()).unwrap();
        let mut most = 0;
        for chunk in plots.chunks(8) {
            tracker.process(chunk).unwrap();
            most = most.max(track_of(&tracker, ADDRESS_A).len());
        }
        assert_eq!(most, 1, "seed {seed}: one track of its address at any time");
    }
}

#[test]
fn a_lone_radar_is_registered_against_adsb() {
    // The radar measures 300 m long in range and 0.4° clockwise in
    // azimuth (≈ 250 m across at 36 km), about 2σ of the default prior.
    let bias = [300.0, 0.4f64.to_radians()];
    let cfg = config();
    let mut rng = Lcg(29);
    let mut plots = adsb(&cfg, (0.0, 240.0), &|_, _| [0.0; 2], &mut rng);
    plots.extend(biased_radar_plots(240.0, bias, &mut rng));
    let tracker = run(&cfg, plots);
    assert_eq!(tracker.confirmed_tracks().len(), 2);
    let b = tracker.biases()[0];
    assert!(b.converged, "{b:?}");
    // Each pair's radial residual has σ ≈ √(100² + 10²) ≈ 100 m (doubled
    // in S for shared plots): two aircraft × 60 scans give ~120 radar
    // plots, so the range bias is known to ≈ 100/√120 ≈ 9 m and the
    // azimuth (45 m across at 30 km, 1.5 mrad) to ≈ 0.14 mrad.
    assert!(
        b.sigma[0] < 30.0 && b.sigma[1] < 0.05f64.to_radians(),
        "{b:?}"
    );
    assert!((b.bias[0] - bias[0]).abs() < 4.0 * b.sigma[0], "{b:?}");
    assert!((b.bias[1] - bias[1]).abs() < 4.0 * b.sigma[1], "{b:?}");
    // The ADS-B stayed trusted throughout: the bias is the radar's.
    for (target, address) in aircraft() {
        let mine = track_of(&tracker, address);
        assert_eq!(mine.len(), 1);
        assert!(mine[0].identity.validation.trusted());
        assert!(error(&mine[0], &target) < 30.0);
    }
}

#[test]
fn a_lone_radar_without_reports_applies_no_bias() {
    let cfg = config();
    assert!(cfg.registration.enabled);
    let mut rng = Lcg(31);
    let tracker = run(&cfg, biased_radar_plots(120.0, [300.0, 0.0], &mut rng));
    // Nothing to compare with: no pair, no prior σ widening the plots.
    assert_eq!(tracker.biases()[0].bias, [0.0; 3]);
    assert_eq!(tracker.biases()[0].sigma, [0.0; 3]);
    assert!(!tracker.biases()[0].converged);
    assert_eq!(tracker.confirmed_tracks().len(), 2);
}
