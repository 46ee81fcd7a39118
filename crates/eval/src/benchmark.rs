//! The scenes of the correlation benchmarks (criterion, the REST load test and
//! `examples/correlation_payload.rs`).
//!
//! [`correlation_request`] (the load tests): two nodes, n targets each, 8
//! samples per track, as a service request. Targets are uniform in a square
//! of side 2 km·√n (one per 4 km², the same density at every n), speeds
//! 4–1200 m/s, headings uniform, T = 4 s; each node reports the truth plus
//! Gaussian errors of σ = 200 m (position) and 30 m/s (velocity) with that
//! diagonal covariance. Method: independent double threshold 6/8 at α = 0.05.
//!
//! [`realistic_scene`] (the engine benchmarks of issue 14): two radars'
//! Kalman-filtered tracks of the same targets, already aligned, as a
//! [`Scene`] the engine takes directly (and as the equivalent request).
//! Targets fly straight at 100–300 m/s with DWNA process noise σ_a = 2 m/s²
//! over a square of side 60 km·√(n/120) (120 targets over 60 km × 60 km);
//! a tenth fly in pairs 300–800 m apart on parallel tracks and a tenth cross
//! another target's path mid-scene. Each node measures positions every 4 s
//! with a polar-like error (σ 120 m in range, 250 m cross-range from its
//! site; the second node 180 m and 350 m) and runs a constant-velocity
//! Kalman filter with the true model, so estimates and covariances are
//! consistent and the two nodes' errors are correlated through the common
//! process noise (what the modified statistic accounts for). The filters run
//! 5 scans before the scene so that covariances are near steady state; 2 %
//! of reports are lost (the track is absent at that instant); the second
//! node lists its tracks in a shuffled order.

use rand::RngExt;
use rand_distr::StandardNormal;

use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};

use super::montecarlo::run_rng;
use algo::{
    correlation::{
        engine::{
            Config, Decision, Method, PairCorrelator, Pruning, Resolution, RuleSpec, Statistic,
        },
        grouping::{self, Link},
        rules::LrRule,
        scene::{Scene, Track},
    },
    motion::{ConstantVelocity, ProcessNoise},
};
use service::correlation::{
    CorrelateInput, MethodInput, MotionModelInput, NodeInput, RuleInput, SampleInput, TrackInput,
};
use service::{Rows, plot_fusion};

/// Position and velocity error σ of the benchmark's local tracks.
pub const SIGMA_POSITION_M: f64 = 200.0;
pub const SIGMA_VELOCITY_MPS: f64 = 30.0;

/// The benchmark request for `n` targets, with `pruning` = `grid` or `none`.
pub fn correlation_request(n: usize, pruning: &str) -> CorrelateInput {
    let mut rng = run_rng(42, n as u64);
    let normal = |rng: &mut super::SimRng| -> f64 { rng.sample(StandardNormal) };
    let side = 2000.0 * (n as f64).sqrt();
    let targets: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            let speed = rng.random_range(4.0..1200.0);
            let heading: f64 = rng.random_range(0.0..std::f64::consts::TAU);
            [
                rng.random_range(0.0..side),
                speed * heading.sin(),
                rng.random_range(0.0..side),
                speed * heading.cos(),
            ]
        })
        .collect();
    let (sp, sv) = (SIGMA_POSITION_M, SIGMA_VELOCITY_MPS);
    let cov = Rows::from_nested(&[
        [sp * sp, 0.0, 0.0, 0.0],
        [0.0, sv * sv, 0.0, 0.0],
        [0.0, 0.0, sp * sp, 0.0],
        [0.0, 0.0, 0.0, sv * sv],
    ]);
    let nodes = ["n1", "n2"]
        .iter()
        .map(|id| NodeInput {
            id: Some(id.to_string()),
            tracks: targets
                .iter()
                .enumerate()
                .map(|(i, x)| TrackInput {
                    id: Some(i.to_string()),
                    samples: (0..8)
                        .map(|k| {
                            let t = 4.0 * k as f64;
                            SampleInput {
                                t: Some(t),
                                state: vec![
                                    x[0] + x[1] * t + sp * normal(&mut rng),
                                    x[1] + sv * normal(&mut rng),
                                    x[2] + x[3] * t + sp * normal(&mut rng),
                                    x[3] + sv * normal(&mut rng),
                                ],
                                covariance: cov.clone(),
                                gain: None,
                            }
                        })
                        .collect(),
                })
                .collect(),
        })
        .collect();
    CorrelateInput {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(MethodInput {
            kind: Some("independent_double_threshold".into()),
            rule: Some(RuleInput {
                l: Some(6),
                r: Some(8),
            }),
            ..Default::default()
        }),
        nodes,
        pruning: Some(pruning.into()),
        ..Default::default()
    }
}

