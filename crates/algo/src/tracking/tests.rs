//! End-to-end tests of the tracker: the patent's Fig. 5 scene in serial
//! mode, a Doppler scene in parallel mode, a 2D + 3D radar mix, chunked
//! processing with the tracker taken apart and rebuilt between chunks equal
//! to one call, late plots.

use super::*;
use crate::gaussian::check_covariance;
use crate::jpda;
use std::f64::consts::TAU;

/// Knuth's MMIX LCG with Box–Muller normals (tests only: `rand` is not an
/// `algo` dependency).
pub(super) struct Lcg(pub(super) u64);

impl Lcg {
    pub(super) fn uniform(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    pub(super) fn normal(&mut self) -> f64 {
        let (u1, u2) = (self.uniform(), self.uniform());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

#[derive(Clone, Copy)]
pub(super) struct Target {
    pub(super) p0: [f64; 3],
    pub(super) v: [f64; 3],
}

impl Target {
    pub(super) fn at(&self, t: f64) -> [f64; 3] {
        [0, 1, 2].map(|i| self.p0[i] + self.v[i] * t)
    }
}

/// Plots of every radar scan `offset + k·period ≤ duration` of every
/// target, with Gaussian polar noise, sorted by time (stable: radar order,
/// then target order, at equal times).
pub(super) fn scene(
    radars: &[RadarSpec],
    offsets: &[f64],
    targets: &[Target],
    duration: f64,
    rng: &mut Lcg,
) -> Vec<Plot> {
    let mut plots = Vec::new();
    for (i, r) in radars.iter().enumerate() {
        let mut k = 0;
        loop {
            let t = offsets[i] + k as f64 * r.scan_period;
            if t > duration {
                break;
            }
            for target in targets {
                let p = target.at(t);
                let rel = [0, 1, 2].map(|a| p[a] - r.site[a]);
                let horizontal = rel[0].hypot(rel[1]);
                let range = if r.is_3d() {
                    horizontal.hypot(rel[2])
                } else {
                    horizontal
                };
                let radial = if r.is_3d() {
                    (0..3).map(|a| rel[a] * target.v[a]).sum::<f64>() / range
                } else {
                    (rel[0] * target.v[0] + rel[1] * target.v[1]) / range
                };
                plots.push(Plot {
                    radar: i,
                    t,
                    range: range + r.sigma_range * rng.normal(),
                    azimuth: rel[0].atan2(rel[1]) + r.sigma_azimuth * rng.normal(),
                    elevation: r
                        .sigma_elevation
                        .map(|s| rel[2].atan2(horizontal) + s * rng.normal()),
                    radial_velocity: r.sigma_radial_velocity.map(|s| radial + s * rng.normal()),
                    identity: Default::default(),
                    report: None,
                });
            }
            k += 1;
        }
    }
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    plots
}

fn radar(site: [f64; 3], period: f64, doppler: bool) -> RadarSpec {
    RadarSpec {
        site,
        // 100 m in range and ≈ 100 m across at the scene's ≈ 43 km.
        sigma_range: 100.0,
        sigma_azimuth: 100.0 / 43_000.0,
        sigma_elevation: None,
        sigma_radial_velocity: doppler.then_some(1.0),
        scan_period: period,
        detection_probability: 0.99,
        clutter_density: 1e-7,
    }
}

/// The patent's Fig. 5 targets: from [−25, 35] and [−26, 31] km at
/// [30, −50] and [50, 20] m/s. They cross near t ≈ 55 s.
fn fig5_targets() -> [Target; 2] {
    [
        Target {
            p0: [-25_000.0, 35_000.0, 0.0],
            v: [30.0, -50.0, 0.0],
        },
        Target {
            p0: [-26_000.0, 31_000.0, 0.0],
            v: [50.0, 20.0, 0.0],
        },
    ]
}

pub(super) fn fig5_config(doppler: bool) -> TrackerConfig {
    let radars = vec![
        radar([-200.0, 0.0, 0.0], 10.0, doppler),
        radar([200.0, 0.0, 0.0], 8.0, doppler),
    ];
    let mut c = TrackerConfig::new(2, radars);
    c.sigma_a = [0.05; 3];
    c.initiation.velocity = VelocityGate::Speed {
        v_min: 0.0,
        v_max: 150.0,
    };
    c
}

/// Confirmed (time, [x, y]) samples of one track.
type Trace = Vec<(f64, [f64; 2])>;
/// Per confirmed track id, its samples.
type Samples = Vec<(u64, Trace)>;

/// Feeds `plots` (in time order) one time instant per call, calling
/// `each` with the tracker and the instant after each.
pub(super) fn feed_by_instants(
    tracker: &mut Tracker,
    plots: &[Plot],
    mut each: impl FnMut(&Tracker, f64),
) {
    let mut start = 0;
    while start < plots.len() {
        let end = start
            + plots[start..]
                .iter()
                .take_while(|p| p.t == plots[start].t)
                .count();
        tracker.process(&plots[start..end]).unwrap();
        start = end;
        each(tracker, plots[end - 1].t);
    }
}

/// Feeds `plots` one time instant per call, checking every covariance, and
/// returns per confirmed track id its (time, position) samples.
fn run_by_instants(tracker: &mut Tracker, plots: &[Plot]) -> Samples {
    let mut samples: Samples = Vec::new();
    feed_by_instants(tracker, plots, |tr, _| record(tr, &mut samples));
    tracker.flush().unwrap();
    record(tracker, &mut samples);
    samples
}

fn record(tracker: &Tracker, samples: &mut Samples) {
    for tr in tracker.tracks() {
        assert_spd(&tr.covariance);
        if tr.status != TrackStatus::Confirmed {
            continue;
        }
        let s = (tr.t, [tr.state[0], tr.state[2]]);
        match samples.iter_mut().find(|(id, _)| *id == tr.id) {
            Some((_, v)) => {
                if v.last().is_none_or(|l| l.0 != s.0) {
                    v.push(s);
                }
            }
            None => samples.push((tr.id, vec![s])),
        }
    }
}

fn assert_spd(p: &nalgebra::DMatrix<f64>) {
    assert_eq!(p, &p.transpose(), "covariance not exactly symmetric");
    check_covariance("covariance", p).unwrap();
}

/// Each track is matched to the target nearest its first confirmed
/// position (the targets are 4 km apart then); asserts that it is still
/// within 500 m of that target once the targets have separated again
/// after their crossing (t ≥ 75 s, 2.4 km apart: a swap would be ≥ 2 km
/// off) and returns its position RMSE against that target.
fn follow(samples: &[(u64, Trace)], targets: &[Target]) -> Vec<f64> {
    samples
        .iter()
        .map(|(id, v)| {
            let error = |k: usize, (t, p): &(f64, [f64; 2])| {
                let q = targets[k].at(*t);
                (p[0] - q[0]).hypot(p[1] - q[1])
            };
            let k = (0..targets.len())
                .min_by(|&a, &b| error(a, &v[0]).total_cmp(&error(b, &v[0])))
                .unwrap();
            let mut sq = 0.0;
            for s in v {
                let e = error(k, s);
                assert!(
                    s.0 < 75.0 || e < 500.0,
                    "track {id} lost target {k} at t = {}",
                    s.0
                );
                sq += e * e;
            }
            (sq / v.len() as f64).sqrt()
        })
        .collect()
}

#[test]
fn fig5_serial_jpda_confirms_two_tracks_without_swaps() {
    let cfg = fig5_config(false);
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    assert_eq!(tracker.mode(), Mode::Serial);
    let targets = fig5_targets();
    let plots = scene(&cfg.radars, &[0.0, 0.0], &targets, 100.0, &mut Lcg(1));
    let samples = run_by_instants(&mut tracker, &plots);
    let c = tracker.counters();
    assert_eq!((c.confirmed, c.deleted), (2, 0), "{c:?}");
    assert_eq!(samples.len(), 2);
    // Frames: radar 1 at 0, 10, …, 100 (11) and radar 2 at 0, 8, …, 96 (13).
    assert_eq!(c.frames, 24);
    // Confirmed at the third frame with a velocity: r1@0 root, r2@8 pair, r1@10 hit.
    for (_, v) in &samples {
        assert_eq!(v[0].0, 10.0);
    }
    let rmse = follow(&samples, &targets);
    // One plot's position error: √(100² + (43 km · σ_θ)²) ≈ 141 m.
    for r in rmse {
        assert!(r < 100.0, "position RMSE {r} m");
    }
}

#[test]
fn tracks_carry_their_start_time_and_last_measured_plot() {
    // Serial frames: each update is one radar's plot, which the track
    // keeps verbatim (one of the scene's plots, of a radar it names, at
    // its last update time); parallel frames fuse plots, so none is kept.
    let cfg = fig5_config(false);
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    let plots = scene(
        &cfg.radars,
        &[0.0, 0.0],
        &fig5_targets(),
        100.0,
        &mut Lcg(1),
    );
    tracker.process(&plots).unwrap();
    let tracks = tracker.confirmed_tracks();
    assert_eq!(tracks.len(), 2);
    for t in &tracks {
        let p = t.last_plot.expect("serial update keeps its plot");
        assert!(plots.contains(&p), "{p:?} is not one of the scene's plots");
        assert_eq!(t.radars, vec![p.radar]);
        assert_eq!(p.t, t.last_update);
        // Both targets' first plots come from radar 1's scan at t = 0.
        assert_eq!(t.started, Some(0.0));
    }
    let mut cfg = fig5_config(true);
    cfg.set_mode(Mode::Parallel);
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    let plots = scene(
        &cfg.radars,
        &[0.0, 0.0],
        &fig5_targets(),
        100.0,
        &mut Lcg(1),
    );
    tracker.process(&plots).unwrap();
    let fused: Vec<_> = tracker
        .confirmed_tracks()
        .into_iter()
        .filter(|t| t.radars.len() > 1)
        .collect();
    assert!(!fused.is_empty());
    assert!(fused.iter().all(|t| t.last_plot.is_none()));
}

#[test]
fn fig5_every_association_method_keeps_the_two_targets() {
    for method in [
        jpda::Method::Amsjpda,
        jpda::Method::NearestNeighbour,
        jpda::Method::GlobalNearestNeighbour,
    ] {
        let mut cfg = fig5_config(false);
        cfg.association.method = method;
        let mut tracker = Tracker::new(cfg.clone()).unwrap();
        let targets = fig5_targets();
        let plots = scene(&cfg.radars, &[0.0, 0.0], &targets, 100.0, &mut Lcg(2));
        let samples = run_by_instants(&mut tracker, &plots);
        assert_eq!(tracker.counters().confirmed, 2, "{method:?}");
        for r in follow(&samples, &targets) {
            assert!(r < 141.0, "{method:?}: RMSE {r}");
        }
    }
}

#[test]
fn parallel_mode_fuses_doppler_plots_and_tracks_the_fig5_targets() {
    // Both radars every 5 s, radar 2 half a second earlier: fusion instants
    // every 5 s take one plot per radar and target, radar 2's extrapolated
    // by 0.5 s along its line of sight.
    let mut cfg = fig5_config(true);
    cfg.set_mode(Mode::Parallel);
    cfg.radars[0].scan_period = 5.0;
    cfg.radars[1].scan_period = 5.0;
    cfg.fusion_period = 5.0;
    cfg.initiation.max_dt = 10.0;
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    assert_eq!(tracker.mode(), Mode::Parallel);
    let targets = fig5_targets();
    let plots = scene(&cfg.radars, &[5.0, 4.5], &targets, 100.0, &mut Lcg(3));
    let samples = run_by_instants(&mut tracker, &plots);
    let c = tracker.counters();
    assert_eq!((c.confirmed, c.deleted), (2, 0), "{c:?}");
    // Instants 5, 10, …, 100: 20 frames with 2 targets × 2 radars; a pair of
    // plots of one target fuses into one plot unless it fails the 99 % gate
    // (or the crossing targets confuse the GNN), so about 40 fused plots.
    assert_eq!(c.frames, 20);
    assert!((40..=46).contains(&c.fused_plots), "{c:?}");
    for r in follow(&samples, &targets) {
        assert!(r < 100.0, "position RMSE {r} m");
    }
}

#[test]
fn a_3d_tracker_takes_a_2d_and_a_3d_radar() {
    let mut r3 = radar([-200.0, 0.0, 0.0], 10.0, false);
    r3.sigma_elevation = Some(100.0 / 43_000.0);
    let r2 = radar([200.0, 0.0, 0.0], 8.0, false);
    let mut cfg = TrackerConfig::new(3, vec![r3, r2]);
    cfg.sigma_a = [0.05; 3];
    cfg.default_height = 4000.0;
    let targets = fig5_targets().map(|mut t| {
        t.p0[2] = 5000.0;
        t
    });
    let plots = scene(&cfg.radars, &[0.0, 0.0], &targets, 100.0, &mut Lcg(4));
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&plots).unwrap();
    tracker.flush().unwrap();
    assert_eq!(tracker.counters().confirmed, 2);
    for tr in tracker.tracks() {
        assert_eq!(tr.state.len(), 6);
        assert_spd(&tr.covariance);
        // The 3D radar measures the height: σ_z ≈ 43 km · σ_φ = 100 m per plot.
        assert!(
            (tr.state[4] - 5000.0).abs() < 300.0,
            "height {}",
            tr.state[4]
        );
    }
}

#[test]
fn chunks_with_the_state_rebuilt_from_parts_equal_one_call() {
    for doppler in [false, true] {
        let cfg = fig5_config(doppler);
        let targets = fig5_targets();
        let plots = scene(&cfg.radars, &[0.0, 0.0], &targets, 100.0, &mut Lcg(5));
        let mut whole = Tracker::new(cfg.clone()).unwrap();
        whole.process(&plots).unwrap();
        whole.flush().unwrap();
        assert!(whole.counters().confirmed >= 2);

        // Cuts anywhere, also inside a radar's scan group.
        let cuts = [0, 1, 3, 4, 7, 8, 20, 21, 33, plots.len()];
        let mut parts = Tracker::new(cfg.clone()).unwrap().state().to_parts();
        for w in cuts.windows(2) {
            let mut t = Tracker::from_parts(parts).unwrap();
            t.process(&plots[w[0]..w[1]]).unwrap();
            parts = t.state().to_parts();
        }
        let mut chunked = Tracker::from_parts(parts).unwrap();
        chunked.flush().unwrap();
        assert_eq!(chunked, whole, "doppler = {doppler}");
    }
}

#[test]
fn parts_that_no_tracker_could_hold_are_rejected() {
    let cfg = fig5_config(false);
    let plots = scene(&cfg.radars, &[0.0, 0.0], &fig5_targets(), 60.0, &mut Lcg(8));
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&plots).unwrap();
    let good = tracker.state().to_parts();
    assert!(!good.tracks.is_empty() && !good.pending.is_empty());
    assert_eq!(Tracker::from_parts(good.clone()).unwrap(), tracker);
    type Mutation = (&'static str, fn(&mut TrackerParts));
    let mutations: [Mutation; 8] = [
        ("short state", |p| {
            p.tracks[0].x = nalgebra::DVector::zeros(3);
        }),
        ("not positive definite", |p| p.tracks[0].p[(0, 0)] = -1.0),
        ("not finite", |p| p.tracks[0].x[1] = f64::NAN),
        // 2 radars and 3 kinds of report: sensors 0 to 4.
        ("sensor index", |p| p.tracks[0].radars = vec![5]),
        ("id at the next id", |p| p.next_id = p.tracks[0].id),
        ("pending plot", |p| p.pending[0].range = -1.0),
        ("pending order", |p| {
            let mut late = p.pending[0];
            late.t -= 10.0;
            p.pending.push(late);
        }),
        ("configuration", |p| p.config.axes = 4),
    ];
    for (what, mutate) in mutations {
        let mut p = good.clone();
        mutate(&mut p);
        assert!(Tracker::from_parts(p).is_err(), "{what}");
    }
}

#[test]
fn a_late_plot_is_counted_and_dropped() {
    let cfg = fig5_config(false);
    let plots = scene(&cfg.radars, &[0.0, 0.0], &fig5_targets(), 40.0, &mut Lcg(6));
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&plots).unwrap();
    let before = tracker.clone();
    // Frames up to radar 1's group at t = 40 are processed; radar 2's group
    // at t = 40 is pending (no later plot has closed it).
    assert_eq!(tracker.last_time(), Some(40.0));
    assert_eq!(tracker.pending(), 2);
    let mut late = plots[0];
    late.t = 39.0;
    let on_time = *plots.last().unwrap();
    assert_eq!((on_time.radar, on_time.t), (1, 40.0));
    let report = tracker.process(&[on_time, late]).unwrap();
    assert_eq!(report.late, vec![1]);
    assert_eq!(tracker.counters().late, 1);
    assert_eq!(tracker.counters().plots, before.counters().plots + 1);
    assert_eq!(tracker.tracks(), before.tracks());
    // Parallel mode: a plot of an already processed fusion instant is late.
    let mut cfg = fig5_config(true);
    cfg.set_mode(Mode::Parallel);
    let plots = scene(&cfg.radars, &[0.0, 0.0], &fig5_targets(), 40.0, &mut Lcg(7));
    let mut tracker = Tracker::new(cfg).unwrap();
    tracker.process(&plots).unwrap();
    let instant = tracker.last_time().unwrap();
    let report = tracker
        .process(&[Plot {
            t: instant,
            ..plots[0]
        }])
        .unwrap();
    assert_eq!(report.late, vec![0]);
}

#[test]
fn bad_input_is_an_error_without_a_state_change() {
    let cfg = fig5_config(false);
    let mut tracker = Tracker::new(cfg.clone()).unwrap();
    let good = Plot {
        radar: 0,
        t: 0.0,
        range: 40_000.0,
        azimuth: 0.5,
        elevation: None,
        radial_velocity: None,
        identity: Default::default(),
        report: None,
    };
    let bad = [
        Plot { radar: 2, ..good },
        Plot { range: 0.0, ..good },
        Plot {
            t: f64::NAN,
            ..good
        },
        Plot {
            elevation: Some(0.1),
            ..good
        },
    ];
    for b in bad {
        assert!(tracker.process(&[good, b]).is_err());
        assert_eq!(tracker.pending(), 0);
    }
    // Parallel mode needs the radial velocity.
    let mut parallel_cfg = fig5_config(true);
    parallel_cfg.set_mode(Mode::Parallel);
    let mut parallel = Tracker::new(parallel_cfg).unwrap();
    assert!(parallel.process(&[good]).is_err());
    // Invalid configurations.
    let mut c = cfg.clone();
    c.axes = 4;
    assert!(Tracker::new(c).is_err());
    let mut c = cfg.clone();
    c.mode = Mode::Parallel;
    assert!(Tracker::new(c).is_err());
    let mut c = cfg.clone();
    c.initiation.confirm_m = 5;
    assert!(Tracker::new(c).is_err());
    let mut c = cfg;
    c.radars[0].sigma_elevation = Some(0.01);
    assert!(Tracker::new(c).is_err(), "a 3D radar in a 2D tracker");
}

/// East at 150 m/s from (−20, 30) km for 100 s, a left standard-rate turn
/// (3 °/s, ω = π/60 rad/s) for 60 s (half a circle of radius
/// 150/ω ≈ 2865 m), then west: position at time t in closed form.
fn turning_target(t: f64) -> [f64; 3] {
    let (v, w) = (150.0, std::f64::consts::PI / 60.0);
    let (x0, y0) = (-20_000.0, 30_000.0);
    if t <= 100.0 {
        return [x0 + v * t, y0, 0.0];
    }
    let radius = v / w;
    let (xa, ya) = (x0 + v * 100.0, y0);
    if t <= 160.0 {
        let a = w * (t - 100.0);
        // Centre at (xa, ya + R); heading east turning left (north).
        return [xa + radius * a.sin(), ya + radius * (1.0 - a.cos()), 0.0];
    }
    [xa - v * (t - 160.0), ya + 2.0 * radius, 0.0]
}

fn turning_plots(radars: &[RadarSpec], duration: f64, rng: &mut Lcg) -> Vec<Plot> {
    let mut plots = Vec::new();
    for (i, r) in radars.iter().enumerate() {
        let mut t = 0.7 * i as f64;
        while t <= duration {
            let p = turning_target(t);
            let rel = [p[0] - r.site[0], p[1] - r.site[1]];
            plots.push(Plot {
                radar: i,
                t,
                range: rel[0].hypot(rel[1]) + r.sigma_range * rng.normal(),
                azimuth: rel[0].atan2(rel[1]) + r.sigma_azimuth * rng.normal(),
                elevation: None,
                radial_velocity: None,
                identity: Default::default(),
                report: None,
            });
            t += r.scan_period;
        }
    }
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    plots
}

/// Per segment (straight before the turn, in the turn), the RMS position
/// error of the confirmed track at its own time, and the largest
/// probability of the left-turn model (index 1 of `Imm::aircraft`) seen
/// in the turn.
fn run_turn(motion: Motion, seed: u64) -> ([f64; 2], f64) {
    let mut radars = vec![
        radar([-10_000.0, 0.0, 0.0], 4.0, false),
        radar([10_000.0, 0.0, 0.0], 5.0, false),
    ];
    for r in &mut radars {
        r.sigma_range = 50.0;
        r.sigma_azimuth = 0.1_f64.to_radians();
    }
    let mut cfg = TrackerConfig::new(2, radars);
    cfg.motion = motion;
    cfg.sigma_a = [0.5; 3];
    let plots = turning_plots(&cfg.radars, 220.0, &mut Lcg(seed));
    let mut tracker = Tracker::new(cfg).unwrap();
    let (mut sums, mut counts, mut left) = ([0.0; 2], [0usize; 2], 0.0f64);
    let mut start = 0;
    while start < plots.len() {
        let end = start + 1;
        tracker.process(&plots[start..end]).unwrap();
        start = end;
        for tr in tracker.confirmed_tracks() {
            let truth = turning_target(tr.t);
            let e2 = (tr.state[0] - truth[0]).powi(2) + (tr.state[2] - truth[1]).powi(2);
            let seg = if (40.0..100.0).contains(&tr.t) {
                0
            } else if (110.0..160.0).contains(&tr.t) {
                if let Some(&p) = tr.modes.get(1) {
                    left = left.max(p);
                }
                1
            } else {
                continue;
            };
            sums[seg] += e2;
            counts[seg] += 1;
        }
    }
    assert!(counts.iter().all(|&c| c > 10), "{counts:?}");
    ([0, 1].map(|s| (sums[s] / counts[s] as f64).sqrt()), left)
}

/// The IMM holds a standard-rate turn that a low-noise constant-velocity
/// filter cannot, with its left-turn model taking over, and loses little
/// on the straight leg (the reason it is the default; seed-001 Monte
/// Carlo and the real-traffic check measure it properly). Seeds 1–5 gave
/// a turn RMSE of 68 m (default IMM) against 350 m (CV √q = 0.5) and 40 m
/// against 35 m on the straight leg.
#[test]
fn the_imm_follows_a_turn_that_low_noise_cv_cannot() {
    let (mut cv, mut imm) = ([0.0; 2], [0.0; 2]);
    for seed in 1..=5 {
        let (e_cv, _) = run_turn(Motion::ConstantVelocity, seed);
        let (e_imm, left) = run_turn(Motion::Imm(Imm::aircraft()), seed);
        assert!(left > 0.5, "left-turn model {left} (seed {seed})");
        for s in 0..2 {
            cv[s] += e_cv[s] / 5.0;
            imm[s] += e_imm[s] / 5.0;
        }
    }
    assert!(
        imm[1] < 0.7 * cv[1],
        "turn: IMM {} m, CV {} m",
        imm[1],
        cv[1]
    );
    assert!(
        imm[0] < 1.3 * cv[0],
        "straight: IMM {} m, CV {} m",
        imm[0],
        cv[0]
    );
}

/// Serial mode associates and updates with the range rate of Doppler
/// radars: on the same plots, the error of the tracks' radial velocity
/// (what ṙ measures) after 60 s is clearly smaller than with the radial
/// velocities removed (before, serial mode gave the same result with and
/// without them). Seeds 1–4 gave 0.71 m/s against 3.68 m/s with the
/// default IMM (0.28 against 0.96 with one CV model of √q = 0.05). Using ṙ
/// in the update but not in the association made it worse (3.5 m/s for
/// CV): at the crossing a plot of the other target, 41 m/s apart in
/// radial speed, pulled the velocity.
#[test]
fn serial_mode_uses_the_range_rate() {
    let mut cfg = fig5_config(true);
    cfg.set_mode(Mode::Serial);
    let targets = fig5_targets();
    let (mut with, mut without) = (0.0, 0.0);
    for seed in 1..=4 {
        let plots = scene(&cfg.radars, &[0.0, 3.0], &targets, 120.0, &mut Lcg(seed));
        let stripped: Vec<Plot> = plots
            .iter()
            .map(|p| Plot {
                radial_velocity: None,
                ..*p
            })
            .collect();
        for (plots, sum) in [(&plots, &mut with), (&stripped, &mut without)] {
            let mut tracker = Tracker::new(cfg.clone()).unwrap();
            let (mut e2, mut n) = (0.0, 0usize);
            for chunk in plots.chunks(2) {
                tracker.process(chunk).unwrap();
                for tr in tracker.confirmed_tracks().iter().filter(|tr| tr.t >= 60.0) {
                    // The nearest target's velocity.
                    let v = targets
                        .iter()
                        .min_by(|a, b| {
                            let d = |g: &Target| {
                                let p = g.at(tr.t);
                                (p[0] - tr.state[0]).hypot(p[1] - tr.state[2])
                            };
                            d(a).total_cmp(&d(b))
                        })
                        .unwrap()
                        .v;
                    // Its radial component as the radars (both near the
                    // origin) see it: what the range rate measures.
                    let (east, north) = (tr.state[0], tr.state[2]);
                    let u = [east / east.hypot(north), north / east.hypot(north)];
                    e2 += ((tr.state[1] - v[0]) * u[0] + (tr.state[3] - v[1]) * u[1]).powi(2);
                    n += 1;
                }
            }
            assert!(n > 20);
            *sum += (e2 / n as f64).sqrt() / 4.0;
        }
    }
    assert!(
        with < 0.8 * without,
        "velocity RMSE {with} with ṙ, {without} without"
    );
}

/// Plots timed when a clockwise beam crosses each target (a real radar's
/// scan: each plot its own frame with `time_tolerance` 0) are tracked like
/// whole scans: every target confirmed and held, no track deleted, because
/// a frame only counts a miss for the tracks its beam swept (`sweep`).
/// Before, every plot was a miss for every other track: tracks were
/// deleted after 2 × radars plots and the real-traffic check held none.
/// Beams turning either way.
#[test]
fn beam_timed_plots_are_tracked_like_whole_scans() {
    let mut cfg = fig5_config(false);
    cfg.radars[0].scan_period = 4.0;
    cfg.radars[1].scan_period = 5.0;
    cfg.initiation.max_dt = 10.0;
    cfg.deletion = cfg.default_deletion();
    let targets = [
        Target {
            p0: [-25_000.0, 35_000.0, 0.0],
            v: [30.0, -50.0, 0.0],
        },
        Target {
            p0: [20_000.0, 30_000.0, 0.0],
            v: [-40.0, 10.0, 0.0],
        },
        Target {
            p0: [10_000.0, -30_000.0, 0.0],
            v: [50.0, 20.0, 0.0],
        },
        Target {
            p0: [-30_000.0, -20_000.0, 0.0],
            v: [0.0, 60.0, 0.0],
        },
    ];
    for anticlockwise in [false, true] {
        let plots = beam_timed(&cfg.radars, &targets, 200.0, anticlockwise, &[1.0; 2], 11);
        let mut tracker = Tracker::new(cfg.clone()).unwrap();
        let report = tracker.process(&plots).unwrap();
        assert!(
            report.deleted.is_empty(),
            "{} deleted",
            report.deleted.len()
        );
        let c = tracker.counters();
        assert!(
            c.frames as usize > plots.len() / 2,
            "beam-timed frames: {c:?}"
        );
        assert_eq!(tracker.confirmed_tracks().len(), targets.len(), "{c:?}");
        assert_eq!((c.deleted, c.merged), (0, 0), "{c:?}");
        for g in &targets {
            let held = tracker.confirmed_tracks().iter().any(|tr| {
                let p = g.at(tr.t);
                (tr.state[0] - p[0]).hypot(tr.state[2] - p[1]) < 300.0
            });
            assert!(held);
        }
    }
}

/// Twelve aircraft at 150–240 m/s on headings 30° apart, 8 km apart,
/// crossing a 60 × 80 km area in `duration` s.
pub(super) fn twelve_crossing(duration: f64) -> Vec<Target> {
    (0..12)
        .map(|i| {
            let h = (30.0 * i as f64).to_radians();
            let speed = 150.0 + 7.5 * i as f64;
            let v = [speed * h.sin(), speed * h.cos(), 0.0];
            let p0 = [
                -0.5 * v[0] * duration + 8_000.0 * (i % 4) as f64,
                -0.5 * v[1] * duration + 20_000.0 - 8_000.0 * (i / 4) as f64,
                0.0,
            ];
            Target { p0, v }
        })
        .collect()
}

/// 2D plots of `radars` (radar i's scans starting at 0.3 i s) of
/// `targets` until `duration`, each timed when the beam (clockwise, or
/// not) crosses it and detected with probability `detection[i]`, with
/// Gaussian polar noise; in time order.
pub(super) fn beam_timed(
    radars: &[RadarSpec],
    targets: &[Target],
    duration: f64,
    anticlockwise: bool,
    detection: &[f64],
    seed: u64,
) -> Vec<Plot> {
    let mut rng = Lcg(seed);
    let mut plots = Vec::new();
    for (i, r) in radars.iter().enumerate() {
        let mut start = 0.3 * i as f64;
        while start < duration {
            for g in targets {
                // The beam crosses azimuth θ at start + period · θ/2π.
                let p0 = g.at(start);
                let az0 = (p0[0] - r.site[0]).atan2(p0[1] - r.site[1]).rem_euclid(TAU);
                let turned = if anticlockwise { TAU - az0 } else { az0 };
                let t = start + r.scan_period * turned / TAU;
                let p = g.at(t);
                let rel = [p[0] - r.site[0], p[1] - r.site[1]];
                let (range, azimuth) = (rel[0].hypot(rel[1]), rel[0].atan2(rel[1]));
                let noise = [rng.normal(), rng.normal()];
                if rng.uniform() >= detection[i] {
                    continue;
                }
                plots.push(Plot {
                    radar: i,
                    t,
                    range: range + r.sigma_range * noise[0],
                    azimuth: azimuth + r.sigma_azimuth * noise[1],
                    elevation: None,
                    radial_velocity: None,
                    identity: Default::default(),
                    report: None,
                });
            }
            start += r.scan_period;
        }
    }
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    plots
}

/// Each radar's detection probability is learnt from the scans between
/// its hits of the confirmed tracks: three radars that detect 60 %, 80 %
/// and 97 % of the time (beam-timed plots), all declared at 0.9, over
/// twelve aircraft for 600 s. Each estimate lies within 3σ of its truth
/// (σ from the binomial, √(0.6 · 0.4 / 1,300) ≈ 0.014 at 0.6 from
/// ≈ 1,300 decayed trials) and, 0.3, 0.1 and 0.07 from the declared value,
/// beyond 4σ, is converged and applied; the same scene with every radar
/// declared right gives estimates at the truth too.
#[test]
fn each_radars_detection_probability_is_learnt_from_its_hits() {
    let sites = [
        [-30_000.0, 0.0, 0.0],
        [30_000.0, 0.0, 0.0],
        [0.0, 40_000.0, 0.0],
    ];
    let truth = [0.6, 0.8, 0.97];
    let radars: Vec<RadarSpec> = (0..3)
        .map(|k| RadarSpec {
            site: sites[k],
            sigma_range: 60.0,
            sigma_azimuth: 0.1_f64.to_radians(),
            sigma_elevation: None,
            sigma_radial_velocity: None,
            scan_period: [4.0, 4.5, 5.0][k],
            detection_probability: 0.9,
            clutter_density: 1e-9,
        })
        .collect();
    let targets = twelve_crossing(600.0);
    let plots = beam_timed(&radars, &targets, 600.0, false, &truth, 53);
    for declared_right in [false, true] {
        let mut cfg = TrackerConfig::new(2, radars.clone());
        cfg.registration.enabled = false;
        cfg.initiation.max_dt = 12.0;
        cfg.deletion = cfg.default_deletion();
        if declared_right {
            for (r, p) in cfg.radars.iter_mut().zip(truth) {
                r.detection_probability = p;
            }
        }
        let mut tracker = Tracker::new(cfg).unwrap();
        tracker.process(&plots).unwrap();
        for (k, a) in tracker.accuracy().iter().enumerate() {
            let d = a.detection_probability;
            eprintln!("radar {k}: {d:?}");
            assert!(d.samples > 500.0, "radar {k}: {d:?}");
            assert!(
                (d.estimate - truth[k]).abs() < 3.0 * d.sigma,
                "radar {k}: {d:?}"
            );
            if !declared_right {
                assert!(d.converged && d.applied == d.estimate, "radar {k}: {d:?}");
            }
        }
        assert_eq!(tracker.confirmed_count(), targets.len());
    }
}

/// The fig. 5 scene's plots with an arrival time each: t plus a delay in
/// [0, 4] s, and `held` of them held up 5–10 s more (always the middle
/// plot, so that every draw has a plot arriving after later ones); sorted
/// by arrival.
fn delayed(plots: &[Plot], held: f64, rng: &mut Lcg) -> Vec<(f64, Plot)> {
    let middle = plots.len() / 2;
    let mut arrivals: Vec<(f64, Plot)> = plots
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut d = 4.0 * rng.uniform();
            if rng.uniform() < held || i == middle {
                d += 5.0 + 5.0 * rng.uniform();
            }
            (p.t + d, *p)
        })
        .collect();
    arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
    arrivals
}

