//! Scenes through the whole pipeline: noise-free plots of known targets.

use super::*;
use std::f64::consts::FRAC_PI_2;

use crate::{geo::Ellipsoid, polar::enu_to_polar_3d};

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
    // The target flies at 7 km; the preset says 3 km. Mapping places the 2D
    // plots 4 km too low with σ_h = 300 m and its 3D test fails; lifting and
    // splitting carry σ_h = 5 km along the cone and correlate. (A 2 km error
    // is within 3σ of the 3D radar's height error at 150 km, 0.25° ≈ 650 m,
    // once the filters report their covariance honestly.)
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
        preset_altitude: 3000.0,
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

#[test]
fn place_2d_matches_the_iterative_placement_and_central_differences() {
    // The analytic Newton slope and implicit-function Jacobian against the
    // numeric path (plot_at_height with central-difference slopes, then
    // central differences of the position in ρ, θ, h).
    let centre = frame(30.0, 120.0, 0.0);
    let radar = frame(30.1, 120.1, 100.0);
    for (rho, th, h) in [
        (150_000.0, 0.7, 7000.0),
        (40_000.0, 3.5, 1500.0),
        (220_000.0, 5.9, 11_000.0),
    ] {
        let (pos, jac) = geometry::place_2d(&radar, &centre, rho, th, h).unwrap();
        let at = |y: [f64; 3]| -> [f64; 3] {
            let (ecef, _) = geometry::plot_at_height(&radar, y[0], y[1], y[2]).unwrap();
            centre.ecef_to_enu(ecef).unwrap()
        };
        let p0 = at([rho, th, h]);
        for i in 0..3 {
            assert!(
                (pos[i] - p0[i]).abs() < 0.05,
                "{i}: {} vs {}",
                pos[i],
                p0[i]
            );
        }
        let steps = [1.0, 1e-6, 1.0];
        for k in 0..3 {
            let (mut hi, mut lo) = ([rho, th, h], [rho, th, h]);
            hi[k] += steps[k];
            lo[k] -= steps[k];
            let (a, b) = (at(hi), at(lo));
            for i in 0..3 {
                let num = (a[i] - b[i]) / (2.0 * steps[k]);
                let tol = 1e-3 * jac.column(k).norm();
                assert!(
                    (jac[(i, k)] - num).abs() < tol,
                    "∂{i}/∂{k}: {} vs {num}",
                    jac[(i, k)]
                );
            }
        }
    }
}

#[test]
fn test_space_jacobians_match_central_differences() {
    let centre = frame(30.0, 120.0, 0.0);
    for pos in [
        [100_000.0, -80_000.0, 9000.0],
        [-150_000.0, 20_000.0, 1000.0],
    ] {
        for method in METHODS {
            let (dim, z, jac) = geometry::test_space(&centre, method, pos).unwrap();
            let g = |p: [f64; 3]| -> Vec<f64> {
                let ecef = centre.enu_to_ecef(p).unwrap();
                match method {
                    Method::Mapping => p.to_vec(),
                    Method::Lifting => geometry::footprint(&centre, ecef).unwrap().to_vec(),
                    Method::Splitting => geometry::direction(&centre, ecef).unwrap().to_vec(),
                }
            };
            let z0 = g(pos);
            assert_eq!(z0.len(), dim);
            for i in 0..dim {
                assert!((z[i] - z0[i]).abs() < 1e-6, "{method:?}");
            }
            for k in 0..3 {
                let (mut hi, mut lo) = (pos, pos);
                hi[k] += 1.0;
                lo[k] -= 1.0;
                let (a, b) = (g(hi), g(lo));
                for i in 0..dim {
                    let num = (a[i] - b[i]) / 2.0;
                    assert!(
                        (jac[(i, k)] - num).abs() < 1e-6,
                        "{method:?} ∂{i}/∂{k}: {} vs {num}",
                        jac[(i, k)]
                    );
                }
            }
        }
    }
}

