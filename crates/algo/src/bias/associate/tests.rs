//! Tests of the association: exact scenes with a pure bias, the seeding
//! paths, the bounds and flags, and the one-pass brackets against the
//! one-by-one search.

use super::alignment::*;
use super::estimate::*;
use super::problem::*;
use super::*;
use crate::assignment;

/// Samples a and a + 1 of `track` around `t` and the weight of a + 1; `None`
/// outside the track or across a gap longer than `max_gap`.
fn bracket(track: &[RadarSample], t: f64, max_gap: f64) -> Option<(usize, f64)> {
    let first = track.first()?;
    let last = track.last()?;
    if t < first.t || t > last.t {
        return None;
    }
    let b = track.partition_point(|s| s.t <= t);
    // track[b − 1].t ≤ t < track[b].t (or b = len when t is the last time).
    let a = b - 1;
    if track[a].t == t {
        return Some((a, 0.0));
    }
    let (ta, tb) = (track[a].t, track[b].t);
    if tb - ta > max_gap {
        return None;
    }
    Some((a, (t - ta) / (tb - ta)))
}

/// Ships on straight lines; radar samples at the AIS times with a pure
/// bias, so the interpolation is exact and the estimate must equal the
/// bias to rounding.
fn scene(
    ships: &[([f64; 2], [f64; 2])],
    with_ais: &[bool],
    bias: Bias,
) -> (Vec<Vec<RadarSample>>, Vec<Vec<AisPoint>>) {
    let times: Vec<f64> = (0..20).map(|k| 10.0 * k as f64).collect();
    let mut radar = Vec::new();
    let mut ais = Vec::new();
    for (s, (p0, v)) in ships.iter().enumerate() {
        let pos = |t: f64| [p0[0] + v[0] * t, p0[1] + v[1] * t];
        radar.push(
            times
                .iter()
                .map(|&t| {
                    let (r, a) = plane_to_polar(pos(t));
                    RadarSample {
                        t,
                        range: r + bias.range,
                        azimuth: (a + bias.azimuth).rem_euclid(std::f64::consts::TAU),
                    }
                })
                .collect(),
        );
        if with_ais[s] {
            ais.push(times.iter().map(|&t| AisPoint::exact(t, pos(t))).collect());
        }
    }
    (radar, ais)
}

fn grid_ships(n: usize) -> Vec<([f64; 2], [f64; 2])> {
    (0..n)
        .map(|k| {
            let (a, b) = ((k % 5) as f64, (k / 5) as f64);
            (
                [2000.0 + 4000.0 * a + 300.0 * b, 3000.0 + 4000.0 * b],
                [5.0 - a, 3.0 + b],
            )
        })
        .collect()
}

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Stream `run` of the ChaCha8 generator keyed by `seed` (the key
/// layout of the simulator's `eval::montecarlo::run_rng`).
fn run_rng(seed: u64, run: u64) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    key[..8].copy_from_slice(&seed.to_le_bytes());
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream(run);
    rng
}