/// The fig. 5 scene (phases 0 and 3 s, 100 s) in time order, each plot at
/// its own time as the beam times them (a scan's two targets 10 ms apart).
fn beam_timed_scene(cfg: &TrackerConfig, seed: u64) -> Vec<Plot> {
    let mut plots = scene(
        &cfg.radars,
        &[0.0, 3.0],
        &fig5_targets(),
        100.0,
        &mut Lcg(seed),
    );
    plots.sort_by(|a, b| a.t.total_cmp(&b.t));
    for (i, p) in plots.iter_mut().enumerate() {
        p.t += 0.01 * i as f64;
    }
    plots
}

/// One tracker given `plots` in that order, flushed.
fn batch_picture(cfg: &TrackerConfig, plots: &[Plot]) -> Tracker {
    let mut t = Tracker::new(cfg.clone()).unwrap();
    t.process(plots).unwrap();
    t.flush().unwrap();
    t
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(12))]

    /// Plots up to 14 s late, pushed in 1-s batches of arrival: after every
    /// batch the picture is bit for bit one tracker's given every plot
    /// received so far (in arrival order) and flushed, in serial and in
    /// parallel mode, also with the window rebuilt from its stored parts
    /// (no snapshots) between batches.
    #[test]
    fn arrival_order_within_the_lag_does_not_matter(seed in 0u64..1_000_000, rebuild in 0u64..3) {
        // Reprocessing, and the default (auto: this scene's replays are
        // within its bound).
        for (doppler, policy) in [
            (false, LatePolicy::Reprocess),
            (true, LatePolicy::Reprocess),
            (false, LatePolicy::default()),
        ] {
            let mut cfg = fig5_config(doppler);
            if doppler {
                cfg.set_mode(Mode::Parallel);
            }
            let mut rng = Lcg(seed);
            let plots = scene(&cfg.radars, &[0.0, 3.0], &fig5_targets(), 100.0, &mut rng);
            let mut arrivals = delayed(&plots, 0.1, &mut rng);
            // The middle plot held 13.5 s (within the 15-s lag): the next
            // scan's plots (at most 8 s later, each at most 4 s delayed)
            // arrive a second or more before it, so some batch carries a
            // late plot whatever the draw (a draw that held it 5 s once
            // left none: seed 351122).
            let middle = plots[plots.len() / 2];
            for a in arrivals.iter_mut().filter(|a| a.1 == middle) {
                a.0 = middle.t + 13.5;
            }
            arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut window =
                LagWindow::with_policy(
                    Tracker::new(cfg.clone()).unwrap(),
                    window::DEFAULT_MAX_LAG_S,
                    policy,
                )
                .unwrap();
            let mut received: Vec<Plot> = Vec::new();
            let mut corrected = 0;
            for batch in batches_of_arrival(&arrivals) {
                let push = window.push(&batch).unwrap();
                proptest::prop_assert!(push.late.is_empty());
                corrected += usize::from(push.within_lag > 0);
                received.extend(batch);
                proptest::prop_assert_eq!(window.picture(), &batch_picture(&cfg, &received));
                if rebuild > 0 && received.len() % (rebuild as usize + 1) == 0 {
                    window = LagWindow::from_parts(window.to_parts()).unwrap();
                }
            }
            proptest::prop_assert!(corrected > 0, "no batch carried a late plot");
            proptest::prop_assert_eq!(window.counters().plots as usize, plots.len());
            proptest::prop_assert!(window.counters().confirmed >= 2);
        }
    }
}