#[test]
fn every_sample_says_where_its_height_comes_from() {
    // A 2D track from t = 0 and a 3D track of the same target that starts at
    // t = 100 s: under lifting and splitting the samples before the 3D track
    // starts are lifted to its height, those with it measured; under mapping
    // they are assumed (preset). A 2D-only track is assumed everywhere.
    let centre = frame(30.0, 120.0, 0.0);
    let radars = vec![
        radar(frame(30.0, 120.0, 0.0), true),
        radar(frame(30.1, 120.1, 100.0), false),
    ];
    let start = [100_000.0, 110_000.0, 9000.0];
    let vel = [-250.0, 0.0, 0.0];
    let mut three = track(&centre, &radars, 0, start, vel, 25);
    three.plots.retain(|p| p.t >= 100.0);
    let tracks = vec![three, track(&centre, &radars, 1, start, vel, 16)];
    for method in METHODS {
        // Mapping needs the right preset to correlate at all.
        let cfg = Config {
            preset_altitude: if method == Method::Mapping {
                9000.0
            } else {
                5000.0
            },
            ..config()
        };
        let out = fuse(&centre, &radars, &tracks, method, &cfg).unwrap();
        assert_eq!(out.system_tracks.len(), 1, "{method:?}");
        let st = &out.system_tracks[0];
        assert_eq!(st.members, vec![0, 1]);
        let joined = tracks[0].plots[1].t; // the 3D filter's first estimate
        for s in &st.samples {
            let want = if s.t >= joined {
                AltitudeSource::Measured
            } else if method == Method::Mapping {
                AltitudeSource::Assumed
            } else {
                AltitudeSource::Lifted
            };
            assert_eq!(s.altitude, want, "{method:?} t = {}", s.t);
            if want == AltitudeSource::Lifted {
                // The 3D track's height (9 km), not the 5 km preset.
                let truth = level(&centre, [start[0] + vel[0] * s.t, start[1], start[2]]);
                let sz = s.p[(4, 4)].sqrt();
                assert!(
                    (s.x[4] - truth[2]).abs() < 3.0 * sz,
                    "{method:?} {}",
                    s.x[4]
                );
                assert!(sz < 2000.0, "σ_z {sz}");
            }
        }
        assert!(
            st.samples
                .iter()
                .any(|s| s.altitude != AltitudeSource::Measured)
        );
    }
    let alone = vec![tracks[1].clone()];
    for method in METHODS {
        let out = fuse(&centre, &radars, &alone, method, &config()).unwrap();
        assert!(
            out.system_tracks[0]
                .samples
                .iter()
                .all(|s| s.altitude == AltitudeSource::Assumed)
        );
    }
}

/// The K-NN test of a pair computed the slow, exact way: the other track
/// extrapolated to the instant and its test coordinates and their Jacobian
/// evaluated there by central differences.
#[allow(clippy::too_many_arguments)]
fn reference_pair(
    centre: &LocalFrame,
    radars: &[Radar],
    tracks: &[LocalTrack],
    centred: &[Vec<State6>],
    a: usize,
    b: usize,
    method: Method,
    cfg: &Config,
) -> PairState {
    let (ra, rb) = (&radars[tracks[a].radar], &radars[tracks[b].radar]);
    let (driver, other, gap) = if ra.scan_period >= rb.scan_period {
        (a, b, 1.5 * rb.scan_period)
    } else {
        (b, a, 1.5 * ra.scan_period)
    };
    let space = |s: &State6| -> (Vec<f64>, nalgebra::DMatrix<f64>) {
        let g = |p: [f64; 3]| -> Vec<f64> {
            let ecef = centre.enu_to_ecef(p).unwrap();
            match method {
                Method::Mapping => p.to_vec(),
                Method::Lifting => geometry::footprint(centre, ecef).unwrap().to_vec(),
                Method::Splitting => geometry::direction(centre, ecef).unwrap().to_vec(),
            }
        };
        let pos = [s.x[0], s.x[2], s.x[4]];
        let z = g(pos);
        let m = z.len();
        let mut j = nalgebra::DMatrix::zeros(m, 3);
        for k in 0..3 {
            let (mut hi, mut lo) = (pos, pos);
            hi[k] += 1.0;
            lo[k] -= 1.0;
            let (u, v) = (g(hi), g(lo));
            for i in 0..m {
                j[(i, k)] = (u[i] - v[i]) / 2.0;
            }
        }
        (z, j)
    };
    let pos_cov = |s: &State6| nalgebra::DMatrix::from_fn(3, 3, |i, j| s.p[(2 * i, 2 * j)]);
    let mut state = PairState::new();
    for s in &centred[driver] {
        if !state.wants_test() {
            break;
        }
        let Some(o) = at_time(&centred[other], s.t, gap) else {
            continue;
        };
        let ((za, ja), (zb, jb)) = (space(s), space(&o));
        let m = za.len();
        let d = nalgebra::DVector::from_fn(m, |i, _| za[i] - zb[i]);
        let cov = &ja * pos_cov(s) * ja.transpose() + &jb * pos_cov(&o) * jb.transpose();
        let stat = d.dot(&cov.clone().cholesky().unwrap().solve(&d));
        let hit = (0..m).all(|i| d[i].abs() <= cfg.gate_sigmas * cov[(i, i)].sqrt());
        let threshold = if m == 3 { cfg.chi2_3 } else { cfg.chi2_2 };
        state.step(cfg.knn, hit, stat <= threshold);
    }
    state
}