/// Every method of the API, by its request name: the engine benchmarks run
/// each of them on [`realistic_scene`].
pub const METHODS: [&str; 8] = [
    "weighted",
    "modified",
    "independent_double_threshold",
    "dependent_double_threshold",
    "double_threshold_assignment",
    "nearest_neighbour",
    "global_assignment",
    "k_nearest_neighbour",
];

/// Acceleration noise σ_a of the targets and of the local filters (m/s²).
pub const SIGMA_A_MPS2: f64 = 2.0;
/// Scan period of both radars (s): the instants of [`realistic_scene`] are
/// this far apart.
pub const SCAN_S: f64 = 4.0;

/// The local filters' motion model in [`realistic_scene`] (state
/// [x, vx, y, vy]).
pub fn realistic_model() -> ConstantVelocity {
    ConstantVelocity::new(
        2,
        ProcessNoise::Dwna {
            sigma_a: SIGMA_A_MPS2,
        },
    )
    .expect("valid model")
}

/// Two radars' aligned tracks of the same targets (see the module comment).
pub struct RealisticScene {
    /// The engine's input: node 0 and node 1, state [x, vx, y, vy].
    pub scene: Scene,
    /// The same samples as a service request (method and pruning unset; a
    /// constant-velocity DWNA motion model; gains when asked for).
    pub request: CorrelateInput,
    /// The target of each track of the second node (a track of the first
    /// node has the index of its target).
    pub target_b: Vec<usize>,
}

