//! `tracker-manoeuvres`: the plot-fusion tracker's accuracy and covariance
//! consistency per kind of flight segment — straight and level, turning,
//! changing speed, climbing or descending — for the default IMM against
//! single constant-velocity filters, on 3D Doppler radars.
//!
//! The scene, per run (all drawn from the run's stream):
//! - three 3D radars on a circle of radius 20 km about the origin at equal
//!   angles (random rotation), σ_ρ ~ U[30, 80] m, σ_θ ~ U[0.1°, 0.25°],
//!   σ_φ ~ U[0.15°, 0.3°], Doppler σ 1 m/s, period ~ U[4, 6] s, first scan
//!   ~ U[0, period) s, P_D = 0.9, coverage 1–200 km all round and 0–45° in
//!   elevation, Poisson clutter of 3 false plots per scan on average;
//! - targets (default 50, `--targets`): born at a time ~ U[0, D/3] at a
//!   position uniform in a 120 km × 120 km square, altitude ~ U[2, 9] km,
//!   speed ~ U[120, 280] m/s, heading uniform. A quarter fly straight and
//!   level throughout; the others alternate straight and level legs
//!   (20–60 s) with a manoeuvre drawn with equal probability from: a
//!   coordinated turn of 2–5 m/s² lateral acceleration (20–60 s, either
//!   side); a speed change of 1–3 m/s² (10–30 s, accelerating or slowing so
//!   that the speed stays in [100, 300] m/s); a climb or descent (a ramp of
//!   0.5–1.5 m/s² vertical acceleration for 5–15 s, a hold of 10–40 s at the
//!   reached vertical speed, and the opposite ramp to level off; descending
//!   above 5.5 km, climbing below);
//! - duration D = 300 s (`--scans` × 5 s).
//!
//! Trackers: the service's defaults (`TrackerConfig::new`: mode `auto`, the
//! IMM of `Imm::aircraft`, range rate in the update), the same with the
//! range rate withheld (plots and radars without Doppler: mode `auto` is
//! then serial), the default in parallel mode, the default IMM with its
//! constant-velocity model's vertical √q at 0.5 as before this experiment,
//! and one constant-velocity model (CWNA) with √q = 3 (the default before
//! the IMM) and √q = 1.
//!
//! Scoring, at every frame a tracker processed: each confirmed track is
//! compared with the truth at the track's own time (`TrackOutput::t`, the
//! time its state holds) and the tracks are assigned to the targets alive at
//! the frame by the optimal assignment of the 3D position distance with a
//! 1 km cut-off ([`algo::assignment::solve`]). An assigned pair falls in the
//! class of the target's segment at the track's time (level for the
//! straight legs and the targets that never manoeuvre). Per class: 3D,
//! horizontal and vertical position RMSE, 3D velocity RMSE, the mean NEES of
//! the 3D position (3 dof) and the share of samples inside the χ²₃ 95 %
//! band and above χ²₃(0.99). ID switches, track breaks, false tracks and
//! time to confirm follow [`crate::scenario001`]'s rules on the same
//! assignment.

use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::time::Instant;

use nalgebra::{DMatrix, DVector};
use rand::RngExt;

use super::{EvalOptions, mean_se};
use crate::metrics::{nees, nees_bounds, rmse};
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario001::{FrameScore, Pair, Summary, radar_spec, scan_plots, summarise};
use crate::sensor::Radar;
use crate::truth::{Leg, Manoeuvre, TargetPlan, Trajectory, simulate, velocity};
use crate::{STANDARD_GRAVITY, SimError, SimRng};
use algo::assignment;
use algo::gating::chi2_threshold;
use algo::tracking::accuracy::{RadarAccuracy, SigmaEstimate};
use algo::tracking::{
    Imm, Mode, Motion, MotionModel, NoiseModel, Plot, RadarSpec, Tracker, TrackerConfig,
};

const RADARS: usize = 3;
const DEFAULT_TARGETS: usize = 50;
const SCAN_UNIT_S: f64 = 5.0;
const DEFAULT_SCANS: usize = 60;
const SITE_RADIUS_M: f64 = 20_000.0;
const MAX_RANGE_M: f64 = 200_000.0;
const FALSE_PLOTS_PER_SCAN: f64 = 3.0;
const BOX_HALF_M: f64 = 60_000.0;
const CUTOFF_M: f64 = 1000.0;
const TRUTH_DT_S: f64 = 0.25;
/// Share of the targets that never manoeuvre.
const STRAIGHT_SHARE: f64 = 0.25;
/// Speed band kept by speed changes (m/s).
const SPEED_BAND: (f64, f64) = (100.0, 300.0);
/// Above this altitude a vertical manoeuvre descends, below it climbs (m).
const MID_ALTITUDE_M: f64 = 5500.0;

/// The kind of flight segment a scored sample falls in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Class {
    Level,
    Turn,
    Speed,
    Climb,
}

const CLASSES: [Class; 4] = [Class::Level, Class::Turn, Class::Speed, Class::Climb];