/// The benchmark scene's configuration with `filter`: K-NN 3 of 5, a
/// preset altitude of 5,000 ± 5,000 m, 3σ gates and the 1 % χ² thresholds
/// (χ²₂(0.01) = −2 ln 0.01 = 9.2103, χ²₃(0.01) = 11.3449).
fn bench_config(filter: Filter) -> Config {
    Config {
        filter,
        knn: KnnParams { n0: 5, k: 3 },
        preset_altitude: 5000.0,
        altitude_sigma: 5000.0,
        gate_sigmas: 3.0,
        chi2_2: 9.2103,
        chi2_3: 11.3449,
    }
}

#[test]
fn fast_pair_tests_decide_as_the_exact_evaluation_on_the_benchmark_scene() {
    // The per-sample test coordinates with the linearised extrapolation and
    // analytic Jacobians give the same K-NN state for every pair as the
    // exact evaluation at each instant, on three seeds of the benchmark
    // scene, both filters, all methods.
    for seed in [1u64, 2, 3] {
        let scene = bench_scene(20, 200.0, seed);
        for filter in [
            Filter::AlphaBeta { window: 4 },
            Filter::Kalman { sigma_a: 5.0 },
        ] {
            let cfg = bench_config(filter);
            let filtered: Vec<Filtered> = scene
                .tracks
                .iter()
                .map(|t| Filtered {
                    radar: t.radar,
                    est: filter_track(&scene.radars[t.radar], t, filter).unwrap(),
                })
                .collect();
            for method in METHODS {
                let sigma_h = if method == Method::Mapping {
                    MAPPING_ALTITUDE_SIGMA_M
                } else {
                    cfg.altitude_sigma
                };
                let centred: Vec<Vec<State6>> = filtered
                    .iter()
                    .map(|f| {
                        f.est
                            .iter()
                            .map(|e| {
                                to_centre(
                                    &scene.centre,
                                    &scene.radars[f.radar],
                                    &Site::new(&scene.centre, &scene.radars[f.radar]),
                                    e,
                                    cfg.preset_altitude,
                                    sigma_h,
                                )
                                .unwrap()
                            })
                            .collect()
                    })
                    .collect();
                let out = fuse_one(
                    &scene.centre,
                    &scene.radars,
                    &scene.tracks,
                    &filtered,
                    &centred,
                    method,
                    &cfg,
                )
                .unwrap();
                let mut correlated = 0;
                for p in &out.pairs {
                    let r = reference_pair(
                        &scene.centre,
                        &scene.radars,
                        &scene.tracks,
                        &centred,
                        p.a,
                        p.b,
                        method,
                        &cfg,
                    );
                    assert_eq!(
                        p.state, r,
                        "seed {seed} {filter:?} {method:?} {}-{}",
                        p.a, p.b
                    );
                    correlated += usize::from(r.correlated());
                }
                assert!(correlated > 5, "seed {seed} {method:?}: {correlated}");
            }
        }
    }
}

