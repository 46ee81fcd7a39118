//! A realistic plot-fusion scene for the black-box tests: radars at real
//! WGS84 sites tens of km apart, unsynchronised scans (different periods
//! and phases), P_D < 1, clutter, targets that start and end at different
//! times. The truth is straight flight in the fusion frame at 8 km up; the
//! plots are made by the WGS84 conversions of `algo::geo` (checked against
//! pyproj elsewhere): truth ENU → ECEF → the radar's ENU → range, azimuth
//! (and elevation), and the radial velocity from the true velocity.

// Helpers shared by test targets: `pub` is for the modules that use them.
#![allow(unreachable_pub)]
#![allow(dead_code)]

use algo::geo::{Ellipsoid, LocalFrame};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde_json::{Value, json};

pub const ORIGIN: (f64, f64) = (52.0, 4.0);

pub struct SceneRadar {
    pub id: &'static str,
    pub lat: f64,
    pub lon: f64,
    pub three_d: bool,
    pub doppler: bool,
    pub period: f64,
    pub phase: f64,
}

pub struct Target {
    pub start: f64,
    pub end: f64,
    /// Position at t = 0 (ENU, m) and velocity (m/s).
    pub p0: [f64; 3],
    pub v: [f64; 3],
}

impl Target {
    pub fn at(&self, t: f64) -> [f64; 3] {
        [
            self.p0[0] + self.v[0] * t,
            self.p0[1] + self.v[1] * t,
            self.p0[2] + self.v[2] * t,
        ]
    }
}

pub const SIGMA_RANGE: f64 = 50.0;
pub const SIGMA_AZ_DEG: f64 = 0.1;
pub const SIGMA_EL_DEG: f64 = 0.1;
pub const SIGMA_RV: f64 = 1.0;
pub const P_D: f64 = 0.9;

/// Two 2D radars, 4 s and 5 s scans, phases 0.3 s and 2.1 s.
pub fn two_radars(doppler: bool) -> Vec<SceneRadar> {
    vec![
        SceneRadar {
            id: "west",
            lat: 52.05,
            lon: 3.4,
            three_d: false,
            doppler,
            period: 4.0,
            phase: 0.3,
        },
        SceneRadar {
            id: "east",
            lat: 52.3,
            lon: 4.7,
            three_d: false,
            doppler,
            period: 5.0,
            phase: 2.1,
        },
    ]
}

/// Three targets: two for the whole time, one that starts at 30 s and
/// ends at 100 s.
pub fn targets() -> Vec<Target> {
    vec![
        Target {
            start: 0.0,
            end: 1e9,
            p0: [-10_000.0, 5_000.0, 8_000.0],
            v: [200.0, 20.0, 0.0],
        },
        Target {
            start: 0.0,
            end: 1e9,
            p0: [15_000.0, -12_000.0, 8_000.0],
            v: [-50.0, 180.0, 0.0],
        },
        Target {
            start: 30.0,
            end: 100.0,
            p0: [0.0, 20_000.0, 8_000.0],
            v: [150.0, -150.0, 0.0],
        },
    ]
}

pub fn origin_frame() -> LocalFrame {
    LocalFrame::new(
        Ellipsoid::WGS84,
        ORIGIN.0.to_radians(),
        ORIGIN.1.to_radians(),
        0.0,
    )
    .unwrap()
}

/// A truth position `[e, n, H]`: the point above the fusion plane's (e, n)
/// at ellipsoidal height H (found by iterating u ← u + (H − height(u)) with
/// the pyproj-checked conversions of `algo::geo`), in the radar's ENU frame.
pub fn in_radar_frame(fusion: &LocalFrame, radar: &LocalFrame, p: [f64; 3]) -> [f64; 3] {
    let mut u = p[2];
    for _ in 0..6 {
        let (_, _, h) = fusion.enu_to_geodetic([p[0], p[1], u]).unwrap();
        u += p[2] - h;
    }
    fusion.position_to(radar, [p[0], p[1], u]).unwrap()
}

/// Two 2D radars about 200 km from the centre, on opposite sides.
pub fn far_radars() -> Vec<SceneRadar> {
    vec![
        SceneRadar {
            id: "north-west",
            lat: 53.3,
            lon: 2.0,
            three_d: false,
            doppler: false,
            period: 6.0,
            phase: 0.7,
        },
        SceneRadar {
            id: "south-east",
            lat: 50.9,
            lon: 6.2,
            three_d: true,
            doppler: false,
            period: 4.0,
            phase: 2.9,
        },
    ]
}

