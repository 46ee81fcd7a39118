//! Scenes through the whole pipeline: noise-free plots of known targets.

use super::*;
use crate::algo::{geo::Ellipsoid, polar::enu_to_polar_3d};

fn frame(lat: f64, lon: f64, h: f64) -> LocalFrame {
    LocalFrame::new(Ellipsoid::WGS84, lat.to_radians(), lon.to_radians(), h).unwrap()
}

fn radar(f: LocalFrame, three_d: bool) -> Radar {
    Radar {
        frame: f,
        three_d,
        sigma_range: if three_d { 100.0 } else { 500.0 },
        sigma_azimuth: 0.5f64.to_radians(),
        sigma_elevation: 0.25f64.to_radians(),
        scan_period: if three_d { 10.0 } else { 15.0 },
    }
}

fn config() -> Config {
    Config {
        filter: Filter::AlphaBeta { window: 4 },
        knn: KnnParams { n0: 4, k: 3 },
        preset_altitude: 7000.0, // the targets' height: mapping's preset is right
        altitude_sigma: 5000.0,
        gate_sigmas: 3.0,
        chi2_2: 13.8155, // χ²₂ at α = 0.001: −2 ln 0.001
        chi2_3: 16.2662, // χ²₃ at α = 0.001
    }
}

/// The point at ellipsoidal height `p[2]` above the footprint of ENU `p`.
fn level(centre: &LocalFrame, p: [f64; 3]) -> [f64; 3] {
    let (lat, lon, _) = centre.enu_to_geodetic(p).unwrap();
    centre.geodetic_to_enu(lat, lon, p[2]).unwrap()
}

/// Plots of a target in level flight at ellipsoidal height `start[2]`
/// (horizontal motion `vel[0..2]` in the centre's ENU frame) flying from `start` (centre ENU, m) with `vel` (m/s).
fn track(
    centre: &LocalFrame,
    radars: &[Radar],
    r: usize,
    start: [f64; 3],
    vel: [f64; 3],
    n: usize,
) -> LocalTrack {
    let rd = &radars[r];
    let plots = (0..n)
        .map(|k| {
            let t = k as f64 * rd.scan_period;
            let p = level(
                centre,
                [start[0] + vel[0] * t, start[1] + vel[1] * t, start[2]],
            );
            let local = centre.position_to(&rd.frame, p).unwrap();
            let [range, azimuth, el] = enu_to_polar_3d(local[0], local[1], local[2]).unwrap();
            Plot {
                t,
                range,
                azimuth,
                elevation: rd.three_d.then_some(el),
            }
        })
        .collect();
    LocalTrack { radar: r, plots }
}

const METHODS: [Method; 3] = [Method::Lifting, Method::Splitting, Method::Mapping];

#[test]
fn one_target_seen_by_a_2d_and_a_3d_radar_is_one_group() {
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![
        radar(frame(30.0, 120.0, 0.0), true),
        radar(frame(30.1, 120.1, 100.0), false),
    ];
    // 150 km north-east, 7 km above the centre's tangent plane, 300 m/s west.
    let start = [100_000.0, 110_000.0, 7000.0];
    let vel = [-300.0, 0.0, 0.0];
    let tracks = vec![
        track(&centre, &radars, 0, start, vel, 15),
        track(&centre, &radars, 1, start, vel, 10),
    ];
    for method in METHODS {
        let cfg = config();
        let out = fuse(&centre, &radars, &tracks, method, &cfg).unwrap();
        assert_eq!(out.pairs.len(), 1);
        let pair = &out.pairs[0];
        assert!(pair.state.correlated(), "{method:?}: {pair:?}");
        assert_eq!(out.system_tracks.len(), 1, "{method:?}");
        let st = &out.system_tracks[0];
        assert_eq!(st.members, vec![0, 1]);
        assert!(st.altitude_known);
        // The last fused position lies near the truth (noise-free plots).
        let s = st.samples.last().unwrap();
        let truth = level(&centre, [start[0] + vel[0] * s.t, start[1], start[2]]);
        let err = ((s.x[0] - truth[0]).powi(2) + (s.x[2] - truth[1]).powi(2)).sqrt();
        assert!(err < 1000.0, "{method:?}: horizontal error {err}");
        assert!(
            (s.x[4] - truth[2]).abs() < 500.0,
            "{method:?}: up {}",
            s.x[4]
        );
    }
}