/// A standard normal draw (Box–Muller).
fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A small AIS–radar scene generator for these tests (the simulator is
/// the `eval` crate's, which the numerical core does not depend on): a
/// harbour (`moored` ships 10–70 m apart in rows of 12 about (3, 5) km,
/// `moving` ships at 2–10 m/s, the last quarter of each kind without
/// AIS, 20 min, radar every 2.5 s with σρ 10 m, σθ 0.1°, AIS every 2–10
/// s under way and 3 min moored with GNSS σ 3 m and antenna offset σ 5
/// m) or, with `open_sea`, ships at 30–80 m/s in 20 × 20 km, all with
/// exact AIS every 2–10 s, radar every 5 s for 145 s with σρ 50 m, σθ
/// 0.2°. The same scene kinds as `eval::ais::AisSceneConfig`.
struct AisSceneConfig {
    ships: usize,
    open_sea: bool,
    bias: Bias,
}

/// A generated scene: radar track i is ship i, AIS ship j is ship `owner[j]`.
struct AisScene {
    radar: Vec<Vec<RadarSample>>,
    ais: Vec<Vec<AisPoint>>,
    owner: Vec<usize>,
}

impl AisSceneConfig {
    fn harbour(ships: usize, range: f64, azimuth: f64) -> Self {
        let bias = Bias { range, azimuth };
        Self {
            ships,
            open_sea: false,
            bias,
        }
    }

    fn open_sea(ships: usize, range: f64, azimuth: f64) -> Self {
        let bias = Bias { range, azimuth };
        Self {
            ships,
            open_sea: true,
            bias,
        }
    }

    fn generate(&self, rng: &mut ChaCha8Rng) -> Result<AisScene, std::convert::Infallible> {
        Ok(generated(self.ships, self.open_sea, self.bias, rng))
    }
}

fn generated(ships: usize, open_sea: bool, bias: Bias, rng: &mut ChaCha8Rng) -> AisScene {
    let (moored, moving) = if open_sea {
        (0, ships)
    } else {
        (ships * 3 / 5, ships - ships * 3 / 5)
    };
    let (duration, period, sr, sa): (f64, f64, f64, f64) = if open_sea {
        (145.0, 5.0, 50.0, 0.2f64.to_radians())
    } else {
        (1200.0, 2.5, 10.0, 0.1f64.to_radians())
    };
    let (ais_sigma, offset_sigma, without) = if open_sea {
        (0.0, 0.0, 0.0)
    } else {
        (3.0, 5.0, 0.25)
    };
    let no_ais = |count: usize, k: usize| k >= count - (count as f64 * without).round() as usize;
    // (start, velocity, carries AIS, moored)
    let mut fleet: Vec<([f64; 2], [f64; 2], bool, bool)> = Vec::new();
    let mut along = 0.0;
    for k in 0..moored {
        along = if k % 12 == 0 {
            0.0
        } else {
            along + rng.random_range(10.0..70.0)
        };
        let p = [3000.0 - 400.0 + along, 5000.0 + 300.0 * (k / 12) as f64];
        fleet.push((p, [0.0, 0.0], !no_ais(moored, k), true));
    }
    let (sea, speed) = if open_sea {
        ([0.0, 20_000.0, 0.0, 20_000.0], (30.0, 80.0))
    } else {
        ([-2000.0, 8000.0, 3000.0, 12_000.0], (2.0, 10.0))
    };
    for k in 0..moving {
        let p = [
            rng.random_range(sea[0]..sea[1]),
            rng.random_range(sea[2]..sea[3]),
        ];
        let v = rng.random_range(speed.0..speed.1);
        let course: f64 = rng.random_range(0.0..std::f64::consts::TAU);
        fleet.push((
            p,
            [v * course.sin(), v * course.cos()],
            !no_ais(moving, k),
            false,
        ));
    }
    let (mut radar, mut ais, mut owner) = (Vec::new(), Vec::new(), Vec::new());
    let scans = (duration / period).floor() as usize;
    for (s, &(p0, v, with_ais, moored)) in fleet.iter().enumerate() {
        let at = |t: f64| [p0[0] + v[0] * t, p0[1] + v[1] * t];
        radar.push(
            (0..=scans)
                .map(|k| {
                    let t = k as f64 * period;
                    let (r, a) = plane_to_polar(at(t));
                    RadarSample {
                        t,
                        range: r + bias.range + sr * gauss(rng),
                        azimuth: (a + bias.azimuth + sa * gauss(rng))
                            .rem_euclid(std::f64::consts::TAU),
                    }
                })
                .collect(),
        );
        if with_ais {
            let interval = if moored { (180.0, 180.0) } else { (2.0, 10.0) };
            let draw = |rng: &mut ChaCha8Rng| {
                if interval.0 < interval.1 {
                    rng.random_range(interval.0..interval.1)
                } else {
                    interval.0
                }
            };
            let offset = [offset_sigma * gauss(rng), offset_sigma * gauss(rng)];
            let mut reports = Vec::new();
            let mut t = rng.random::<f64>() * draw(rng);
            while t <= duration {
                let p = at(t);
                reports.push(AisPoint::exact(
                    t,
                    [
                        p[0] + offset[0] + ais_sigma * gauss(rng),
                        p[1] + offset[1] + ais_sigma * gauss(rng),
                    ],
                ));
                t += draw(rng);
            }
            ais.push(reports);
            owner.push(s);
        }
    }
    AisScene { radar, ais, owner }
}

/// (correct, false, missed) of an outcome against the scene's owners.
fn score(out: &Outcome, owner: &[usize]) -> (usize, usize, usize) {
    let mut s = (0, 0, 0);
    for (j, &o) in owner.iter().enumerate() {
        match out.associations.iter().find(|a| a.ais == j) {
            Some(a) if a.radar == o => s.0 += 1,
            Some(_) => s.1 += 1,
            None => s.2 += 1,
        }
    }
    s
}

/// The search as it was before the ranking (issue 17's "before"):
/// every in-bound pair-implied bias scored on the full eq. 6 matrix
/// (sin/cos compensation, `hypot` distances, no screening), the best by
/// gated pairs then total distance refined. Independent of the
/// summaries, screens, votes and caps of `search`.
fn exhaustive(radar: &[Vec<RadarSample>], ais: &[Vec<AisPoint>], cfg: &Config) -> Refined {
    let problem = Problem::new(radar, ais, cfg);
    let cols = ais.len();
    let full = |b: Bias| -> Vec<(usize, usize, f64)> {
        let pos: Vec<Vec<[f64; 2]>> = radar
            .iter()
            .map(|t| {
                t.iter()
                    .map(|s| {
                        let c = compensate(s, b);
                        polar_to_plane(c.range, c.azimuth)
                    })
                    .collect()
            })
            .collect();
        let mut edges = Vec::new();
        for (i, track) in radar.iter().enumerate() {
            for (j, ship) in ais.iter().enumerate() {
                let d: Vec<f64> = ship
                    .iter()
                    .filter_map(|r| bracket(track, r.t, cfg.max_gap).map(|bw| (r, bw)))
                    .map(|(r, (a, w))| {
                        let p = at(&pos[i], a, w);
                        (p[0] - r.position[0]).hypot(p[1] - r.position[1])
                    })
                    .collect();
                if d.len() >= cfg.min_common {
                    let m = d.iter().sum::<f64>() / d.len() as f64;
                    if m < cfg.gate {
                        edges.push((i, j, m));
                    }
                }
            }
        }
        edges
    };
    let mut best: Option<(usize, f64, Bias)> = None;
    for i in 0..radar.len() {
        for j in 0..cols {
            let r = problem.residuals(i, j);
            if r.len() < cfg.min_common {
                continue;
            }
            let n = r.len() as f64;
            let b = Bias {
                range: r.iter().map(|x| x.0[0]).sum::<f64>() / n,
                azimuth: r.iter().map(|x| x.0[1]).sum::<f64>() / n,
            };
            if b.range.abs() > cfg.max_range_bias || b.azimuth.abs() > cfg.max_azimuth_bias {
                continue;
            }
            let edges = full(b);
            let pairs = assignment::solve(&edges, cfg.gate);
            let total: f64 = pairs
                .iter()
                .map(|p| edges.iter().find(|e| (e.0, e.1) == *p).unwrap().2)
                .sum();
            if best.is_none_or(|(c, t, _)| pairs.len() > c || (pairs.len() == c && total < t)) {
                best = Some((pairs.len(), total, b));
            }
        }
    }
    problem.refine(best.unwrap().2)
}

/// Issue 17: the ranked search must decide as the exhaustive one on
/// scenes where that was right (harbour and open sea, several seeds,
/// small and large biases).
#[test]
fn ranked_search_matches_the_exhaustive_search() {
    let cfg = Config {
        seeding: Seeding::Search,
        ..Config::default()
    };
    let mut compared = 0;
    for seed in 0..3u64 {
        for (make, bias) in [
            (
                AisSceneConfig::harbour(20, 500.0, 0.5f64.to_radians()),
                500.0,
            ),
            (
                AisSceneConfig::harbour(20, 3000.0, -1f64.to_radians()),
                3000.0,
            ),
            (
                AisSceneConfig::open_sea(12, 2000.0, 1f64.to_radians()),
                2000.0,
            ),
        ] {
            let scene = make.generate(&mut run_rng(seed, bias as u64)).unwrap();
            let reference = exhaustive(&scene.radar, &scene.ais, &cfg);
            let out = associate(&scene.radar, &scene.ais, &cfg);
            let pairs: Vec<(usize, usize)> =
                out.associations.iter().map(|a| (a.radar, a.ais)).collect();
            assert_eq!(pairs, reference.pairs, "seed {seed} bias {bias}");
            let (e, r) = (out.estimate.unwrap().bias, reference.estimate.unwrap().bias);
            assert!((e.range - r.range).abs() < 1e-6, "{e:?} {r:?}");
            assert!((e.azimuth - r.azimuth).abs() < 1e-9, "{e:?} {r:?}");
            assert!(out.evaluated <= cfg.max_evaluations);
            compared += 1;
        }
    }
    assert_eq!(compared, 9);
}

/// The smaller-side formulation against `assignment::solve` (the square
/// (s + l)² formulation, itself checked against brute force): on random
/// sparse problems with continuous costs (a unique optimum) both choose
/// the same pairs, with the same objective.
#[test]
fn gated_solver_matches_the_square_formulation() {
    let mut rng = run_rng(170, 0);
    for case in 0..300 {
        let (rows, cols) = (rng.random_range(1..30), rng.random_range(1..30));
        let density = rng.random_range(0.02..0.9);
        let gate = 100.0;
        let mut edges = Vec::new();
        for i in 0..rows {
            for j in 0..cols {
                if rng.random_bool(density) {
                    edges.push((i, j, rng.random_range(0.0..1.2 * gate)));
                }
            }
        }
        let reference = assignment::solve(&edges, gate);
        let got = solve_gated(&edges, rows, cols, gate);
        assert_eq!(got, reference, "case {case}: {rows}x{cols}");
    }
}

/// Issue 17's silent failure: a 6 km range bias, past the 5 km bound.
/// The widened search finds it (and says so); without widening the
/// result is flagged, never returned as a clean answer.
#[test]
fn bias_past_the_bound_is_found_by_widening_or_flagged() {
    let cfg = AisSceneConfig::harbour(48, 6000.0, 1f64.to_radians());
    let scene = cfg.generate(&mut run_rng(17, 6000)).unwrap();
    let out = associate(&scene.radar, &scene.ais, &Config::default());
    let (c, f, m) = score(&out, &scene.owner);
    assert!(out.widened.is_some(), "{:?}", out.widened);
    assert!(c >= 33 && f == 0, "{c}/{f}/{m}");
    let e = out.estimate.unwrap();
    assert!((e.bias.range - 6000.0).abs() < 10.0, "{:?}", e.bias);
    assert!(out.at_bound && !out.inconsistent);

    let fixed = Config {
        widen: false,
        ..Config::default()
    };
    let out = associate(&scene.radar, &scene.ais, &fixed);
    assert!(out.widened.is_none());
    let flagged = out.at_bound || out.inconsistent || out.estimate.is_none();
    assert!(flagged, "{:?} {}", out.estimate, out.inconsistent);
}

/// A row of moored ships 300 m apart along one bearing, AIS on the
/// first three: a bias 300 m larger pairs every AIS ship with the next
/// track exactly as well, so the result must say it is ambiguous.
#[test]
fn periodic_row_is_ambiguous() {
    let ships: Vec<([f64; 2], [f64; 2])> = (0..6)
        .map(|k| ([0.0, 5000.0 + 300.0 * k as f64], [0.0, 0.0]))
        .collect();
    let bias = Bias {
        range: 200.0,
        azimuth: 0.0,
    };
    let (radar, ais) = scene(&ships, &[true, true, true, false, false, false], bias);
    let out = associate(&radar, &ais, &Config::default());
    let alt = out.ambiguous.expect("ambiguous");
    let e = out.estimate.unwrap().bias;
    let shift = (alt.bias.range - e.range).abs();
    assert!((shift / 300.0 - (shift / 300.0).round()).abs() < 1e-6 && shift > 1.0);
    assert_eq!(alt.pairs, 3);
}

/// Residuals of σρ = 50 m and σθ = 0.2° against stated errors ten times
/// smaller are inconsistent; against the true ones they are not (ratio
/// near 1: each axis's residual over its stated σ has unit variance;
/// here about 0.82, see below).
#[test]
fn residuals_beyond_the_stated_errors_are_inconsistent() {
    // With this crate's own scene generator (the workspace split moved
    // the simulator out), the ratio over seeds 0–29 of this scene is
    // 0.785–0.859 (mean 0.82; one outlier at 2.6, seed 13): the radar
    // track interpolated between scans has less variance than its
    // stated σ. Seed 1 (0.821) is a typical run; the simulator's seed 4
    // was the typical run of the old generator.
    let scene = AisSceneConfig::open_sea(20, 500.0, 0.5f64.to_radians())
        .generate(&mut run_rng(1, 0))
        .unwrap();
    let stated = Config {
        sigma_ais: 0.0001,
        ..Config::default()
    };
    let out = associate(&scene.radar, &scene.ais, &stated);
    let ratio = out.estimate.unwrap().residual_ratio;
    assert!(!out.inconsistent && (0.8..1.25).contains(&ratio), "{ratio}");
    let small = Config {
        sigma_range: 5.0,
        sigma_azimuth: 0.02f64.to_radians(),
        sigma_ais: 1.0,
        ..Config::default()
    };
    let out = associate(&scene.radar, &scene.ais, &small);
    assert!(out.inconsistent, "{:?}", out.estimate);
    assert_eq!(score(&out, &scene.owner), (20, 0, 0));
}

#[test]
fn a_single_ais_report_is_never_associable() {
    let bias = Bias {
        range: 300.0,
        azimuth: 0.0,
    };
    let (radar, mut ais) = scene(&grid_ships(5), &[true; 5], bias);
    ais[2].truncate(1);
    let out = associate(&radar, &ais, &Config::default());
    assert_eq!(out.unassociable_ais, vec![2]);
    assert!(out.associations.iter().all(|a| a.ais != 2));
    assert_eq!(out.associations.len(), 4);
}

/// T²(2, ν) in closed form against tabulated F quantiles:
/// F₀.₉₅(2, 18) = 3.5546 (tables), T² = 2·19/18 · 3.5546 = 7.5041,
/// over χ²₂ = 5.9915 gives 1.2525; F₀.₉₅(2, 1) = 199.5 gives
/// 4 · 199.5 / 5.9915 = 133.19.
#[test]
fn small_sample_factor_matches_f_tables() {
    assert!((small_sample_factor(19.0) - 1.2525).abs() < 1e-3);
    assert!((small_sample_factor(2.0) - 133.19).abs() < 0.05);
    assert!((small_sample_factor(1e6) - 1.0).abs() < 1e-4);
}

/// Whole-second AIS times (NMEA tag blocks truncate): taken at the
/// middle of their second with σ = 1/√12 s, the bias covariance must
/// cover the truth over Monte Carlo runs (95 % ellipse, χ²₂ = 5.991);
/// taken as exact, the azimuth is biased by the fleet's along-track
/// offsets (½ s × 30–80 m/s).
#[test]
fn quantised_ais_times_are_covered_by_the_covariance() {
    let runs = 100;
    let (mut inside, mut nees_sum) = (0, 0.0);
    for run in 0..runs {
        let truth = [500.0, 0.5f64.to_radians()];
        let mut scene = AisSceneConfig::open_sea(20, truth[0], truth[1])
            .generate(&mut run_rng(40, run))
            .unwrap();
        for ship in &mut scene.ais {
            for r in ship.iter_mut() {
                r.t = r.t.floor() + 0.5;
                r.time_sigma = quantisation_sigma(1.0);
            }
        }
        let e = associate(&scene.radar, &scene.ais, &Config::default())
            .estimate
            .unwrap();
        let d = [e.bias.range - truth[0], e.bias.azimuth - truth[1]];
        let c = e.covariance;
        let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
        let nees =
            (c[1][1] * d[0] * d[0] - 2.0 * c[0][1] * d[0] * d[1] + c[0][0] * d[1] * d[1]) / det;
        nees_sum += nees;
        inside += usize::from(nees <= 5.991);
    }
    // Binomial(100, 0.95): 3 standard deviations (2.2 %) below is 88.5 %.
    assert!(inside >= 88, "{inside}/{runs}");
    assert!(nees_sum / runs as f64 <= 2.6, "{}", nees_sum / runs as f64);
}

#[test]
fn noise_free_bias_is_recovered_to_1e_9() {
    let bias = Bias {
        range: 500.0,
        azimuth: 0.5f64.to_radians(),
    };
    let ships = grid_ships(12);
    let (radar, ais) = scene(&ships, &[true; 12], bias);
    for seeding in [Seeding::Cfar, Seeding::Search, Seeding::Auto] {
        let cfg = Config {
            seeding,
            ..Config::default()
        };
        let out = associate(&radar, &ais, &cfg);
        let e = out.estimate.unwrap();
        assert!(
            (e.bias.range - 500.0).abs() < 1e-9,
            "{seeding:?} {:?}",
            e.bias
        );
        assert!((e.bias.azimuth - bias.azimuth).abs() < 1e-12);
        assert_eq!(out.associations.len(), 12);
        assert!(out.associations.iter().all(|a| a.radar == a.ais));
        assert!(out.mean_error_after.unwrap() < 1e-6);
    }
}

#[test]
fn large_range_bias_needs_the_search() {
    // 3 km range bias and 1°: the biased tracks sit closer to their
    // neighbours' AIS than to their own.
    let bias = Bias {
        range: 3000.0,
        azimuth: 1f64.to_radians(),
    };
    let ships = grid_ships(10);
    let mut with = [true; 10];
    with[3] = false;
    with[7] = false;
    let (radar, ais) = scene(&ships, &with, bias);
    let out = associate(&radar, &ais, &Config::default());
    let e = out.estimate.unwrap();
    assert!((e.bias.range - 3000.0).abs() < 1e-9);
    assert_eq!(out.associations.len(), 8);
    // AIS index j belongs to ship with[..] position j.
    let owners: Vec<usize> = (0..10).filter(|&s| with[s]).collect();
    assert!(out.associations.iter().all(|a| owners[a.ais] == a.radar));
}

#[test]
fn one_ship_no_ships_and_ships_without_ais() {
    let bias = Bias {
        range: 200.0,
        azimuth: -0.3f64.to_radians(),
    };
    let one = grid_ships(1);
    let (radar, ais) = scene(&one, &[true], bias);
    let out = associate(&radar, &ais, &Config::default());
    assert_eq!(out.path, Path::BiasSearch);
    assert!((out.estimate.unwrap().bias.range - 200.0).abs() < 1e-9);
    assert_eq!(out.associations.len(), 1);

    let out = associate(&[], &[], &Config::default());
    assert_eq!(out.path, Path::None);
    assert!(out.associations.is_empty() && out.estimate.is_none());

    let (radar, _) = scene(&grid_ships(4), &[false; 4], bias);
    let out = associate(&radar, &[], &Config::default());
    assert_eq!(out.path, Path::None);
    assert!(out.associations.is_empty());
}

#[test]
fn interpolation_never_crosses_long_gaps_or_extrapolates() {
    let s = |t| RadarSample {
        t,
        range: 1.0,
        azimuth: 0.0,
    };
    let track = [s(0.0), s(10.0), s(50.0)];
    assert_eq!(bracket(&track, 5.0, 30.0), Some((0, 0.5)));
    assert_eq!(bracket(&track, 10.0, 30.0), Some((1, 0.0)));
    assert_eq!(bracket(&track, 50.0, 30.0), Some((2, 0.0)));
    assert_eq!(bracket(&track, 20.0, 30.0), None);
    assert_eq!(bracket(&track, 60.0, 30.0), None);
    assert_eq!(bracket(&track, -1.0, 30.0), None);
}

/// Tracks share brackets only with tracks whose times are equal bit for
/// bit (+0 and −0 differ), and every pair's shared brackets are the ones
/// its own track gives (`walk` run on that track alone), on a harbour
/// where half the tracks keep the scan times and the rest are moved
/// by a per-track offset (a plot timed by its azimuth).
#[test]
fn time_groups_share_only_identical_brackets() {
    let mut scene = AisSceneConfig::harbour(24, 500.0, 0.5f64.to_radians())
        .generate(&mut run_rng(3, 0))
        .unwrap();
    for (i, track) in scene.radar.iter_mut().enumerate() {
        if i % 2 == 1 {
            let offset = 0.1 * (i % 6) as f64;
            track.iter_mut().for_each(|s| s.t += offset);
        }
    }
    // The first sample at −0: a group of its own (tracks 2 and 4 keep
    // +0; track 6 is moved to −0 and so is track 8, which joins it).
    for i in [6, 8] {
        scene.radar[i][0].t = -0.0;
    }
    let (group, sizes) = time_groups(&scene.radar);
    for a in 0..scene.radar.len() {
        for b in 0..scene.radar.len() {
            let same = scene.radar[a].len() == scene.radar[b].len()
                && scene.radar[a]
                    .iter()
                    .zip(&scene.radar[b])
                    .all(|(x, y)| x.t.to_bits() == y.t.to_bits());
            assert_eq!(group[a] == group[b], same, "tracks {a} and {b}");
        }
    }
    assert_eq!(sizes.iter().sum::<usize>(), scene.radar.len());
    assert!(sizes.iter().any(|&n| n > 2) && group[6] == group[8] && group[6] != group[2]);

    let cfg = Config::default();
    let problem = Problem::new(&scene.radar, &scene.ais, &cfg);
    let key = |b: &[Bracket]| -> Vec<(u32, u32, u64)> {
        b.iter().map(|b| (b.k, b.a, b.w.to_bits())).collect()
    };
    let mut walked = 0;
    for i in 0..scene.radar.len() {
        for j in 0..scene.ais.len() {
            let own = walk_brackets(&scene.radar[i], &scene.ais[j], cfg.max_gap);
            let ij = i * problem.cols + j;
            assert_eq!(key(problem.walked(ij)), key(&own), "pair {i}, {j}");
            if problem.summary[ij].n > 0 {
                assert_eq!(problem.summary[ij].n, own.len());
                assert_eq!(key(problem.brackets(ij)), key(&own));
                walked += 1;
            }
        }
    }
    assert!(walked > scene.ais.len());
}