/// The radars as the request's JSON.
pub fn radars_json(radars: &[SceneRadar], clutter: f64) -> Value {
    Value::Array(
        radars
            .iter()
            .map(|r| {
                let mut v = json!({
                    "id": r.id,
                    "kind": if r.three_d { "3d" } else { "2d" },
                    "site": {"lat_deg": r.lat, "lon_deg": r.lon, "height_m": 0.0},
                    "sigma_range_m": SIGMA_RANGE,
                    "sigma_azimuth_deg": SIGMA_AZ_DEG,
                    "scan_period_s": r.period,
                    "p_detection": P_D,
                    "clutter_density": clutter,
                });
                if r.three_d {
                    v["sigma_elevation_deg"] = json!(SIGMA_EL_DEG);
                }
                if r.doppler {
                    v["sigma_radial_velocity_mps"] = json!(SIGMA_RV);
                }
                v
            })
            .collect(),
    )
}

/// Plots of every radar scan up to `duration` s, in time order, with about
/// `false_per_scan` clutter plots per scan (uniform in range 5–60 km and
/// azimuth), every scan's plots at the scan's time.
pub fn plots(
    radars: &[SceneRadar],
    targets: &[Target],
    duration: f64,
    false_per_scan: f64,
    seed: u64,
) -> Vec<Value> {
    plots_tagged(radars, targets, duration, false_per_scan, seed, &|_, _| {
        None
    })
}

/// [`plots`], each target's plot given the fields `tag(target index, t)`
/// says (SSR and Mode S), merged in; the same noise and detections.
pub fn plots_tagged(
    radars: &[SceneRadar],
    targets: &[Target],
    duration: f64,
    false_per_scan: f64,
    seed: u64,
    tag: &dyn Fn(usize, f64) -> Option<Value>,
) -> Vec<Value> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let fusion = origin_frame();
    let mut out: Vec<(f64, Value)> = Vec::new();
    for r in radars {
        let frame = LocalFrame::new(
            Ellipsoid::WGS84,
            r.lat.to_radians(),
            r.lon.to_radians(),
            0.0,
        )
        .unwrap();
        let mut t = r.phase;
        while t <= duration {
            for (index, target) in targets
                .iter()
                .enumerate()
                .filter(|(_, g)| g.start <= t && t <= g.end)
            {
                if rng.random::<f64>() >= P_D {
                    continue;
                }
                let p = in_radar_frame(&fusion, &frame, target.at(t));
                let range = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                let horizontal = p[0].hypot(p[1]);
                let az = p[0].atan2(p[1]).to_degrees();
                let el = p[2].atan2(horizontal).to_degrees();
                // ṙ by a central difference over ±10 ms.
                let slant = |t: f64| {
                    let q = in_radar_frame(&fusion, &frame, target.at(t));
                    (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt()
                };
                let rv = (slant(t + 0.01) - slant(t - 0.01)) / 0.02;
                let n = |rng: &mut ChaCha8Rng| rng.sample::<f64, _>(StandardNormal);
                let mut plot = json!({
                    "radar_id": r.id,
                    "t": t,
                    "range_m": range + SIGMA_RANGE * n(&mut rng),
                    "azimuth_deg": az + SIGMA_AZ_DEG * n(&mut rng),
                });
                if r.three_d {
                    plot["elevation_deg"] = json!(el + SIGMA_EL_DEG * n(&mut rng));
                }
                if r.doppler {
                    plot["radial_velocity_mps"] = json!(rv + SIGMA_RV * n(&mut rng));
                }
                if let Some(Value::Object(fields)) = tag(index, t) {
                    plot.as_object_mut().unwrap().extend(fields);
                }
                out.push((t, plot));
            }
            let k = (false_per_scan * 2.0 * rng.random::<f64>()).round() as usize;
            for _ in 0..k {
                let mut plot = json!({
                    "radar_id": r.id,
                    "t": t,
                    "range_m": 5_000.0 + 55_000.0 * rng.random::<f64>(),
                    "azimuth_deg": 360.0 * rng.random::<f64>(),
                });
                if r.three_d {
                    plot["elevation_deg"] = json!(15.0 * rng.random::<f64>());
                }
                if r.doppler {
                    plot["radial_velocity_mps"] = json!(300.0 * (rng.random::<f64>() - 0.5));
                }
                out.push((t, plot));
            }
            t += r.period;
        }
    }
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    out.into_iter().map(|(_, p)| p).collect()
}

/// The request of the default scene: two 2D radars, three targets, 150 s.
pub fn request(doppler: bool, seed: u64) -> Value {
    let radars = two_radars(doppler);
    json!({
        "origin": {"lat_deg": ORIGIN.0, "lon_deg": ORIGIN.1, "height_m": 0.0},
        "radars": radars_json(&radars, 1e-7),
        "plots": plots(&radars, &targets(), 150.0, 1.0, seed),
    })
}