/// A live feed whose every push holds one plot older than the previous
/// push's newest (several radars' datagrams overlapping) replays a few
/// plots a push, not the stream: the window keeps a snapshot
/// `RECENT_SNAPSHOT_S` (0.5 s) before each push's newest plot. Pushes:
/// {p1}, {p0, p3}, {p2, p5}, … (p sorted by time). Without that snapshot
/// each push dropped the previous push's own snapshot and replayed from
/// the oldest one left, or `base`.
#[test]
fn a_feed_late_by_one_plot_replays_a_few_plots_a_push() {
    let cfg = fig5_config(false);
    let plots = beam_timed_scene(&cfg, 5);
    assert!(plots.len() > 30);
    let mut window = LagWindow::with_policy(
        Tracker::new(cfg.clone()).unwrap(),
        window::DEFAULT_MAX_LAG_S,
        LatePolicy::Reprocess,
    )
    .unwrap();
    let mut received = vec![plots[1]];
    window.push(&[plots[1]]).unwrap();
    let mut most = 0;
    let mut k = 1;
    while 2 * k + 1 < plots.len() {
        let batch = [plots[2 * k - 2], plots[2 * k + 1]];
        let push = window.push(&batch).unwrap();
        most = most.max(push.replayed);
        received.extend(batch);
        k += 1;
    }
    // A replay starts at the recent snapshot: here one plot a push
    // (without it, 13: from whatever older snapshot or base survived,
    // growing with the lag).
    assert!(most <= 3, "{most} plots replayed in one push");
    assert_eq!(window.picture(), &batch_picture(&cfg, &received));
}