impl Class {
    fn name(self) -> &'static str {
        match self {
            Class::Level => "straight and level",
            Class::Turn => "turning",
            Class::Speed => "changing speed",
            Class::Climb => "climbing or descending",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

/// A target: its trajectory and its manoeuvre segments `(start, end,
/// class)` in absolute time; time outside them is straight and level.
struct Target {
    truth: Trajectory,
    segments: Vec<(f64, f64, Class)>,
}

impl Target {
    fn class_at(&self, t: f64) -> Class {
        self.segments
            .iter()
            .find(|(a, b, _)| (*a..*b).contains(&t))
            .map_or(Class::Level, |s| s.2)
    }
}

/// The trackers of the table.
#[derive(Debug, Clone, Copy)]
enum Method {
    Default,
    NoRangeRate,
    Parallel,
    Cv3,
    Cv1,
    FormerVertical,
    /// Every radar biased (range ±500 m, azimuth ±0.5°, elevation ±0.2°,
    /// uniform), the defaults (registration on).
    Biased,
    /// The same biased plots, registration off.
    BiasedUnregistered,
    /// The default with the accuracy estimator off (every radar declared
    /// right).
    AccuracyOff,
    /// Every radar declared with its σ (all four) times 0.3, 1 or 3, drawn
    /// per radar; the defaults (accuracy learnt).
    Misdeclared,
    /// The same misdeclared radars, the accuracy estimator off.
    MisdeclaredFixed,
}

const METHODS: [Method; 8] = [
    Method::Default,
    Method::FormerVertical,
    Method::NoRangeRate,
    Method::Parallel,
    Method::Cv3,
    Method::Cv1,
    Method::Biased,
    Method::BiasedUnregistered,
];

/// The methods of the `accuracy` experiment.
const ACCURACY_METHODS: [Method; 4] = [
    Method::Default,
    Method::AccuracyOff,
    Method::Misdeclared,
    Method::MisdeclaredFixed,
];

/// The factors a radar's declared σ are drawn from (`accuracy`).
const MISDECLARED: [f64; 3] = [0.3, 1.0, 3.0];

/// The detection probability a misdeclared radar declares (every radar's
/// is 0.9): a datasheet's 0.99 with its σ × 0.3 (optimistic in both), the
/// truth with × 1, and 0.7 with × 3.
fn misdeclared_detection(factor: f64) -> f64 {
    if factor < 1.0 {
        0.99
    } else if factor > 1.0 {
        0.7
    } else {
        0.9
    }
}

impl Method {
    fn name(self) -> &'static str {
        match self {
            Method::Default => "default (auto, IMM, range rate)",
            Method::NoRangeRate => "default, range rate withheld",
            Method::Parallel => "default in parallel mode",
            Method::Cv3 => "CV √q = 3 (the default before the IMM)",
            Method::Cv1 => "CV √q = 1",
            Method::FormerVertical => "default IMM with its CV model's vertical √q 0.5 (before)",
            Method::Biased => "default, every radar biased (±500 m, ±0.5°, ±0.2° el.), registered",
            Method::BiasedUnregistered => "the same biased plots, registration off",
            Method::AccuracyOff => "default, declared right, accuracy estimator off",
            Method::Misdeclared => "σ declared ×0.3/×1/×3 per radar, accuracy learnt (default)",
            Method::MisdeclaredFixed => "σ declared ×0.3/×1/×3 per radar, accuracy estimator off",
        }
    }

    /// The configuration from the true radars `specs`; `factors`: per
    /// radar, what its declared σ are multiplied by when misdeclared.
    fn config(self, specs: &[RadarSpec], factors: &[f64]) -> TrackerConfig {
        let mut specs = specs.to_vec();
        if matches!(self, Method::NoRangeRate) {
            for s in &mut specs {
                s.sigma_radial_velocity = None;
            }
        }
        if matches!(self, Method::Misdeclared | Method::MisdeclaredFixed) {
            for (s, &f) in specs.iter_mut().zip(factors) {
                s.sigma_range *= f;
                s.sigma_azimuth *= f;
                s.sigma_elevation = s.sigma_elevation.map(|v| v * f);
                s.sigma_radial_velocity = s.sigma_radial_velocity.map(|v| v * f);
                s.detection_probability = misdeclared_detection(f);
            }
        }
        let mut c = TrackerConfig::new(3, specs);
        match self {
            Method::Default | Method::NoRangeRate | Method::Biased | Method::Misdeclared => {}
            Method::AccuracyOff | Method::MisdeclaredFixed => c.accuracy.enabled = false,
            Method::BiasedUnregistered => c.registration.enabled = false,
            Method::Parallel => c.set_mode(Mode::Parallel),
            Method::FormerVertical => {
                let mut imm = Imm::aircraft();
                imm.models[0] = MotionModel::ConstantVelocity { sigma_a: [0.5; 3] };
                c.motion = Motion::Imm(imm);
            }
            Method::Cv3 | Method::Cv1 => {
                c.motion = Motion::ConstantVelocity;
                c.noise = NoiseModel::Cwna;
                let q = if matches!(self, Method::Cv3) {
                    3.0
                } else {
                    1.0
                };
                c.sigma_a = [q; 3];
            }
        }
        c
    }
}

/// Sums of one class of samples.
#[derive(Debug, Clone, Copy, Default)]
struct ClassSums {
    samples: usize,
    error_sq: f64,
    horizontal_sq: f64,
    vertical_sq: f64,
    velocity_sq: f64,
    nees: f64,
    in_band: usize,
    over_99: usize,
}

/// One tracker's result in one run.
#[derive(Debug, Clone, Default)]
struct MethodRun {
    summary: Summary,
    classes: [ClassSums; 4],
    /// The same sums over the frames from [`SETTLED_S`] on.
    settled: [ClassSums; 4],
    /// The summary of the frames from [`SETTLED_S`] on.
    settled_summary: Summary,
    seconds: f64,
    /// Per radar and component (range, azimuth, elevation, radial
    /// velocity): the learnt σ at the end and its σ, with the time it
    /// first converged (when converged at the end).
    learnt: Vec<[Option<Learnt>; ESTIMATED]>,
    /// The same against the truth ([`score_estimates`]).
    estimates: Vec<[Option<EstimateScore>; ESTIMATED]>,
}

/// A learnt σ: the estimate, its σ, and when it first converged (if it
/// is converged at the end).
type Learnt = (f64, f64, Option<f64>);

/// A learnt σ against the radar's true one.
#[derive(Debug, Clone, Copy)]
struct EstimateScore {
    relative_error: f64,
    normalised_error: f64,
    converged_at: Option<f64>,
    factor: f64,
}

/// Frames from this time on are also scored apart ("settled"): the
/// registration of biased radars has converged by then (25–35 s).
const SETTLED_S: f64 = 100.0;

/// The χ²₃ per-sample 95 % band and 99 % quantile.
struct Chi2 {
    band: (f64, f64),
    q99: f64,
}

/// Runs the experiment.
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    run_with(opts, "tracker-manoeuvres", &METHODS)
}