/// The realistic benchmark scene of `n` targets over `instants` instants,
/// 4 s apart. With `gains` every sample carries its filter's I − K H (the
/// request: K and H), otherwise the modified statistic recomputes it from
/// the covariances.
pub fn realistic_scene(n: usize, instants: usize, gains: bool) -> RealisticScene {
    use std::f64::consts::TAU;
    let mut rng = run_rng(44, n as u64);
    let normal = |rng: &mut super::SimRng| -> f64 { rng.sample(StandardNormal) };
    let side = 60_000.0 * (n as f64 / 120.0).sqrt();
    let warm = 5;
    let steps = warm + instants;
    // Targets at the first (warm-up) scan.
    let mut targets: Vec<Vector4<f64>> = Vec::with_capacity(n);
    let velocity = |rng: &mut super::SimRng, heading: f64| {
        let speed = rng.random_range(100.0..300.0);
        (speed * heading.sin(), speed * heading.cos())
    };
    while targets.len() < n {
        let heading: f64 = rng.random_range(0.0..TAU);
        let (vx, vy) = velocity(&mut rng, heading);
        let x = Vector4::new(
            rng.random_range(0.0..side),
            vx,
            rng.random_range(0.0..side),
            vy,
        );
        targets.push(x);
        let kind = rng.random_range(0..10);
        if kind == 0 && targets.len() < n {
            // A formation partner abeam, 300–800 m away.
            let gap = rng.random_range(300.0..800.0);
            let (ux, uy) = (heading.cos(), -heading.sin());
            targets.push(Vector4::new(x[0] + gap * ux, vx, x[2] + gap * uy, vy));
        } else if kind == 1 && targets.len() < n {
            // A target crossing this one's path where it is mid-scene.
            let tc = (warm as f64 + instants as f64 / 2.0) * SCAN_S;
            let (mx, my) = (x[0] + vx * tc, x[2] + vy * tc);
            let turn: f64 = rng.random_range(0.5..2.6);
            let (wx, wy) = velocity(&mut rng, heading + turn);
            targets.push(Vector4::new(mx - wx * tc, wx, my - wy * tc, wy));
        }
    }
    // Truth with DWNA process noise: x⁺ = F x + Γ a, Γ = [T²/2, T]' per axis.
    let t = SCAN_S;
    let f = Matrix4::new(
        1.0, t, 0.0, 0.0, //
        0.0, 1.0, 0.0, 0.0, //
        0.0, 0.0, 1.0, t, //
        0.0, 0.0, 0.0, 1.0,
    );
    let (q11, q12, q22) = (t.powi(4) / 4.0, t.powi(3) / 2.0, t * t);
    let s2 = SIGMA_A_MPS2 * SIGMA_A_MPS2;
    let q = Matrix4::new(
        q11, q12, 0.0, 0.0, //
        q12, q22, 0.0, 0.0, //
        0.0, 0.0, q11, q12, //
        0.0, 0.0, q12, q22,
    ) * s2;
    let mut truth: Vec<Vec<Vector4<f64>>> = vec![targets];
    for _ in 1..steps {
        let prev = truth.last().expect("one scan");
        let next = prev
            .iter()
            .map(|x| {
                let (ax, ay) = (
                    SIGMA_A_MPS2 * normal(&mut rng),
                    SIGMA_A_MPS2 * normal(&mut rng),
                );
                f * x + Vector4::new(t * t / 2.0 * ax, t * ax, t * t / 2.0 * ay, t * ay)
            })
            .collect();
        truth.push(next);
    }
    let h = Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0);
    // (site, σ range, σ cross-range) of each node.
    let radars = [
        (Vector2::new(-0.1 * side, 0.5 * side), 120.0, 250.0),
        (Vector2::new(0.5 * side, -0.1 * side), 180.0, 350.0),
    ];
    let times: Vec<f64> = (0..instants).map(|k| k as f64 * SCAN_S).collect();
    let mut scene = Scene::new(4, vec![0, 2], times.clone()).expect("valid scene");
    let mut nodes = Vec::new();
    let mut target_b: Vec<usize> = (0..n).collect();
    for i in (1..n).rev() {
        target_b.swap(i, rng.random_range(0..=i));
    }
    for (node, &(site, sr, sc)) in radars.iter().enumerate() {
        let order: Vec<usize> = if node == 0 {
            (0..n).collect()
        } else {
            target_b.clone()
        };
        let mut tracks = Vec::with_capacity(n);
        let mut inputs = Vec::with_capacity(n);
        for &target in &order {
            let (sp0, sv0) = (300.0, 40.0);
            let x0 = truth[0][target];
            let mut x = x0
                + Vector4::new(
                    sp0 * normal(&mut rng),
                    sv0 * normal(&mut rng),
                    sp0 * normal(&mut rng),
                    sv0 * normal(&mut rng),
                );
            let mut p =
                Matrix4::from_diagonal(&Vector4::new(sp0 * sp0, sv0 * sv0, sp0 * sp0, sv0 * sv0));
            let mut track = Track::new(instants, 4);
            let mut samples = Vec::new();
            for (k, scan) in truth.iter().enumerate() {
                if k > 0 {
                    x = f * x;
                    p = f * p * f.transpose() + q;
                }
                let xt = scan[target];
                let los = Vector2::new(xt[0], xt[2]) - site;
                let u = los / los.norm();
                let w = Vector2::new(-u[1], u[0]);
                let r = u * u.transpose() * (sr * sr) + w * w.transpose() * (sc * sc);
                let z = h * xt + u * (sr * normal(&mut rng)) + w * (sc * normal(&mut rng));
                let s = h * p * h.transpose() + r;
                let s_inv: Matrix2<f64> = s.try_inverse().expect("positive definite");
                let gain = p * h.transpose() * s_inv;
                x += gain * (z - h * x);
                let a = Matrix4::identity() - gain * h;
                // Joseph form, symmetrised.
                p = a * p * a.transpose() + gain * r * gain.transpose();
                p = (p + p.transpose()) * 0.5;
                let j = k as isize - warm as isize;
                if j < 0 || rng.random::<f64>() < 0.02 {
                    continue;
                }
                let j = j as usize;
                let row = |m: &Matrix4<f64>| -> Vec<f64> {
                    (0..4)
                        .flat_map(|i| (0..4).map(move |c| m[(i, c)]))
                        .collect()
                };
                track.set(j, x.as_slice(), &row(&p));
                if gains {
                    track.set_gain_factor(j, &row(&a));
                }
                samples.push(SampleInput {
                    t: Some(times[j]),
                    state: x.as_slice().to_vec(),
                    covariance: Rows::from_nested(
                        &(0..4)
                            .map(|i| [p[(i, 0)], p[(i, 1)], p[(i, 2)], p[(i, 3)]])
                            .collect::<Vec<_>>(),
                    ),
                    gain: gains.then(|| {
                        Rows::from_nested(
                            &(0..4)
                                .map(|i| [gain[(i, 0)], gain[(i, 1)]])
                                .collect::<Vec<_>>(),
                        )
                    }),
                });
            }
            tracks.push(track);
            inputs.push(TrackInput {
                id: Some(format!("{}{target}", ["a", "b"][node])),
                samples,
            });
        }
        scene.add_node(tracks).expect("consistent tracks");
        nodes.push(NodeInput {
            id: Some(format!("radar{}", node + 1)),
            tracks: inputs,
        });
    }
    let request = CorrelateInput {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        motion_model: Some(MotionModelInput {
            kind: Some("constant_velocity".into()),
            process_noise: Some("dwna".into()),
            sigma_a_mps2: Some(SIGMA_A_MPS2),
            ..Default::default()
        }),
        measurement_matrix: gains.then(|| vec![vec![1.0, 0.0, 0.0, 0.0], vec![0.0, 0.0, 1.0, 0.0]]),
        nodes,
        ..Default::default()
    };
    RealisticScene {
        scene,
        request,
        target_b,
    }
}