#[test]
fn a_plot_older_than_the_lag_is_late_and_changes_nothing() {
    for policy in [LatePolicy::Retrodict, LatePolicy::Reprocess] {
        a_plot_older_than_the_lag_is_late_under(policy);
    }
}

fn a_plot_older_than_the_lag_is_late_under(policy: LatePolicy) {
    let cfg = fig5_config(false);
    let plots = scene(&cfg.radars, &[0.0, 0.0], &fig5_targets(), 60.0, &mut Lcg(3));
    let mut window =
        LagWindow::with_policy(Tracker::new(cfg.clone()).unwrap(), 10.0, policy).unwrap();
    let (early, rest): (Vec<Plot>, Vec<Plot>) = plots.iter().partition(|p| p.t < 20.0);
    window.push(&rest).unwrap();
    // The newest plot is at 60 s (radar 0 scans every 10 s): the horizon
    // is 50 s, and every plot before 20 s is late beyond the lag.
    assert_eq!(window.horizon(), Some(60.0 - 10.0));
    let before = window.picture().clone();
    let push = window.push(&early).unwrap();
    assert_eq!(push.late, (0..early.len()).collect::<Vec<_>>());
    assert_eq!(window.counters().late as usize, early.len());
    assert_eq!(window.picture(), &before);
    assert_eq!(push.frames, 0);
}