/// `accuracy`: the same scene with every radar's σ declared ×0.3, ×1 or
/// ×3 at random per radar, learnt online against declared right and
/// against the estimator off; with the learnt σ's errors against their
/// own σ and the time they took to converge.
pub fn run_accuracy(opts: &EvalOptions) -> Result<Report, SimError> {
    run_with(opts, "accuracy", &ACCURACY_METHODS)
}

fn run_with(opts: &EvalOptions, name: &str, methods: &[Method]) -> Result<Report, SimError> {
    let targets = opts.targets.unwrap_or(DEFAULT_TARGETS).max(1);
    let scans = opts.scans.unwrap_or(DEFAULT_SCANS).max(2);
    let duration = SCAN_UNIT_S * scans as f64;
    let hours = duration / 3600.0;
    let chi2 = Chi2 {
        band: nees_bounds(3, 1, 0.95)?,
        q99: chi2_threshold(3, 0.01)?,
    };
    let started = Instant::now();
    let per_run = run_batch(&opts.runner, name, |_, rng| {
        one_run(targets, duration, &chi2, methods, rng)
    });
    let per_run: Vec<Vec<MethodRun>> = per_run.into_iter().collect::<Result<_, _>>()?;
    let wall = started.elapsed().as_secs_f64();

    let mut csv = String::from(
        "run,method,class,samples,rmse_3d_m,rmse_h_m,rmse_v_m,rmse_velocity_mps,mean_nees_3dof,in_band_95,over_99\n",
    );
    let mut class_rows = Vec::new();
    let mut overall_rows = Vec::new();
    let mut rmse_series = Vec::new();
    let mut nees_series = Vec::new();
    for (m, method) in methods.iter().enumerate() {
        let mut pooled = [ClassSums::default(); 4];
        for (r, run) in per_run.iter().enumerate() {
            for c in CLASSES {
                let s = run[m].classes[c.index()];
                add(&mut pooled[c.index()], &s);
                let _ = writeln!(
                    csv,
                    "{r},{},{},{},{}",
                    method.name(),
                    c.name(),
                    s.samples,
                    figures(&s).map(|v| format!("{v:.4}")).join(",")
                );
            }
        }
        let series = |g: &dyn Fn(&[f64; 7]) -> f64| Series {
            name: method.name().into(),
            points: CLASSES
                .iter()
                .map(|c| ((c.index() + 1) as f64, g(&figures(&pooled[c.index()]))))
                .collect(),
            dashed: false,
        };
        rmse_series.push(series(&|f| f[0]));
        nees_series.push(series(&|f| f[4]));
        for c in CLASSES {
            let s = pooled[c.index()];
            let [e3, eh, ev, evel, n, band, over] = figures(&s);
            class_rows.push(vec![
                method.name().into(),
                c.name().into(),
                s.samples.to_string(),
                format!("{e3:.1}"),
                format!("{eh:.1}"),
                format!("{ev:.1}"),
                format!("{evel:.2}"),
                format!("{n:.2}"),
                format!("{:.1} %", 100.0 * band),
                format!("{:.1} %", 100.0 * over),
            ]);
        }
        let mut all = ClassSums::default();
        for s in &pooled {
            add(&mut all, s);
        }
        let runs: Vec<&MethodRun> = per_run.iter().map(|r| &r[m]).collect();
        let per = |g: &dyn Fn(&MethodRun) -> f64| -> String {
            let (v, se) = mean_se(&runs.iter().map(|r| g(r)).collect::<Vec<_>>());
            format!("{v:.1} ± {se:.1}")
        };
        let delays: Vec<f64> = runs
            .iter()
            .flat_map(|r| r.summary.confirm_delay.iter().flatten().copied())
            .collect();
        let delay_slots: usize = runs.iter().map(|r| r.summary.confirm_delay.len()).sum();
        let [e3, _, _, evel, n, band, _] = figures(&all);
        let mut late = ClassSums::default();
        for r in &runs {
            for c in &r.settled {
                add(&mut late, c);
            }
        }
        let [e3_late, eh_late, _, _, nees_late, band_late, _] = figures(&late);
        overall_rows.push(vec![
            method.name().into(),
            format!("{e3:.1}"),
            format!("{e3_late:.1} / {eh_late:.1}"),
            format!("{evel:.2}"),
            format!("{n:.2}"),
            format!("{:.1} %", 100.0 * band),
            per(&|r| r.summary.gospa / r.summary.frames.max(1) as f64),
            per(&|r| r.summary.switches as f64 / hours),
            per(&|r| r.summary.breaks as f64 / hours),
            per(&|r| r.summary.false_tracks as f64 / hours),
            format!("{nees_late:.2} / {:.1} %", 100.0 * band_late),
            per(&|r| {
                r.settled_summary.false_tracks as f64 / (hours - SETTLED_S / 3600.0).max(1e-9)
            }),
            format!("{:.3}", delays.len() as f64 / delay_slots.max(1) as f64),
            format!("{:.1}", mean_se(&delays).0),
            format!(
                "{:.0}",
                1e3 * runs.iter().map(|r| r.seconds).sum::<f64>() / runs.len().max(1) as f64
            ),
        ]);
    }

    let mut md = format!("# {name}\n\n");
    let _ = writeln!(
        md,
        "{targets} aircraft over {duration} s ({:.0} % straight and level throughout, the others \
         alternating straight legs with turns of 2–5 m/s², speed changes of 1–3 m/s² and climbs or \
         descents), three 3D Doppler radars 20 km from the centre (periods 4–6 s, random phases, \
         P_D = 0.9, {FALSE_PLOTS_PER_SCAN} false plots per scan). Scored at every frame, each track \
         against the truth at its own time, 3D assignment with a 1 km cut-off. {} runs from seed \
         {}; wall time {wall:.1} s.\n",
        100.0 * STRAIGHT_SHARE,
        opts.runner.runs,
        opts.runner.seed
    );
    md.push_str("Per kind of segment (samples pooled over runs):\n\n");
    md.push_str(&markdown_table(
        &[
            "tracker",
            "segment",
            "samples",
            "RMSE 3D (m)",
            "RMSE horizontal (m)",
            "RMSE vertical (m)",
            "velocity RMSE (m/s)",
            "mean NEES (3 dof)",
            "in χ²₃ 95 % band",
            "> χ²₃(0.99)",
        ],
        &class_rows,
    ));
    let _ = writeln!(
        md,
        "\nA consistent tracker has mean NEES 3, 95 % of its samples in the per-sample χ²₃ band \
         [{:.4}, {:.4}] and 1 % above χ²₃(0.99) = {:.3}.\n",
        chi2.band.0, chi2.band.1, chi2.q99
    );
    md.push_str("Whole scene (± one standard error over runs):\n\n");
    md.push_str(&markdown_table(
        &[
            "tracker",
            "RMSE 3D (m)",
            "after 100 s: RMSE 3D / horizontal (m)",
            "velocity RMSE (m/s)",
            "mean NEES (3 dof)",
            "in χ²₃ 95 % band",
            "GOSPA (m)",
            "ID switches per hour",
            "track breaks per hour",
            "false tracks per hour",
            "after 100 s: NEES / in band",
            "after 100 s: false tracks per hour",
            "targets confirmed",
            "time to confirm (s)",
            "tracker time per run (ms)",
        ],
        &overall_rows,
    ));
    md.push_str(
        "\nRates per hour are per hour of simulated time for the whole scene. GOSPA (p = 1, \
         α = 2, c = 1 km, 3D) is a sum over the targets alive at a frame.\n",
    );
    if methods.iter().any(|m| matches!(m, Method::Misdeclared)) {
        md.push_str(&estimate_table(methods, &per_run));
    }
    let plot = |title: &str, y_label: &str, series| LinePlot {
        title: title.into(),
        x_label: "segment: 1 level, 2 turning, 3 changing speed, 4 climbing".into(),
        y_label: y_label.into(),
        series,
        y_range: None,
    };
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![
            (
                "rmse".into(),
                plot(
                    &format!("{name}: 3D RMSE per segment"),
                    "RMSE (m)",
                    rmse_series,
                )
                .to_svg(),
            ),
            (
                "nees".into(),
                plot(
                    &format!("{name}: mean NEES (3 dof) per segment"),
                    "NEES",
                    nees_series,
                )
                .to_svg(),
            ),
        ],
    })
}