/// The engine configuration of the API method `name` with the service's
/// defaults (rule 6/8, window 1, K-NN 3 of 5, α = 0.05).
pub fn engine_config(name: &str, pruning: Pruning) -> Config {
    let rule = |l, r| RuleSpec::Fixed(LrRule::new(l, r).expect("valid rule"));
    let dt = |l, r, resolution| Method::DoubleThreshold {
        rules: rule(l, r),
        resolution,
    };
    let (method, statistic) = match name {
        "weighted" => (dt(1, 1, Resolution::Greedy), Statistic::Weighted),
        "modified" => (dt(1, 1, Resolution::Greedy), Statistic::Modified),
        "independent_double_threshold" => (dt(6, 8, Resolution::Greedy), Statistic::Weighted),
        "dependent_double_threshold" => (dt(6, 8, Resolution::Greedy), Statistic::Modified),
        "double_threshold_assignment" => (dt(6, 8, Resolution::Assignment), Statistic::Weighted),
        "nearest_neighbour" => (Method::NearestNeighbour { window: 1 }, Statistic::Weighted),
        "global_assignment" => (Method::GlobalAssignment { window: 1 }, Statistic::Weighted),
        "k_nearest_neighbour" => (
            Method::KNearestNeighbour { k: 3, window: 5 },
            Statistic::Weighted,
        ),
        other => panic!("unknown method {other}"),
    };
    Config {
        method,
        statistic,
        alpha: 0.05,
        pruning,
    }
}

/// What the engine benchmark computed, to check a run did the work.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EngineOutcome {
    /// Candidate pairs held by the engine.
    pub pairs: usize,
    /// Pairs decided correlated at the last instant.
    pub correlated: usize,
    /// Of those, pairs of the same target.
    pub right: usize,
    /// Groups formed from them.
    pub groups: usize,
}