#[test]
fn crossing_targets_at_different_heights_are_kept_apart() {
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![
        radar(frame(30.0, 120.0, 0.0), true),
        radar(frame(30.1, 120.1, 100.0), false),
    ];
    // Two targets at 3 km and 10 km whose footprints cross: a flies north
    // from (80, 60) km, b west from (110, 90) km, both at 200 m/s, so both
    // are over (80, 90) km at t = 150 s, the middle of the 300 s scene. The
    // 2D radar sees the same horizontal position for both there.
    let a = ([80_000.0, 60_000.0, 3000.0], [0.0, 200.0, 0.0]);
    let b = ([110_000.0, 90_000.0, 10_000.0], [-200.0, 0.0, 0.0]);
    let tracks = vec![
        track(&centre, &radars, 0, a.0, a.1, 31),
        track(&centre, &radars, 0, b.0, b.1, 31),
        track(&centre, &radars, 1, a.0, a.1, 21),
        track(&centre, &radars, 1, b.0, b.1, 21),
    ];
    for method in [Method::Lifting, Method::Splitting] {
        let out = fuse(&centre, &radars, &tracks, method, &config()).unwrap();
        let mut groups: Vec<Vec<usize>> = out
            .system_tracks
            .iter()
            .map(|s| s.members.clone())
            .collect();
        groups.sort();
        assert_eq!(groups, vec![vec![0, 2], vec![1, 3]], "{method:?}");
        // The cross pairs were rejected, the true pairs are held.
        for p in &out.pairs {
            let same = (p.a, p.b) == (0, 2) || (p.a, p.b) == (1, 3);
            assert_eq!(p.state.period == Period::Hold, same, "{method:?}: {p:?}");
        }
    }
}

#[test]
fn a_2d_only_track_has_an_unknown_altitude_except_under_mapping() {
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![
        radar(frame(30.0, 120.0, 0.0), true),
        radar(frame(30.1, 120.1, 100.0), false),
    ];
    let tracks = vec![track(
        &centre,
        &radars,
        1,
        [50_000.0, 50_000.0, 7000.0],
        [200.0, 0.0, 0.0],
        6,
    )];
    for method in METHODS {
        let out = fuse(&centre, &radars, &tracks, method, &config()).unwrap();
        assert_eq!(out.system_tracks.len(), 1);
        assert_eq!(
            out.system_tracks[0].altitude_known,
            method == Method::Mapping
        );
    }
}

#[test]
fn a_wrong_preset_altitude_breaks_mapping_but_not_lifting_or_splitting() {
    // The target flies at 7 km; the preset says 5 km. Mapping places the 2D
    // plots 2 km too low with σ_h = 300 m and its 3D test fails; lifting and
    // splitting carry σ_h = 5 km along the cone and correlate.
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![
        radar(frame(30.0, 120.0, 0.0), true),
        radar(frame(30.1, 120.1, 100.0), false),
    ];
    let (start, vel) = ([100_000.0, 110_000.0, 7000.0], [-300.0, 0.0, 0.0]);
    let tracks = vec![
        track(&centre, &radars, 0, start, vel, 15),
        track(&centre, &radars, 1, start, vel, 10),
    ];
    let cfg = Config {
        preset_altitude: 5000.0,
        ..config()
    };
    for method in METHODS {
        let out = fuse(&centre, &radars, &tracks, method, &cfg).unwrap();
        assert_eq!(
            out.pairs[0].state.correlated(),
            method != Method::Mapping,
            "{method:?}: {:?}",
            out.pairs[0]
        );
    }
}

#[test]
fn a_2d_track_closer_than_the_preset_height_is_placed_where_it_can_be() {
    // Slant ranges of 2–3 km cannot reach a 5 km preset: the plots go to
    // the site's height + 0.9 ρ instead of failing the request.
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![radar(frame(30.0, 120.0, 0.0), false)];
    let tracks = vec![track(
        &centre,
        &radars,
        0,
        [2000.0, 1000.0, 1000.0],
        [10.0, 0.0, 0.0],
        5,
    )];
    let cfg = Config {
        preset_altitude: 5000.0,
        ..config()
    };
    for method in METHODS {
        let out = fuse(&centre, &radars, &tracks, method, &cfg).unwrap();
        let s = out.system_tracks[0].samples.last().unwrap();
        assert!(s.x.iter().all(|v| v.is_finite()));
    }
}