/// The learnt σ of the misdeclared radars, per component and declared
/// factor: how many converged, their relative error, their error in their
/// own σ (mean and RMS: 0 and 1 when honest), and the time to converge.
fn estimate_table(methods: &[Method], per_run: &[Vec<MethodRun>]) -> String {
    let Some(m) = methods
        .iter()
        .position(|m| matches!(m, Method::Misdeclared))
    else {
        return String::new();
    };
    let names = [
        "range",
        "azimuth",
        "elevation",
        "radial velocity",
        "detection probability",
    ];
    let mut rows = Vec::new();
    for (k, name) in names.iter().enumerate() {
        for factor in MISDECLARED {
            let scores: Vec<EstimateScore> = per_run
                .iter()
                .flat_map(|r| r[m].estimates.iter().filter_map(|e| e[k]))
                .filter(|e| e.factor == factor)
                .collect();
            let converged: Vec<&EstimateScore> =
                scores.iter().filter(|e| e.converged_at.is_some()).collect();
            let rel: Vec<f64> = converged.iter().map(|e| e.relative_error).collect();
            let z: Vec<f64> = converged.iter().map(|e| e.normalised_error).collect();
            let mut times: Vec<f64> = converged.iter().filter_map(|e| e.converged_at).collect();
            times.sort_by(f64::total_cmp);
            let rms =
                |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt();
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
            rows.push(vec![
                (*name).into(),
                format!("×{factor}"),
                format!("{}/{}", converged.len(), scores.len()),
                format!("{:+.1} %", 100.0 * mean(&rel)),
                format!("{:.1} %", 100.0 * rms(&rel)),
                format!("{:+.2}", mean(&z)),
                format!("{:.2}", rms(&z)),
                times
                    .get(times.len() / 2)
                    .map_or("–".into(), |t| format!("{t:.0}")),
                times
                    .get((times.len() * 9) / 10)
                    .map_or("–".into(), |t| format!("{t:.0}")),
            ]);
        }
    }
    let mut md = String::from(
        "\nThe learnt σ at the end of each run (misdeclared radars, accuracy learnt), against \
         the true σ, per component and declared factor:\n\n",
    );
    md.push_str(&markdown_table(
        &[
            "component",
            "declared",
            "converged",
            "mean error",
            "RMS error",
            "mean error / its σ",
            "RMS error / its σ",
            "converged at, median (s)",
            "90th percentile (s)",
        ],
        &rows,
    ));
    md
}