#[test]
fn the_latest_sample_alone_is_the_last_of_the_whole_history_bit_for_bit() {
    // `Samples::Latest` fuses only the last instant of each system track
    // (and reads back to the latest instant a 3D member covers, for the
    // height lifting and splitting borrow). Its one sample per system
    // track must be the last sample of `Samples::All` to the bit, with the
    // same pairs, groups and conflicts, for every method alone and for the
    // combinations that share work (mapping's 3D pass, lifting's tracks
    // kept for splitting), on three seeds of the benchmark scene and both
    // filters; the comparison covers samples of every altitude source.
    let sets: [&[Method]; 5] = [
        &[Method::Mapping, Method::Lifting, Method::Splitting],
        &[Method::Splitting, Method::Lifting],
        &[Method::Mapping],
        &[Method::Lifting],
        &[Method::Splitting],
    ];
    let mut seen = [0usize; 3];
    for seed in [1u64, 2, 3] {
        let scene = bench_scene(20, 200.0, seed);
        for filter in [
            Filter::AlphaBeta { window: 4 },
            Filter::Kalman { sigma_a: 5.0 },
        ] {
            let cfg = bench_config(filter);
            for methods in sets {
                let run = |samples| {
                    fuse_methods_with(
                        &scene.centre,
                        &scene.radars,
                        &scene.tracks,
                        methods,
                        &cfg,
                        samples,
                    )
                    .unwrap()
                };
                let (all, latest) = (run(Samples::All), run(Samples::Latest));
                for (m, (a, l)) in methods.iter().zip(all.iter().zip(&latest)) {
                    let at = format!("seed {seed} {filter:?} {m:?} of {methods:?}");
                    assert_eq!(a.pairs, l.pairs, "{at}");
                    assert_eq!(a.conflicts, l.conflicts, "{at}");
                    assert_eq!(a.system_tracks.len(), l.system_tracks.len(), "{at}");
                    for (ta, tl) in a.system_tracks.iter().zip(&l.system_tracks) {
                        assert_eq!(ta.members, tl.members, "{at}");
                        assert_eq!(ta.altitude_known, tl.altitude_known, "{at}");
                        assert_eq!(tl.samples.len(), 1, "{at}");
                        let (sa, sl) = (ta.samples.last().unwrap(), &tl.samples[0]);
                        let bits = |s: &Sample| {
                            std::iter::once(s.t)
                                .chain(s.x.iter().copied())
                                .chain(s.p.iter().copied())
                                .map(f64::to_bits)
                                .collect::<Vec<_>>()
                        };
                        assert_eq!(bits(sa), bits(sl), "{at} {:?}", ta.members);
                        assert_eq!(sa.altitude, sl.altitude, "{at}");
                        seen[sl.altitude as usize] += 1;
                    }
                }
            }
        }
    }
    // Every altitude source among the compared samples.
    assert!(seen.iter().all(|&n| n > 10), "{seen:?}");
}