#[test]
fn the_window_holds_the_lag_not_the_history() {
    let cfg = fig5_config(false);
    let plots = scene(
        &cfg.radars,
        &[0.0, 0.0],
        &fig5_targets(),
        400.0,
        &mut Lcg(4),
    );
    let mut window = LagWindow::with_policy(
        Tracker::new(cfg.clone()).unwrap(),
        15.0,
        LatePolicy::Reprocess,
    )
    .unwrap();
    for chunk in plots.chunks(3) {
        window.push(chunk).unwrap();
        let newest = chunk[chunk.len() - 1].t;
        let oldest = window.state().window[0].t;
        // Snapshots are adopted as base as soon as they are older than the
        // horizon: the window spans the lag plus one push (here ≤ 10 s).
        assert!(newest - oldest <= 15.0 + 10.0, "{oldest} .. {newest}");
    }
    assert_eq!(window.picture(), &batch_picture(&cfg, &plots));
}

/// A tracker bounded in tracks starts none beyond the bound and counts
/// the starts it refused; unbounded, the same plots give two tracks.
#[test]
fn a_tracker_at_its_bound_of_tracks_starts_no_more() {
    let cfg = fig5_config(false);
    let plots = scene(
        &cfg.radars,
        &[0.0, 3.0],
        &fig5_targets(),
        100.0,
        &mut Lcg(8),
    );
    let mut bounded = Tracker::new(cfg.clone()).unwrap();
    bounded.set_max_tracks(Some(1));
    let mut refused = 0;
    for chunk in plots.chunks(4) {
        refused += bounded.process(chunk).unwrap().refused;
        assert!(bounded.tracks().len() <= 1);
    }
    refused += bounded.flush().unwrap().refused;
    assert!(refused > 0);
    assert_eq!(bounded.confirmed_tracks().len(), 1);
    assert_eq!(batch_picture(&cfg, &plots).confirmed_tracks().len(), 2);
}