fn add(into: &mut ClassSums, s: &ClassSums) {
    into.samples += s.samples;
    into.error_sq += s.error_sq;
    into.horizontal_sq += s.horizontal_sq;
    into.vertical_sq += s.vertical_sq;
    into.velocity_sq += s.velocity_sq;
    into.nees += s.nees;
    into.in_band += s.in_band;
    into.over_99 += s.over_99;
}

/// RMSE 3D, horizontal, vertical, velocity; mean NEES; in-band and over-99
/// shares.
fn figures(s: &ClassSums) -> [f64; 7] {
    let n = s.samples.max(1) as f64;
    [
        rmse(s.error_sq, s.samples),
        rmse(s.horizontal_sq, s.samples),
        rmse(s.vertical_sq, s.samples),
        rmse(s.velocity_sq, s.samples),
        s.nees / n,
        s.in_band as f64 / n,
        s.over_99 as f64 / n,
    ]
}

/// The radars of a run.
fn radars(rng: &mut SimRng) -> Vec<Radar> {
    let rotation = rng.random_range(0.0..TAU);
    (0..RADARS)
        .map(|i| {
            let a = rotation + TAU * i as f64 / RADARS as f64;
            let period = rng.random_range(4.0..6.0);
            let mut r = Radar::two_d(
                [SITE_RADIUS_M * a.sin(), SITE_RADIUS_M * a.cos(), 0.0],
                rng.random_range(30.0..80.0),
                rng.random_range(0.1f64..0.25).to_radians(),
                period,
            )
            .with_elevation(rng.random_range(0.15f64..0.3).to_radians());
            r.doppler = true;
            r.sigma_doppler = 1.0;
            r.phase = rng.random_range(0.0..period);
            r.pd = 0.9;
            r.max_range = MAX_RANGE_M;
            r.clutter_per_km2 = FALSE_PLOTS_PER_SCAN / r.coverage_area_km2();
            r
        })
        .collect()
}

/// The tracker's description of a simulated 3D radar: [`radar_spec`]'s,
/// with the elevation σ and the clutter spread over the elevation extent
/// too (λ per m·rad²).
fn spec_3d(r: &Radar) -> RadarSpec {
    let mut s = radar_spec(r, 1e-9);
    s.sigma_elevation = Some(r.sigma_elevation);
    s.clutter_density = (s.clutter_density / r.max_elevation).max(1e-12);
    s
}

/// One manoeuvre after a straight leg: its legs and its class; `speed` and
/// `altitude` are the target's before it and are updated.
fn manoeuvre(speed: &mut f64, altitude: &mut f64, rng: &mut SimRng) -> (Vec<Leg>, Class) {
    let leg = |duration, manoeuvre| Leg {
        duration,
        manoeuvre,
    };
    match rng.random_range(0..3) {
        0 => {
            let a = rng.random_range(2.0..5.0) / STANDARD_GRAVITY;
            let g_load = if rng.random_bool(0.5) { a } else { -a };
            let d = rng.random_range(20.0..60.0);
            (vec![leg(d, Manoeuvre::Turn { g_load })], Class::Turn)
        }
        1 => {
            let a = rng.random_range(1.0..3.0);
            let d = rng.random_range(10.0..30.0);
            // Accelerate or slow down at random, unless that leaves the
            // band; then the other way, for no longer than the band allows.
            let up = rng.random_bool(0.5);
            let room = |up: bool| {
                if up {
                    SPEED_BAND.1 - *speed
                } else {
                    *speed - SPEED_BAND.0
                }
            };
            let up = if room(up) >= a * d { up } else { !up };
            let d = d.min(room(up).max(0.0) / a);
            let acceleration = if up { a } else { -a };
            *speed += acceleration * d;
            (
                vec![leg(d, Manoeuvre::SpeedChange { acceleration })],
                Class::Speed,
            )
        }
        _ => {
            let a = rng.random_range(0.5..1.5);
            let ramp = rng.random_range(5.0..15.0);
            let hold = rng.random_range(10.0..40.0);
            let a = if *altitude > MID_ALTITUDE_M { -a } else { a };
            // Δz = ½aR² + aR·H + (aR·R − ½aR²) = aR(R + H).
            *altitude += a * ramp * (ramp + hold);
            (
                vec![
                    leg(ramp, Manoeuvre::VerticalAcceleration { acceleration: a }),
                    leg(hold, Manoeuvre::ConstantVelocity),
                    leg(ramp, Manoeuvre::VerticalAcceleration { acceleration: -a }),
                ],
                Class::Climb,
            )
        }
    }
}