/// The engine's part of a correlation request on a prebuilt aligned scene:
/// the pair correlator over every instant, its reports and the grouping of
/// the correlated pairs (what the service times as `correlate_us`, without
/// the alignment and the response).
pub fn correlate_scene(s: &RealisticScene, cfg: &Config) -> EngineOutcome {
    let model = realistic_model();
    let mut c = PairCorrelator::new(&s.scene, 0, 1, cfg, Some(&model)).expect("valid config");
    c.run().expect("no pair budget");
    let reports = c.reports();
    let links: Vec<Link> = reports
        .iter()
        .filter(|r| r.decision == Decision::Correlated)
        .map(|r| Link {
            a: (0, r.a),
            b: (1, r.b),
            m: r.m,
            mean_statistic: r.mean_statistic,
        })
        .collect();
    let groups = grouping::group(&links).groups.len();
    EngineOutcome {
        pairs: reports.len(),
        correlated: links.len(),
        right: links.iter().filter(|l| s.target_b[l.b.1] == l.a.1).count(),
        groups,
    }
}

/// How the plots of the plot-fusion benchmark scene are timed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlotTiming {
    /// Each plot at the instant the beam crossed the target, as a real radar
    /// times it (ASTERIX CAT048 I048/140), quantised to 1/128 s: almost
    /// every plot has its own time.
    Beam,
    /// Every plot of a scan stamped with the scan's start, and the target
    /// taken there: a convenient but unrealistic feed (a real plot's time
    /// is then up to one scan off).
    ScanStart,
}

/// The plot-fusion benchmark scene: the request's spec and plots, and the
/// truth (each target's `[e, ve, n, vn]` at t = 0, straight flight).
#[derive(Debug, Clone)]
pub struct PlotFusionScene {
    /// The network and default tracker options.
    pub spec: plot_fusion::SpecInput,
    /// Every plot, sorted by time.
    pub plots: Vec<plot_fusion::PlotInput>,
    /// Per target, `[e, ve, n, vn]` (m, m/s) at t = 0 in the radars' frame.
    pub targets: Vec<[f64; 4]>,
}

impl PlotFusionScene {
    /// Horizontal error (m) of a position at time `t` to the nearest target.
    pub fn nearest_error(&self, t: f64, e: f64, n: f64) -> f64 {
        self.targets
            .iter()
            .map(|x| (x[0] + x[1] * t - e).hypot(x[2] + x[3] * t - n))
            .fold(f64::INFINITY, f64::min)
    }
}