/// A window bounded in plots holds at most that many: the oldest go into
/// `base` early and the horizon moves up with them, so a plot older than
/// it is late although within the lag. Plots in time order lose nothing
/// (`base` takes them in order: the picture is one tracker's).
#[test]
fn a_window_holds_at_most_its_bound_of_plots() {
    let cfg = fig5_config(false);
    let plots = beam_timed_scene(&cfg, 6);
    let mut window = LagWindow::with_policy(
        Tracker::new(cfg.clone()).unwrap(),
        60.0,
        LatePolicy::Reprocess,
    )
    .unwrap();
    window.set_max_plots(8);
    let mut bounded = None;
    for chunk in plots.chunks(3) {
        let push = window.push(chunk).unwrap();
        assert!(window.window_len() <= 8, "{}", window.window_len());
        bounded = push.bounded_horizon.or(bounded);
    }
    let h = bounded.expect("the bound acted");
    assert!(window.horizon() >= Some(h));
    // 100 s of plots, a 60-s lag: without the bound the horizon would be
    // near 40 s; with it, it is the time of the 8th newest plot.
    assert!(h > 60.0, "{h}");
    assert_eq!(window.picture(), &batch_picture(&cfg, &plots));
    let older = *plots.iter().rev().find(|p| p.t < h).unwrap();
    let push = window.push(&[older]).unwrap();
    assert_eq!(push.late, vec![0]);
}

#[test]
fn a_lag_must_be_finite_and_at_most_the_limit() {
    for bad in [-1.0, f64::NAN, f64::INFINITY, window::MAX_LAG_LIMIT_S + 1.0] {
        let t = Tracker::new(fig5_config(false)).unwrap();
        let e = LagWindow::new(t, bad).unwrap_err();
        assert!(e.to_string().contains("max_lag_s"), "{e}");
    }
    assert!(LagWindow::new(Tracker::new(fig5_config(false)).unwrap(), 0.0).is_ok());
}

/// A dense picture: 400 targets seen by two radars. Once confirmed, every
/// frame hits about 400 tracks whose previous plot was the other radar's,
/// but registration learns from at most `MAX_PAIRS_PER_FRAME` of them (the
/// decayed pair count of a radar grows by at most that much a frame, plus
/// the decay's rounding), and from more than half of that bound (so the
/// bound, not a lack of pairs, is what limits).
#[test]
fn a_dense_frame_learns_from_at_most_the_bound_of_pairs() {
    let radars = vec![
        radar([-20_000.0, 0.0, 0.0], 4.0, false),
        radar([20_000.0, 0.0, 0.0], 5.0, false),
    ];
    let targets: Vec<Target> = (0..400)
        .map(|k| Target {
            p0: [
                -40_000.0 + 4_000.0 * (k % 20) as f64,
                20_000.0 + 4_000.0 * (k / 20) as f64,
                0.0,
            ],
            v: [150.0, 0.0, 0.0],
        })
        .collect();
    let plots = scene(&radars, &[0.0, 1.0], &targets, 60.0, &mut Lcg(7));
    let mut tracker = Tracker::new(TrackerConfig::new(2, radars)).unwrap();
    let mut previous = 0.0;
    let mut largest_step: f64 = 0.0;
    tracker
        .process_with(&plots, true, &mut |tr: &Tracker| {
            let pairs = tr.biases()[0].pairs;
            largest_step = largest_step.max(pairs - previous);
            previous = pairs;
            std::ops::ControlFlow::Continue(())
        })
        .unwrap();
    let bound = registration::MAX_PAIRS_PER_FRAME as f64;
    assert!(
        tracker.counters().confirmed >= 390,
        "{:?}",
        tracker.counters()
    );
    assert!(largest_step <= bound + 1e-6, "{largest_step}");
    assert!(largest_step > 0.5 * bound, "{largest_step}");
}

/// The largest distance between the confirmed tracks of `a` and those of
/// `b` (each of `b`'s matched to the nearest of `a`'s, one to one), in
/// metres and in units of `b`'s horizontal σ √(P_xx + P_yy); or why they
/// do not match.
fn largest_gap(a: &Tracker, b: &Tracker) -> Result<(f64, f64), String> {
    let (ta, tb) = (a.confirmed_tracks(), b.confirmed_tracks());
    if ta.len() != tb.len() {
        return Err(format!("{} tracks vs {}", ta.len(), tb.len()));
    }
    let mut taken = vec![false; ta.len()];
    let (mut metres, mut sigmas): (f64, f64) = (0.0, 0.0);
    for y in &tb {
        let (i, d) = ta
            .iter()
            .enumerate()
            .filter(|(i, _)| !taken[*i])
            .map(|(i, x)| (i, (x.state[0] - y.state[0]).hypot(x.state[2] - y.state[2])))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("as many tracks");
        taken[i] = true;
        let sigma = (y.covariance[(0, 0)] + y.covariance[(2, 2)]).sqrt();
        metres = metres.max(d);
        sigmas = sigmas.max(d / sigma);
    }
    Ok((metres, sigmas))
}

/// Retrodiction on the beam-timed fig. 5 scene (two targets that cross at
/// about 60 s): radar 1's link 2 s slower than radar 0's, each plot a
/// further 0–0.3 s, and 3 % of the plots (at least the middle one) held
/// 5–10 s, pushed in 1-s batches of arrival. Nothing is replayed; the
/// flushed picture has as many tracks as one call over every plot in time
/// order, with at most one more track confirmed (and deleted) over the run.
/// Over seeds 0–23 (fixed, so that the bounds are a statement about them)
/// with and without the IMM, the largest distance of a final track from
/// the batch call's, in that track's σ: median 0.25 σ at most, worst 2 σ
/// at most (1.3 σ, 146 m, seen: a track started again after the
/// crossing). The 5 m is measured on its scenes
/// (docs/RESULTS.md), where the default replays.
#[test]
fn retrodiction_gives_the_batch_picture_within_its_tolerance() {
    let mut sigmas = Vec::new();
    for seed in 0..24 {
        retrodiction_gap(seed, &mut sigmas).unwrap();
    }
    sigmas.sort_by(f64::total_cmp);
    let median = sigmas[sigmas.len() / 2];
    let worst = sigmas[sigmas.len() - 1];
    assert!(
        median <= 0.25 && worst <= 2.0,
        "median {median} σ, worst {worst} σ: {sigmas:?}"
    );
}