/// The targets of a run.
fn targets(n: usize, duration: f64, rng: &mut SimRng) -> Result<Vec<Target>, SimError> {
    (0..n)
        .map(|_| {
            let birth = rng.random_range(0.0..duration / 3.0);
            let mut speed = rng.random_range(120.0..280.0);
            let (vx, vy) = velocity(speed, rng.random_range(0.0..TAU));
            let mut altitude = rng.random_range(2000.0..9000.0);
            let initial = [
                rng.random_range(-BOX_HALF_M..BOX_HALF_M),
                vx,
                rng.random_range(-BOX_HALF_M..BOX_HALF_M),
                vy,
                altitude,
                0.0,
            ];
            let mut legs = Vec::new();
            let mut segments = Vec::new();
            if !rng.random_bool(STRAIGHT_SHARE) {
                let mut t = birth;
                while t < duration {
                    let straight = rng.random_range(20.0..60.0);
                    legs.push(Leg {
                        duration: straight,
                        manoeuvre: Manoeuvre::ConstantVelocity,
                    });
                    t += straight;
                    let (m, class) = manoeuvre(&mut speed, &mut altitude, rng);
                    let length: f64 = m.iter().map(|l| l.duration).sum();
                    segments.push((t, t + length, class));
                    legs.extend(m);
                    t += length;
                }
            }
            let plan = TargetPlan {
                birth,
                initial,
                legs,
                noise_factor: 0.0,
            };
            Ok(Target {
                truth: simulate(&plan, TRUTH_DT_S, duration, rng)?,
                segments,
            })
        })
        .collect()
}

/// A confirmed track as scored: its time, state and covariance.
struct Scored {
    id: u64,
    t: f64,
    state: DVector<f64>,
    covariance: DMatrix<f64>,
}

/// What the accuracy estimator learns of a radar: its four σ and its
/// detection probability.
const ESTIMATED: usize = 5;

/// A radar's learnt σ and P_D in the order of [`ESTIMATED`].
fn estimated(a: &RadarAccuracy) -> [Option<SigmaEstimate>; ESTIMATED] {
    [
        Some(a.range),
        Some(a.azimuth),
        a.elevation,
        a.radial_velocity,
        Some(a.detection_probability),
    ]
}

/// Runs `config` on `plots` and scores every frame.
fn track(
    config: TrackerConfig,
    plots: &[Plot],
    targets: &[Target],
    chi2: &Chi2,
) -> Result<MethodRun, SimError> {
    let started = Instant::now();
    let mut tracker = Tracker::new(config)?;
    let mut frames: Vec<(f64, Vec<Scored>)> = Vec::new();
    let learns = tracker.config().accuracy.enabled;
    let mut converged_at = vec![[None::<f64>; ESTIMATED]; tracker.config().radars.len()];
    tracker.process_with(plots, true, &mut |tr: &Tracker| {
        if learns {
            let t = tr.last_time().unwrap_or(f64::NAN);
            for (at, a) in converged_at.iter_mut().zip(tr.accuracy()) {
                let c = estimated(&a);
                for k in 0..ESTIMATED {
                    if at[k].is_none() && c[k].is_some_and(|e| e.converged) {
                        at[k] = Some(t);
                    }
                }
            }
        }
        let tracks = tr
            .confirmed_tracks()
            .into_iter()
            .map(|o| Scored {
                id: o.id,
                t: o.t,
                state: o.state,
                covariance: o.covariance,
            })
            .collect();
        frames.push((tr.last_time().unwrap_or(f64::NAN), tracks));
        std::ops::ControlFlow::Continue(())
    })?;
    let seconds = started.elapsed().as_secs_f64();
    let mut classes = [ClassSums::default(); 4];
    let mut settled = [ClassSums::default(); 4];
    let mut scores = Vec::with_capacity(frames.len());
    for (t, tracks) in &frames {
        scores.push(score_frame(*t, tracks, targets, chi2, &mut classes)?);
        if *t >= SETTLED_S {
            score_frame(*t, tracks, targets, chi2, &mut settled)?;
        }
    }
    let truth: Vec<Trajectory> = targets.iter().map(|t| t.truth.clone()).collect();
    let first_settled = frames
        .iter()
        .position(|(t, _)| *t >= SETTLED_S)
        .unwrap_or(frames.len());
    let settled_summary = summarise(&scores[first_settled..], &truth);
    let learnt = if learns {
        tracker
            .accuracy()
            .iter()
            .zip(&converged_at)
            .map(|(a, at)| {
                let c = estimated(a);
                std::array::from_fn(|k| {
                    c[k].map(|e| (e.estimate, e.sigma, at[k].filter(|_| e.converged)))
                })
            })
            .collect()
    } else {
        Vec::new()
    };
    Ok(MethodRun {
        summary: summarise(&scores, &truth),
        classes,
        settled,
        settled_summary,
        seconds,
        learnt,
        estimates: Vec::new(),
    })
}