#[test]
fn all_finite_agrees_with_is_finite() {
    let vals = [
        0.0,
        -0.0,
        1.0,
        -3.5e300,
        f64::MIN_POSITIVE,
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    for &a in &vals {
        for &b in &vals {
            for &c in &vals {
                let v = [a, b, c, 2.0];
                assert_eq!(all_finite(&v), v.iter().all(|x| x.is_finite()), "{v:?}");
            }
        }
    }
    assert!(all_finite(&[]));
}

#[test]
fn local_3d_gives_the_bits_of_plot_to_local() {
    let f = frame(30.0, 120.0, 0.0);
    let r = radar(f, true);
    let mut n = 0;
    for &range in &[0.0, 1.0, 850.0, 37_123.4, 199_999.9] {
        for k in 0..24 {
            let azimuth = -7.0 + 0.61 * f64::from(k);
            for &elevation in &[-1.6, -FRAC_PI_2, -0.3, 0.0, 0.017, 0.9, FRAC_PI_2, 2.0] {
                let plot = Plot {
                    t: 0.0,
                    range,
                    azimuth,
                    elevation: Some(elevation),
                };
                let exact = plot_to_local(
                    [0.0; 3],
                    &PolarMeasurement {
                        range,
                        azimuth,
                        elevation: Some(elevation),
                        sigma_range: r.sigma_range,
                        sigma_azimuth: r.sigma_azimuth,
                        sigma_elevation: Some(r.sigma_elevation),
                    },
                );
                match (local_3d(&r, &plot), exact) {
                    (Ok((mean, cov)), Ok(g)) => {
                        n += 1;
                        for i in 0..3 {
                            assert_eq!(mean[i].to_bits(), g.mean()[i].to_bits());
                            for j in 0..3 {
                                assert_eq!(cov[(i, j)].to_bits(), g.cov()[(i, j)].to_bits());
                            }
                        }
                    }
                    (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
                    (a, b) => panic!("{range} {azimuth} {elevation}: {a:?} vs {:?}", b.is_ok()),
                }
            }
        }
    }
    assert!(n > 400, "{n}");
}

/// The radars and local tracks of a small benchmark scene.
struct BenchScene {
    centre: LocalFrame,
    radars: Vec<Radar>,
    tracks: Vec<LocalTrack>,
}

/// A small seeded scene generator for the test above (the simulator is the
/// `eval` crate's, which the numerical core does not depend on), after the
/// simulator's `seed003_dimension::bench_scene`: four radars 30–50 km apart
/// (two 3D: σρ 100 m, σθ 0.3°, σε 0.25°, cover 120 km; two 2D: σρ 250 m,
/// σθ 0.4°, cover 150 km; scans every 10 s at phases 0, 2.5, 5, 7.5 s), and
/// `aircraft` aircraft within 170 km at 120–260 m/s and 1–12 km height, 30
/// % of them turning at 1–3 g for 30–90 s after 20–150 s (closed-form
/// coordinated turn); plots seen above the horizon within cover, with
/// Gaussian errors; a track per run of at least 3 plots.
fn bench_scene(aircraft: usize, duration: f64, seed: u64) -> BenchScene {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let gauss = |rng: &mut rand_chacha::ChaCha8Rng| {
        let u1: f64 = 1.0 - rng.random::<f64>();
        let u2: f64 = rng.random::<f64>();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    };
    let c = LocalFrame::new(
        Ellipsoid::WGS84,
        30f64.to_radians(),
        120f64.to_radians(),
        0.0,
    )
    .unwrap();
    let layout = [
        (-20_000.0, -15_000.0, 50.0, true, 120_000.0),
        (25_000.0, -20_000.0, 0.0, false, 150_000.0),
        (20_000.0, 25_000.0, 120.0, true, 120_000.0),
        (-25_000.0, 20_000.0, 30.0, false, 150_000.0),
    ];
    let mut radars = Vec::new();
    for &(e, n, h, three_d, _) in &layout {
        let (lat, lon, _) = c.enu_to_geodetic([e, n, 0.0]).unwrap();
        radars.push(Radar {
            frame: LocalFrame::new(Ellipsoid::WGS84, lat, lon, h).unwrap(),
            three_d,
            sigma_range: if three_d { 100.0 } else { 250.0 },
            sigma_azimuth: if three_d { 0.3f64 } else { 0.4 }.to_radians(),
            sigma_elevation: if three_d { 0.25f64.to_radians() } else { 0.0 },
            scan_period: 10.0,
        });
    }
    let mut tracks = Vec::new();
    for _ in 0..aircraft {
        let r = 170_000.0 * rng.random::<f64>().sqrt();
        let bearing = rng.random_range(0.0..std::f64::consts::TAU);
        let heading = rng.random_range(0.0..std::f64::consts::TAU);
        let speed = rng.random_range(120.0..260.0);
        let height = rng.random_range(1000.0..12_000.0);
        // (start, length, turn rate) of the turn; none for 70 %.
        let turn = (rng.random::<f64>() < 0.3).then(|| {
            let start = rng.random_range(20.0..150.0);
            let length = rng.random_range(30.0..90.0);
            let g = rng.random_range(1.0..3.0) * if rng.random::<bool>() { 1.0 } else { -1.0 };
            (start, length, g * 9.80665 / speed)
        });
        // Closed form: straight, then a turn at rate w, then straight.
        let at = |t: f64| -> [f64; 3] {
            let (mut x, mut y, mut h) = (r * bearing.sin(), r * bearing.cos(), heading);
            let straight = |x: &mut f64, y: &mut f64, h: f64, dt: f64| {
                *x += speed * h.sin() * dt;
                *y += speed * h.cos() * dt;
            };
            match turn {
                None => straight(&mut x, &mut y, h, t),
                Some((start, length, w)) => {
                    straight(&mut x, &mut y, h, t.min(start));
                    let dt = (t - start).clamp(0.0, length);
                    // Heading h from north, clockwise; turning at rate w.
                    x += speed / w * ((h).cos() - (h + w * dt).cos());
                    y += speed / w * ((h + w * dt).sin() - h.sin());
                    h += w * dt;
                    straight(&mut x, &mut y, h, (t - start - length).max(0.0));
                }
            }
            let (lat, lon, _) = c.enu_to_geodetic([x, y, 0.0]).unwrap();
            c.geodetic_to_enu(lat, lon, height).unwrap()
        };
        for (i, &(_, _, _, three_d, cover)) in layout.iter().enumerate() {
            let rd = &radars[i];
            let mut plots: Vec<Plot> = Vec::new();
            let mut t = 2.5 * i as f64;
            while t <= duration {
                let l = c.position_to(&rd.frame, at(t)).unwrap();
                let [range, az, el] = enu_to_polar_3d(l[0], l[1], l[2]).unwrap();
                if range <= cover && el > 0.0 {
                    plots.push(Plot {
                        t,
                        range: range + rd.sigma_range * gauss(&mut rng),
                        azimuth: az + rd.sigma_azimuth * gauss(&mut rng),
                        elevation: three_d.then(|| el + rd.sigma_elevation * gauss(&mut rng)),
                    });
                } else if plots.len() >= 3 {
                    tracks.push(LocalTrack {
                        radar: i,
                        plots: std::mem::take(&mut plots),
                    });
                } else {
                    plots.clear();
                }
                t += 10.0;
            }
            if plots.len() >= 3 {
                tracks.push(LocalTrack { radar: i, plots });
            }
        }
    }
    BenchScene {
        centre: c,
        radars,
        tracks,
    }
}