fn retrodiction_gap(
    seed: u64,
    out: &mut Vec<f64>,
) -> Result<(), proptest::test_runner::TestCaseError> {
    for imm in [true, false] {
        let mut cfg = fig5_config(false);
        if !imm {
            cfg.motion = Motion::ConstantVelocity;
        }
        let mut rng = Lcg(seed);
        let plots = beam_timed_scene(&cfg, seed);
        let arrivals = delayed_by_radar(&plots, &[0.0, 2.0], 0.03, &mut rng);
        let mut window = LagWindow::with_policy(
            Tracker::new(cfg.clone()).unwrap(),
            window::DEFAULT_MAX_LAG_S,
            LatePolicy::Retrodict,
        )
        .unwrap();
        proptest::prop_assert_eq!(window.policy(), LatePolicy::Retrodict);
        let mut late = 0;
        let mut ever = std::collections::BTreeSet::new();
        let mut deleted = 0;
        for batch in batches_of_arrival(&arrivals) {
            let push = window.push(&batch).unwrap();
            proptest::prop_assert!(push.late.is_empty());
            proptest::prop_assert_eq!(push.replayed, 0);
            late += push.within_lag;
            deleted += push.deleted.len();
            ever.extend(window.picture().confirmed_tracks().iter().map(|t| t.id));
        }
        proptest::prop_assert!(late > 0, "no plot was late");
        let mut sorted = plots.clone();
        sorted.sort_by(|a, b| a.t.total_cmp(&b.t));
        let batch = batch_picture(&cfg, &sorted);
        // The same tracks at the end; over the run at most one more
        // track confirmed (and one more deleted) than by the one call:
        // at the crossing the pair may merge and the lost one start
        // again, as the one call itself does with the IMM (plots split
        // over frames by their arrival weigh the pair apart less).
        let c = batch.counters();
        proptest::prop_assert_eq!(window.picture().confirmed_count(), batch.confirmed_count());
        proptest::prop_assert!(ever.len() as u64 <= c.confirmed + 1, "ids {:?}", ever);
        proptest::prop_assert!(deleted as u64 <= c.deleted + c.merged + 1);
        let gap = largest_gap(window.picture(), &batch);
        // The gap, in σ: in this sparse scene (scans of 8 and 10 s, two
        // targets that cross) a held plot is one or two updates old, and
        // a track started again after the crossing has a few updates (σ
        // near 100 m); retrodiction's approximation (module
        // `retrodiction`: the process noise's correlation with the
        // estimate neglected, the IMM's mode history not kept; a scan
        // split over frames associated in pieces) moves such a track most.
        let (_, sigmas) = gap.map_err(proptest::test_runner::TestCaseError::fail)?;
        out.push(sigmas);
    }
    Ok(())
}

/// `arrivals` (in arrival order) cut into 1-s batches of arrival: the
/// plots that arrive in [s − 1, s) for s = 1, 2, … up to the last (empty
/// seconds included).
fn batches_of_arrival(arrivals: &[(f64, Plot)]) -> Vec<Vec<Plot>> {
    let mut out = Vec::new();
    let (mut k, mut second) = (0, 1.0);
    while k < arrivals.len() {
        let batch: Vec<Plot> = arrivals[k..]
            .iter()
            .take_while(|(a, _)| *a < second)
            .map(|(_, p)| *p)
            .collect();
        k += batch.len();
        second += 1.0;
        out.push(batch);
    }
    out
}

/// Arrival times: each radar's link delay, 0–0.3 s more per plot, and a
/// fraction `held` of the plots (and the middle one) 5–10 s later still;
/// in arrival order.
fn delayed_by_radar(plots: &[Plot], links: &[f64], held: f64, rng: &mut Lcg) -> Vec<(f64, Plot)> {
    let middle = plots.len() / 2;
    let mut arrivals: Vec<(f64, Plot)> = plots
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut d = links[p.radar] + 0.3 * rng.uniform();
            if rng.uniform() < held || i == middle {
                d += 5.0 + 5.0 * rng.uniform();
            }
            (p.t + d, *p)
        })
        .collect();
    arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
    arrivals
}

/// Auto with a bound of 1 replayed plot on the retrodiction test's
/// arrivals: pushes whose replay exceeds it retrodict (the head then
/// approximate from the earliest such plot), the others replay while the
/// window is within its bound (once a push leaves it holding more plots
/// than the bound, it keeps none and retrodicts from then on: it does not
/// become exact again; `exact_again` counts the pushes that did before
/// that). After every push a
/// window rebuilt from its stored parts continues like the original
/// (the decisions depend on stored data only), and the end is within
/// the retrodiction test's worst bound (2 σ) of the batch call.
/// Seeds 0–7.
#[test]
fn auto_replays_within_its_bound_and_retrodicts_beyond() {
    for seed in 0..8 {
        auto_run(seed).unwrap();
    }
}

fn auto_run(seed: u64) -> Result<(), proptest::test_runner::TestCaseError> {
    let cfg = fig5_config(false);
    let mut rng = Lcg(seed);
    let plots = beam_timed_scene(&cfg, seed);
    let arrivals = delayed_by_radar(&plots, &[0.0, 2.0], 0.03, &mut rng);
    let policy = LatePolicy::Auto { max_replay: 1 };
    let mut window = LagWindow::with_policy(
        Tracker::new(cfg.clone()).unwrap(),
        window::DEFAULT_MAX_LAG_S,
        policy,
    )
    .unwrap();
    let (mut retrodicted, mut exact_again) = (0, 0);
    for batch in batches_of_arrival(&arrivals) {
        let was = window.approximate_from();
        let mut rebuilt = LagWindow::from_parts(window.to_parts()).unwrap();
        let push = window.push(&batch).unwrap();
        rebuilt.push(&batch).unwrap();
        proptest::prop_assert_eq!(window.picture(), rebuilt.picture());
        proptest::prop_assert_eq!(window.approximate_from(), rebuilt.approximate_from());
        proptest::prop_assert!(push.replayed <= 1 + batch.len());
        retrodicted += push.retrodicted;
        if push.retrodicted > 0 {
            proptest::prop_assert!(window.approximate_from().is_some());
        }
        exact_again += usize::from(was.is_some() && window.approximate_from().is_none());
    }
    proptest::prop_assert!(retrodicted > 0, "nothing was retrodicted");
    let mut sorted = plots.clone();
    sorted.sort_by(|a, b| a.t.total_cmp(&b.t));
    let batch = batch_picture(&cfg, &sorted);
    proptest::prop_assert_eq!(window.picture().confirmed_count(), batch.confirmed_count());
    let gap = largest_gap(window.picture(), &batch);
    proptest::prop_assert!(
        gap.as_ref().is_ok_and(|(m, s)| *m <= 5.0 || *s <= 2.0),
        "{:?} ({} exact again)",
        gap,
        exact_again
    );
    Ok(())
}

/// Two aircraft converge at a shallow angle and cross (B 400 m north of A,
/// closing at 4 m/s: they meet at t = 100 s), a thousand feet apart, under
/// the Fig. 5 radars. With their Mode S replies each track keeps its
/// aircraft: at the end every confirmed track is nearest the aircraft
/// whose address it carries, and its flight level is that aircraft's.
#[test]
fn mode_s_keeps_crossing_aircraft_apart() {
    let targets = [
        Target {
            p0: [-20_000.0, 30_000.0, 0.0],
            v: [100.0, 0.0, 0.0],
        },
        Target {
            p0: [-20_000.0, 30_400.0, 0.0],
            v: [100.0, -4.0, 0.0],
        },
    ];
    let addresses = [0x4CA2D1, 0x3C6586];
    let levels = [300.0, 310.0];
    let cfg = fig5_config(false);
    for seed in 0..8 {
        let mut rng = Lcg(seed);
        let mut plots = scene(&cfg.radars, &[0.0, 3.0], &targets, 200.0, &mut rng);
        // The scene lists a scan's targets in order: tag each plot by the
        // target nearest its true position (the plots alternate A, B).
        for (k, p) in plots.iter_mut().enumerate() {
            let i = k % 2;
            p.identity = Identity {
                address: Some(addresses[i]),
                mode_c: Some(ModeC {
                    flight_level: levels[i],
                    validated: true,
                    garbled: false,
                }),
                detection: Some(Detection::Combined),
                ..Identity::default()
            };
        }
        let mut tracker = Tracker::new(cfg.clone()).unwrap();
        tracker.process(&plots).unwrap();
        tracker.flush().unwrap();
        let confirmed: Vec<TrackOutput> = tracker
            .tracks()
            .into_iter()
            .filter(|t| t.status == TrackStatus::Confirmed)
            .collect();
        assert_eq!(confirmed.len(), 2, "seed {seed}");
        for t in &confirmed {
            let address = t.identity.address.expect("a Mode S track").value;
            let i = addresses.iter().position(|&a| a == address).unwrap();
            let truth = targets[i].at(t.t);
            let other = targets[1 - i].at(t.t);
            let d = |p: [f64; 3]| (t.state[0] - p[0]).hypot(t.state[2] - p[1]);
            assert!(d(truth) < d(other), "seed {seed}: track {} swapped", t.id);
            let fl = t.identity.altitude.unwrap().x[0] / 100.0;
            assert!((fl - levels[i]).abs() < 0.5, "seed {seed}: FL {fl}");
        }
    }
}