/// Assigns the tracks of one frame at `t` to the targets alive then (3D
/// distance, each track against the truth at its own time) and adds the
/// pairs to `classes`.
fn score_frame(
    t: f64,
    tracks: &[Scored],
    targets: &[Target],
    chi2: &Chi2,
    classes: &mut [ClassSums; 4],
) -> Result<FrameScore, SimError> {
    let alive: Vec<usize> = (0..targets.len())
        .filter(|&k| targets[k].truth.state_at(t).is_some())
        .collect();
    let mut edges = Vec::new();
    for (i, &k) in alive.iter().enumerate() {
        for (j, tr) in tracks.iter().enumerate() {
            if let Some(s) = targets[k].truth.state_at(tr.t) {
                let d = (tr.state[0] - s[0])
                    .hypot(tr.state[2] - s[2])
                    .hypot(tr.state[4] - s[4]);
                if d < CUTOFF_M {
                    edges.push((i, j, d));
                }
            }
        }
    }
    let chosen = assignment::solve(&edges, CUTOFF_M);
    let mut used = vec![false; tracks.len()];
    let mut pairs = Vec::with_capacity(chosen.len());
    let mut localisation = 0.0;
    for (i, j) in chosen {
        let k = alive[i];
        let tr = &tracks[j];
        used[j] = true;
        let s = targets[k]
            .truth
            .state_at(tr.t)
            .ok_or_else(|| SimError::InvalidConfig("assigned a target not alive".into()))?;
        let e = DVector::from_vec(vec![
            tr.state[0] - s[0],
            tr.state[2] - s[2],
            tr.state[4] - s[4],
        ]);
        let ev = [tr.state[1] - s[1], tr.state[3] - s[3], tr.state[5] - s[5]];
        let p = DMatrix::from_fn(3, 3, |a, b| tr.covariance[(2 * a, 2 * b)]);
        let n = nees(&e, &p)?;
        let c = &mut classes[targets[k].class_at(tr.t).index()];
        let h = e[0] * e[0] + e[1] * e[1];
        c.samples += 1;
        c.error_sq += h + e[2] * e[2];
        c.horizontal_sq += h;
        c.vertical_sq += e[2] * e[2];
        c.velocity_sq += ev.iter().map(|v| v * v).sum::<f64>();
        c.nees += n;
        c.in_band += usize::from((chi2.band.0..=chi2.band.1).contains(&n));
        c.over_99 += usize::from(n > chi2.q99);
        localisation += e.norm();
        pairs.push(Pair {
            target: k,
            track: tr.id,
            error_sq: e.norm_squared(),
            nees: n,
        });
    }
    let unassigned = alive.len() + tracks.len() - 2 * pairs.len();
    let duplicates = (0..tracks.len())
        .filter(|&j| !used[j] && edges.iter().any(|e| e.1 == j))
        .count();
    Ok(FrameScore {
        t,
        targets: alive.len(),
        unassigned: tracks
            .iter()
            .zip(&used)
            .filter(|(_, u)| !**u)
            .map(|(tr, _)| tr.id)
            .collect(),
        duplicates,
        gospa: localisation + CUTOFF_M / 2.0 * unassigned as f64,
        pairs,
    })
}

fn one_run(
    n_targets: usize,
    duration: f64,
    chi2: &Chi2,
    methods: &[Method],
    rng: &mut SimRng,
) -> Result<Vec<MethodRun>, SimError> {
    let radars = radars(rng);
    let targets = targets(n_targets, duration, rng)?;
    let truth: Vec<Trajectory> = targets.iter().map(|t| t.truth.clone()).collect();
    let (plots, _) = scan_plots(&radars, &truth, duration, rng)?;
    let specs: Vec<RadarSpec> = radars.iter().map(spec_3d).collect();
    let without_doppler: Vec<Plot> = plots
        .iter()
        .map(|p| Plot {
            radial_velocity: None,
            ..*p
        })
        .collect();
    // Drawn after the plots, so the other methods' plots are those of the
    // release before this variant.
    let biases: Vec<[f64; 3]> = (0..radars.len())
        .map(|_| {
            [
                rng.random_range(-500.0..500.0),
                rng.random_range(-0.5f64..0.5).to_radians(),
                rng.random_range(-0.2f64..0.2).to_radians(),
            ]
        })
        .collect();
    let biased: Vec<Plot> = plots
        .iter()
        .map(|p| {
            let b = biases[p.radar];
            Plot {
                range: (p.range + b[0]).max(0.0),
                azimuth: p.azimuth + b[1],
                elevation: p.elevation.map(|e| e + b[2]),
                ..*p
            }
        })
        .collect();
    // Drawn last, for the same reason.
    let factors: Vec<f64> = (0..radars.len())
        .map(|_| MISDECLARED[rng.random_range(0..MISDECLARED.len())])
        .collect();
    methods
        .iter()
        .map(|m| {
            let p = match m {
                Method::NoRangeRate => &without_doppler,
                Method::Biased | Method::BiasedUnregistered => &biased,
                _ => &plots,
            };
            let mut run = track(m.config(&specs, &factors), p, &targets, chi2)?;
            let declared = if matches!(m, Method::Misdeclared | Method::MisdeclaredFixed) {
                factors.clone()
            } else {
                vec![1.0; specs.len()]
            };
            score_estimates(&mut run, &specs, &declared);
            Ok(run)
        })
        .collect()
}