/// The plot-fusion benchmark scene (`examples/plot_fusion_load.rs`): `n`
/// targets in straight flight uniform in a square of side 6 km·√n (one per
/// 36 km²: 1,000 targets over 190 km × 190 km) at 100–300 m/s, seen by
/// `radars` 2D radars spread on a 60 km circle about the centre, scan
/// periods 4, 4.5, 5, 5.5 s with phases 0, 1.1, 2.3, 3.7 s, σ_ρ = 50 m,
/// σ_θ = 0.1°, P_D = 0.9, `false_per_scan` clutter plots per scan
/// (uniform in range 1–200 km and azimuth); with `doppler` every radar
/// also gives the radial velocity (σ 1 m/s). The beams turn clockwise
/// from north, one turn per scan period from the scan's start; with
/// [`PlotTiming::Beam`] a target's plot is at the time the beam crossed it
/// (found by fixed-point iteration on the target's azimuth, to well below
/// a millisecond) and stamped to 1/128 s. Plots are in time order.
pub fn plot_fusion_scene(
    n: usize,
    radars: usize,
    duration_s: f64,
    false_per_scan: usize,
    doppler: bool,
    timing: PlotTiming,
) -> PlotFusionScene {
    use std::f64::consts::TAU;
    let mut rng = run_rng(43, n as u64);
    let normal = |rng: &mut super::SimRng| -> f64 { rng.sample(StandardNormal) };
    let side = 6000.0 * (n as f64).sqrt();
    let targets: Vec<[f64; 4]> = (0..n)
        .map(|_| {
            let speed = rng.random_range(100.0..300.0);
            let heading: f64 = rng.random_range(0.0..TAU);
            [
                rng.random_range(-side / 2.0..side / 2.0),
                speed * heading.sin(),
                rng.random_range(-side / 2.0..side / 2.0),
                speed * heading.cos(),
            ]
        })
        .collect();
    let sites: Vec<[f64; 2]> = (0..radars)
        .map(|i| {
            let a = TAU * i as f64 / radars as f64;
            [60_000.0 * a.sin(), 60_000.0 * a.cos()]
        })
        .collect();
    let periods = [4.0, 4.5, 5.0, 5.5];
    let phases = [0.0, 1.1, 2.3, 3.7];
    let (sr, sa, sv) = (50.0, 0.1f64.to_radians(), 1.0);
    // The time stamp of I048/140: 1/128 s.
    let stamp = |t: f64| (t * 128.0).round() / 128.0;
    let mut plots: Vec<plot_fusion::PlotInput> = Vec::new();
    for (r, site) in sites.iter().enumerate() {
        let period = periods[r % 4];
        let mut start = phases[r % 4];
        while start <= duration_s {
            for x in &targets {
                if rng.random::<f64>() >= 0.9 {
                    continue;
                }
                let at = |t: f64| (x[0] + x[1] * t - site[0], x[2] + x[3] * t - site[1]);
                let t = match timing {
                    PlotTiming::ScanStart => start,
                    PlotTiming::Beam => {
                        // The beam is at azimuth θ at start + θ/2π · period.
                        let mut t = start;
                        for _ in 0..4 {
                            let (e, nn) = at(t);
                            t = start + e.atan2(nn).rem_euclid(TAU) / TAU * period;
                        }
                        t
                    }
                };
                let (e, nn) = at(t);
                let range = e.hypot(nn);
                let rv = (e * x[1] + nn * x[3]) / range;
                let t_stamped = match timing {
                    PlotTiming::ScanStart => t,
                    PlotTiming::Beam => stamp(t),
                };
                if t_stamped > duration_s {
                    continue;
                }
                plots.push(plot_fusion::PlotInput {
                    radar_id: Some(format!("r{r}")),
                    t: Some(t_stamped),
                    range_m: Some(range + sr * normal(&mut rng)),
                    azimuth_deg: Some((e.atan2(nn) + sa * normal(&mut rng)).to_degrees()),
                    elevation_deg: None,
                    radial_velocity_mps: doppler.then(|| rv + sv * normal(&mut rng)),
                    ssr: Default::default(),
                    report: None,
                });
            }
            for _ in 0..false_per_scan {
                // Drawn in the order of the scene before beam timing.
                let range = rng.random_range(1_000.0..200_000.0);
                let azimuth: f64 = rng.random_range(0.0..360.0);
                let t = match timing {
                    PlotTiming::ScanStart => start,
                    PlotTiming::Beam => stamp(start + azimuth / 360.0 * period),
                };
                let radial = doppler.then(|| rng.random_range(-300.0..300.0));
                if t > duration_s {
                    continue;
                }
                plots.push(plot_fusion::PlotInput {
                    radar_id: Some(format!("r{r}")),
                    t: Some(t),
                    range_m: Some(range),
                    azimuth_deg: Some(azimuth),
                    elevation_deg: None,
                    radial_velocity_mps: radial,
                    ssr: Default::default(),
                    report: None,
                });
            }
            start += period;
        }
    }
    plots.sort_by(|a, b| a.t.unwrap_or(0.0).total_cmp(&b.t.unwrap_or(0.0)));
    let spec = plot_fusion::SpecInput {
        origin: Some(plot_fusion::GeoInput {
            lat_deg: Some(52.0),
            lon_deg: Some(4.0),
            height_m: Some(0.0),
        }),
        radars: sites
            .iter()
            .enumerate()
            .map(|(r, site)| plot_fusion::RadarInput {
                id: Some(format!("r{r}")),
                kind: Some("2d".into()),
                site: Some(plot_fusion::SiteInput {
                    geodetic: None,
                    position_m: Some(site.to_vec()),
                }),
                sigma_range_m: Some(sr),
                sigma_azimuth_deg: Some(0.1),
                sigma_radial_velocity_mps: doppler.then_some(sv),
                scan_period_s: Some(periods[r % 4]),
                p_detection: Some(0.9),
                // false_per_scan over 199 km × 2π rad.
                clutter_density: Some((false_per_scan.max(1) as f64) / (199_000.0 * TAU)),
                ..Default::default()
            })
            .collect(),
        tracker: Default::default(),
        cat062: None,
    };
    PlotFusionScene {
        spec,
        plots,
        targets,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_benchmark_scene_is_deterministic_and_correlates() {
        let a = correlation_request(20, "grid");
        let b = correlation_request(20, "grid");
        assert_eq!(
            a.nodes[0].tracks[3].samples[5].state,
            b.nodes[0].tracks[3].samples[5].state
        );
        let out = service::correlation::correlate(a).unwrap();
        // Targets 2 km apart on average against 200 m errors: nearly all the
        // 20 true pairs correlate (a loose bound, not a tuned figure).
        let correlated = out
            .pairs
            .iter()
            .filter(|p| p.decision == algo::correlation::engine::Decision::Correlated)
            .count();
        assert!(correlated >= 15, "{correlated}");
    }

    #[test]
    fn the_realistic_scene_is_consistent_and_correlates() {
        let s = realistic_scene(120, 12, true);
        let dim = s.scene.dim();
        // NEES of the first node's tracks against their second-node twins is
        // not available (no truth kept), but the difference of two tracks of
        // one target has covariance ≈ P_a + P_b − P_ab − P_ab': its weighted
        // statistic, χ²₄ at most inflated by the ignored cross-covariance,
        // averages near 4 when the covariances are consistent. A loose band:
        // 2 to 8 (a gross inconsistency, e.g. σ off by 2, gives 16 or 1).
        let mut sum = 0.0;
        let mut count = 0;
        for (b, &a) in s.target_b.iter().enumerate() {
            let (ta, tb) = (s.scene.track(0, a), s.scene.track(1, b));
            for k in 0..12 {
                if ta.is_present(k) && tb.is_present(k) {
                    let d: Vec<f64> = (0..dim)
                        .map(|i| ta.x(k, dim)[i] - tb.x(k, dim)[i])
                        .collect();
                    let sm: Vec<f64> = (0..dim * dim)
                        .map(|i| ta.p(k, dim)[i] + tb.p(k, dim)[i])
                        .collect();
                    sum += algo::small::quad_form_inv(&sm, &d, dim).unwrap();
                    count += 1;
                }
            }
        }
        let mean = sum / count as f64;
        assert!((2.0..8.0).contains(&mean), "{mean}");
        // Every method finds most true pairs (formation partners 300 m apart
        // may swap, so the bound is loose), and the double-threshold methods
        // make few mistakes.
        for method in METHODS {
            let o = correlate_scene(&s, &engine_config(method, Pruning::Grid));
            assert!(o.right >= 100, "{method}: {o:?}");
            assert!(o.correlated - o.right <= 10, "{method}: {o:?}");
        }
        // The same samples through the service decide the same pairs, when
        // the service aligns them as the prebuilt scene does: as reported
        // at their instants (the default grid would also bring a track's
        // previous report to an instant where its report was lost).
        let mut input = s.request.clone();
        input.method = Some(MethodInput {
            kind: Some("dependent_double_threshold".into()),
            ..Default::default()
        });
        input.alignment = Some(service::correlation::AlignmentInput {
            mode: Some("nearest".into()),
            ..Default::default()
        });
        let out = service::correlation::correlate(input).unwrap();
        let service = out
            .pairs
            .iter()
            .filter(|p| p.decision == Decision::Correlated)
            .count();
        let engine = correlate_scene(
            &s,
            &engine_config("dependent_double_threshold", Pruning::Grid),
        );
        assert_eq!(service, engine.correlated);
    }
}