/// An overflight: aircraft A flies straight over a 3D radar's site (at
/// t = 40 s, 3 km up; the radar sees nothing overhead, so no plot of A
/// then), B parallel 40 m north of it. At t = 40 s B's plot makes A a
/// candidate (the hypothesiser's pre-test reaches 50 m and more, the gate
/// of these metre-sized sigmas a few metres), and A's predicted position
/// is the site's (noise-free plots: to 10⁻¹³ m), where
/// the radar's azimuth is undefined: the frame must not fail. A gates
/// nothing in that frame (listed in `StepReport::undefined`), coasts, and
/// both aircraft keep their tracks.
#[test]
fn an_overflight_of_a_radar_site_does_not_stop_the_tracker() {
    overflight(
        |cfg| {
            cfg.motion = Motion::ConstantVelocity;
            cfg.sigma_a = [0.05; 3];
        },
        "A was not predicted at the site",
    );
}

/// One address, one aircraft: an aircraft's plots jump 5 km north at
/// t = 100 s (its track cannot follow: it coasts, missing, while a new
/// track confirms on the plots). With a Mode S address on every plot the
/// coasting track, not updated since the new one's first plot, takes the
/// new one's state and goes on under its own id: one confirmed track
/// ever, near the aircraft at the end. Primary plots (no address) give a
/// second track, the first deleted: the restart the rule removes.
#[test]
fn a_track_that_lost_its_mode_s_aircraft_takes_the_new_track_of_its_address() {
    let before = Target {
        p0: [-20_000.0, 30_000.0, 0.0],
        v: [100.0, 0.0, 0.0],
    };
    let after = Target {
        p0: [-20_000.0, 35_000.0, 0.0],
        ..before
    };
    let cfg = fig5_config(false);
    for seed in 0..4 {
        for mode_s in [true, false] {
            let mut rng = Lcg(seed);
            let mut plots: Vec<Plot> = scene(&cfg.radars, &[0.0, 3.0], &[before], 200.0, &mut rng)
                .into_iter()
                .filter(|p| p.t < 100.0)
                .chain(
                    scene(&cfg.radars, &[0.0, 3.0], &[after], 200.0, &mut rng)
                        .into_iter()
                        .filter(|p| p.t >= 100.0),
                )
                .collect();
            plots.sort_by(|a, b| a.t.total_cmp(&b.t));
            if mode_s {
                for p in &mut plots {
                    p.identity = Identity {
                        address: Some(0x4CA2D1),
                        detection: Some(Detection::Combined),
                        ..Identity::default()
                    };
                }
            }
            let mut tracker = Tracker::new(cfg.clone()).unwrap();
            let (early, late): (Vec<Plot>, Vec<Plot>) = plots.iter().partition(|p| p.t < 100.0);
            tracker.process(&early).unwrap();
            let first: Vec<u64> = tracker.confirmed_tracks().iter().map(|t| t.id).collect();
            assert_eq!(first.len(), 1, "seed {seed}");
            tracker.process(&late).unwrap();
            tracker.flush().unwrap();
            let last: Vec<TrackOutput> = tracker
                .tracks()
                .into_iter()
                .filter(|t| t.status == TrackStatus::Confirmed)
                .collect();
            assert_eq!(last.len(), 1, "seed {seed}, Mode S {mode_s}");
            let truth = after.at(last[0].t);
            let d = (last[0].state[0] - truth[0]).hypot(last[0].state[2] - truth[1]);
            assert!(d < 500.0, "seed {seed}: {d} m");
            if mode_s {
                assert_eq!(last[0].id, first[0], "seed {seed}: restarted");
                assert_eq!(tracker.counters().confirmed, 1, "seed {seed}");
            } else {
                assert_ne!(last[0].id, first[0], "seed {seed}");
            }
        }
    }
}

/// The overflight of `an_overflight_of_a_radar_site_does_not_stop_the_tracker`
/// with an IMM tracker of a constant-velocity model (left at a rate of
/// 1/20 s) and a 0.05 rad/s turn (left at 1/10⁹ s, so it hardly mixes into
/// the first): A's constant-velocity model predicts it at the site at
/// t = 40 s (noise-free plots: 1.6·10⁻⁶ m), its turn model some 40 m
/// aside, and the combined prediction the association uses is not at the
/// site, so B's plot, 40 m north, is gated and weighed. The update of A's
/// first model with it is undefined there: before, the frame, and with it
/// the whole call, failed with DegenerateGeometry; now A coasts that frame,
/// listed in `StepReport::undefined`, and both aircraft keep their tracks.
#[test]
fn an_imm_models_own_overflight_coasts_the_track() {
    overflight(
        |cfg| {
            cfg.motion = Motion::Imm(Imm {
                models: vec![
                    MotionModel::ConstantVelocity { sigma_a: [0.05; 3] },
                    MotionModel::CoordinatedTurn {
                        turn_rate: 0.05,
                        sigma_a: [0.05; 3],
                    },
                ],
                mean_sojourn: vec![20.0, 1e9],
                initial_probabilities: vec![0.5, 0.5],
            });
        },
        "no model of A was predicted at the site",
    );
}

/// The scene of the overflight tests: a noise-free 3D radar at the
/// origin (σ of metres), A flying over its site at t = 40 s, 3 km up (no
/// plot of A within 1 m of the vertical: the cone of silence), B
/// parallel 40 m north; `motion` sets the tracker's motion. A must be
/// listed in `undefined` (`why` names what was undefined) and both
/// aircraft keep their tracks.
fn overflight(motion: impl FnOnce(&mut TrackerConfig), why: &str) {
    let radar = RadarSpec {
        site: [0.0; 3],
        sigma_range: 5.0,
        sigma_azimuth: 1e-4,
        sigma_elevation: Some(1e-4),
        sigma_radial_velocity: None,
        scan_period: 4.0,
        detection_probability: 1.0,
        clutter_density: 1e-9,
    };
    let mut cfg = TrackerConfig::new(3, vec![radar.clone()]);
    motion(&mut cfg);
    let targets = [
        Target {
            p0: [-4_000.0, 0.0, 3_000.0],
            v: [100.0, 0.0, 0.0],
        },
        Target {
            p0: [-4_000.0, 40.0, 3_000.0],
            v: [100.0, 0.0, 0.0],
        },
    ];
    let mut plots = Vec::new();
    for k in 0..=20 {
        let t = 4.0 * k as f64;
        for target in &targets {
            let p = target.at(t);
            let horizontal = p[0].hypot(p[1]);
            if horizontal < 1.0 {
                continue; // the cone of silence
            }
            plots.push(Plot {
                radar: 0,
                t,
                range: horizontal.hypot(p[2]),
                azimuth: p[0].atan2(p[1]),
                elevation: Some(p[2].atan2(horizontal)),
                radial_velocity: None,
                identity: Identity::default(),
                report: None,
            });
        }
    }
    let mut tracker = Tracker::new(cfg).unwrap();
    let mut report = tracker.process(&plots).expect("an overflight is no error");
    let flushed = tracker.flush().unwrap();
    report.undefined.extend(flushed.undefined);
    assert!(!report.undefined.is_empty(), "{why}");
    let end = 80.0;
    for target in &targets {
        let p = target.at(end);
        let near = tracker.tracks().iter().any(|t| {
            t.status == TrackStatus::Confirmed
                && (t.state[0] - p[0]).hypot(t.state[2] - p[1]) < 20.0
        });
        assert!(near, "no track within 20 m of {p:?}");
    }
}