/// The learnt σ of `run` against the true radars `specs`, each declared
/// with σ × `factors`.
fn score_estimates(run: &mut MethodRun, specs: &[RadarSpec], factors: &[f64]) {
    run.estimates = run
        .learnt
        .iter()
        .zip(specs.iter().zip(factors))
        .map(|(learnt, (spec, &factor))| {
            let truth = [
                Some(spec.sigma_range),
                Some(spec.sigma_azimuth),
                spec.sigma_elevation,
                spec.sigma_radial_velocity,
                Some(spec.detection_probability),
            ];
            std::array::from_fn(|k| {
                let ((estimate, sigma, converged_at), t) = learnt[k].zip(truth[k])?;
                Some(EstimateScore {
                    relative_error: estimate / t - 1.0,
                    normalised_error: (estimate - t) / sigma,
                    converged_at,
                    factor,
                })
            })
        })
        .collect();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;

    #[test]
    fn the_scene_is_as_documented() {
        let mut rng = run_rng(7, 0);
        let r = radars(&mut rng);
        for a in &r {
            assert!((a.site[0].hypot(a.site[1]) - SITE_RADIUS_M).abs() < 1e-6);
            let s = spec_3d(a);
            let el = s.sigma_elevation.unwrap().to_degrees();
            assert!((0.15..0.3).contains(&el), "{el}");
            assert_eq!(s.sigma_radial_velocity, Some(1.0));
        }
        let duration = 300.0;
        let t = targets(200, duration, &mut rng).unwrap();
        let mut seen = [0usize; 4];
        let mut straight = 0;
        for target in &t {
            let tr = &target.truth;
            straight += usize::from(target.segments.is_empty());
            for s in &target.segments {
                seen[s.2.index()] += 1;
            }
            // Speeds and altitudes stay in their bands along the whole
            // trajectory, and every manoeuvre ends level.
            for s in &tr.states {
                let v = s[1].hypot(s[3]);
                assert!(
                    (SPEED_BAND.0 - 1e-6..=SPEED_BAND.1 + 1e-6).contains(&v),
                    "{v}"
                );
                assert!((0.0..13_000.0).contains(&s[4]), "{}", s[4]);
            }
            for &(a, b, class) in &target.segments {
                assert_eq!(target.class_at(0.5 * (a + b)), class);
                if b + 1.0 < tr.end() {
                    let after = tr.state_at(b + 1.0).unwrap();
                    assert!(after[5].abs() < 1e-6, "still climbing after {b}: {after:?}");
                }
            }
        }
        // About a quarter fly straight; every kind of manoeuvre occurs.
        assert!((25..80).contains(&straight), "{straight}");
        assert!(
            seen[0] == 0 && seen[1..].iter().all(|&c| c > 50),
            "{seen:?}"
        );
    }

    #[test]
    fn a_track_on_the_truth_scores_zero_and_its_nees_by_hand() {
        let mut rng = run_rng(1, 0);
        let t = targets(1, 300.0, &mut rng).unwrap();
        let s = t[0].truth.state_at(100.0).unwrap();
        let chi2 = Chi2 {
            band: nees_bounds(3, 1, 0.95).unwrap(),
            q99: chi2_threshold(3, 0.01).unwrap(),
        };
        // 30 m east, 40 m up, P = 100 I: error² 2500, NEES 25 (> 11.34).
        let mut state = DVector::from_row_slice(&s);
        state[0] += 30.0;
        state[4] += 40.0;
        let track = Scored {
            id: 9,
            t: 100.0,
            state,
            covariance: DMatrix::identity(6, 6) * 100.0,
        };
        let mut classes = [ClassSums::default(); 4];
        let f = score_frame(100.0, &[track], &t, &chi2, &mut classes).unwrap();
        assert_eq!(f.pairs.len(), 1);
        assert!((f.pairs[0].error_sq - 2500.0).abs() < 1e-6);
        assert!((f.pairs[0].nees - 25.0).abs() < 1e-9);
        let c = classes[t[0].class_at(100.0).index()];
        assert_eq!((c.samples, c.in_band, c.over_99), (1, 0, 1));
        assert!((c.vertical_sq - 1600.0).abs() < 1e-6 && (c.horizontal_sq - 900.0).abs() < 1e-6);
        // Published χ²₃ quantiles: 0.2158 (2.5 %), 9.3484 (97.5 %), 11.3449 (99 %).
        assert!((chi2.band.0 - 0.2158).abs() < 1e-3 && (chi2.band.1 - 9.3484).abs() < 1e-3);
        assert!((chi2.q99 - 11.3449).abs() < 1e-3);
    }
}
