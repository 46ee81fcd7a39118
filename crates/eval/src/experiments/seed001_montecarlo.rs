//! `seed001-montecarlo`: the seed 001 tracker beyond the patent — a radar
//! network of 2, 3 or 4 unsynchronised Doppler radars (one table row each),
//! many targets, some turning, P_D = 0.9 and clutter; parallel plot fusion
//! (steps 3–5), serial plot fusion (step 6) and the best single radar on
//! the same plots.
//!
//! The scene, per run (all drawn from the run's stream):
//! - radars on a circle of radius 20 km about the origin at equal angles
//!   (random rotation): 40 km apart for 2 radars, 35 km for 3, 28 km
//!   between neighbours for 4; 2D, σ_ρ ~ U[30, 80] m, σ_θ ~ U[0.1°, 0.25°],
//!   Doppler σ 1 m/s, period ~ U[4, 6] s, first scan ~ U[0, period) s,
//!   P_D = 0.9, coverage 1–200 km all round, Poisson clutter of 3 false
//!   plots per scan on average, uniform over the coverage (radial velocity
//!   uniform in ±300 m/s);
//! - targets (default 50, `--targets`): born at a time ~ U[0, D/3], at a
//!   position uniform in a 120 km × 120 km square about the origin, speed
//!   ~ U[100, 300] m/s, heading uniform; half of them manoeuvre: legs of
//!   straight flight (20–60 s) alternate with coordinated turns (20–60 s)
//!   of 2–4 m/s² lateral acceleration, either side;
//! - duration D = 300 s (`--scans` × 5 s).
//!
//! Trackers, all with `TrackerConfig::new`'s defaults unless stated: exact
//! JPDA, the IMM of `Imm::aircraft` (CV √q = 0.5, coordinated turns at
//! ±3 °/s with √q = 3 and a manoeuvre CV √q = 5; mean sojourns 60/20/20/20 s,
//! a new track 0.7/0.1/0.1/0.1) for confirmed tracks, CWNA √q = 3 per axis
//! for tentative ones (the "CV" variants: one constant-velocity model for
//! both, the default before the IMM), 3-of-4 initiation with a
//! [0, 600] m/s speed gate, deletion by `TrackerConfig::default_deletion`
//! (2 × radars, at least 3, consecutive missed frames in serial mode, 3 in parallel
//! mode), 99 % gates, σ_t = 300 m/s for the unseen cross-range motion of
//! parallel mode, duplicate deletion inside the χ² 0.99 gate. The
//! diagnostic variants include the former defaults (DWNA σ_a = 1 m/s²,
//! σ_t = 100 m/s, 3 misses, no duplicate deletion). The radar specs are the true
//! ones (λ per m·rad from the clutter rate, see
//! [`crate::scenario001::radar_spec`]).
//! - **parallel**: every radar, `Mode::Parallel`, fusion period = the
//!   shortest scan period (the default), epoch 0;
//! - **serial**: every radar, `Mode::Serial`;
//! - **best single radar**: each radar alone (`Mode::Serial`, its plots
//!   only); per run, the one with the lowest position RMSE (an oracle's
//!   choice, which favours the single radar).
//!
//! Scoring: [`crate::scenario001`] with a 1 km cut-off (GOSPA p = 1,
//! c = 1 km, α = 2), at every frame the method processed.

use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::time::Instant;

use rand::RngExt;

use super::{EvalOptions, mean_se};
use crate::metrics::{nees_bounds, rmse};
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario001::{
    Summary, only_radar, radar_spec, run_tracker, scan_plots, score_frames, summarise,
};
use crate::sensor::Radar;
use crate::truth::{Leg, Manoeuvre, TargetPlan, Trajectory, simulate, velocity};
use crate::{STANDARD_GRAVITY, SimError, SimRng};
use algo::jpda::Method;
use algo::tracking::{Imm, Mode, Motion, MotionModel, NoiseModel, Plot, RadarSpec, TrackerConfig};

const RADAR_COUNTS: [usize; 3] = [2, 3, 4];
pub(crate) const DEFAULT_TARGETS: usize = 50;
pub(crate) const SCAN_UNIT_S: f64 = 5.0;
pub(crate) const DEFAULT_SCANS: usize = 60;
const SITE_RADIUS_M: f64 = 20_000.0;
const MAX_RANGE_M: f64 = 200_000.0;
const FALSE_PLOTS_PER_SCAN: f64 = 3.0;
const BOX_HALF_M: f64 = 60_000.0;
pub(crate) const CUTOFF_M: f64 = 1000.0;
const TRUTH_DT_S: f64 = 0.25;
/// The methods of the table, in order.
const METHODS: [&str; 3] = ["parallel", "serial", "best single radar"];
/// The radar count whose scenes also run the diagnostic variants.
const DIAGNOSTIC_RADARS: usize = 3;

/// A tracker with one or more options changed from the defaults, run on
/// the same scenes as the [`DIAGNOSTIC_RADARS`] row to find what drives a
/// figure.
struct Variant {
    name: &'static str,
    mode: Mode,
    /// Each radar alone (`mode` ignored), the best RMSE of them kept.
    single: bool,
    /// `Some`: one constant-velocity model instead of the default IMM, with
    /// this process noise model and σ_a (or √q) per axis.
    noise: Option<(NoiseModel, f64)>,
    /// `Some`: σ_t of parallel mode (m/s).
    sigma_t: Option<f64>,
    /// `Some`: consecutive misses that delete a track.
    max_misses: Option<u32>,
    /// `Some`: `duplicate_gate_probability` (0 disables duplicate deletion).
    duplicate: Option<f64>,
    method: Method,
    /// `Some`: this IMM instead of the default one.
    imm: Option<fn() -> Imm>,
}

impl Variant {
    /// The defaults in `mode`, named `name`; change fields with `..`.
    const fn of(name: &'static str, mode: Mode) -> Self {
        Self {
            name,
            mode,
            single: false,
            noise: None,
            sigma_t: None,
            max_misses: None,
            duplicate: None,
            method: Method::Exact,
            imm: None,
        }
    }
}

/// A candidate IMM for the default (the table's variants compare them):
/// constant velocity with √q `sigma_cv` (mean sojourn 60 s, initial
/// probability `initial[0]`), coordinated turns at ± each of `rates` (°/s)
/// with √q `sigma_ct`, and optionally a manoeuvre CV model of √q
/// `manoeuvre`; the others 20 s and `initial[1]` each.
fn imm_set(
    sigma_cv: f64,
    rates: &[f64],
    sigma_ct: f64,
    manoeuvre: Option<f64>,
    initial: [f64; 2],
) -> Imm {
    let mut models = vec![MotionModel::ConstantVelocity {
        sigma_a: [sigma_cv; 3],
    }];
    for &r in rates {
        for sign in [1.0, -1.0] {
            models.push(MotionModel::CoordinatedTurn {
                turn_rate: sign * r.to_radians(),
                sigma_a: [sigma_ct; 3],
            });
        }
    }
    if let Some(s) = manoeuvre {
        models.push(MotionModel::ConstantVelocity { sigma_a: [s; 3] });
    }
    let n = models.len();
    let mut mean_sojourn = vec![20.0; n];
    mean_sojourn[0] = 60.0;
    let mut initial_probabilities = vec![initial[1]; n];
    initial_probabilities[0] = initial[0];
    Imm {
        models,
        mean_sojourn,
        initial_probabilities,
    }
}

fn imm_cv_cv() -> Imm {
    imm_set(0.5, &[], 0.0, Some(5.0), [0.8, 0.2])
}

fn imm_ct_1_5() -> Imm {
    imm_set(0.5, &[1.5], 2.0, None, [0.8, 0.1])
}

fn imm_ct_3_noisy() -> Imm {
    imm_set(1.0, &[3.0], 3.0, None, [0.8, 0.1])
}

fn imm_cv_ct_cv() -> Imm {
    imm_set(0.5, &[1.5], 1.5, Some(5.0), [0.7, 0.1])
}

fn imm_d() -> Imm {
    imm_set(0.5, &[1.5, 3.0], 1.5, None, [0.7, 0.075])
}

fn imm_g() -> Imm {
    imm_set(0.5, &[1.5, 3.0], 2.0, None, [0.7, 0.075])
}

/// The defaults before commits 4fc2c52, 114755c and 5f66756: DWNA
/// σ_a = 1 m/s², σ_t = 100 m/s, 3 consecutive misses delete, no duplicate
/// deletion.
const FORMER_NOISE: Option<(NoiseModel, f64)> = Some((NoiseModel::Dwna, 1.0));
const FORMER_SIGMA_T: Option<f64> = Some(100.0);
const FORMER_MISSES: Option<u32> = Some(3);
const FORMER_DUPLICATE: Option<f64> = Some(0.0);

const VARIANTS: [Variant; 25] = [
    Variant {
        imm: Some(imm_d),
        ..Variant::of("serial IMM cv 0.5 + ct ±1.5 and ±3°/s 1.5", Mode::Serial)
    },
    Variant {
        imm: Some(imm_g),
        ..Variant::of("serial IMM cv 0.5 + ct ±1.5 and ±3°/s 2", Mode::Serial)
    },
    Variant {
        imm: Some(imm_d),
        ..Variant::of(
            "parallel IMM cv 0.5 + ct ±1.5 and ±3°/s 1.5",
            Mode::Parallel,
        )
    },
    Variant {
        imm: Some(imm_g),
        ..Variant::of("parallel IMM cv 0.5 + ct ±1.5 and ±3°/s 2", Mode::Parallel)
    },
    Variant {
        imm: Some(imm_cv_cv),
        ..Variant::of("serial IMM cv 0.5 + cv 5", Mode::Serial)
    },
    Variant {
        imm: Some(imm_ct_1_5),
        ..Variant::of("serial IMM cv 0.5 + ct ±1.5°/s 2", Mode::Serial)
    },
    Variant {
        imm: Some(imm_ct_3_noisy),
        ..Variant::of("serial IMM cv 1 + ct ±3°/s 3", Mode::Serial)
    },
    Variant {
        imm: Some(imm_cv_ct_cv),
        ..Variant::of("serial IMM cv 0.5 + ct ±1.5°/s 1.5 + cv 5", Mode::Serial)
    },
    Variant {
        imm: Some(imm_cv_cv),
        ..Variant::of("parallel IMM cv 0.5 + cv 5", Mode::Parallel)
    },
    Variant {
        imm: Some(imm_ct_1_5),
        ..Variant::of("parallel IMM cv 0.5 + ct ±1.5°/s 2", Mode::Parallel)
    },
    Variant {
        imm: Some(imm_ct_3_noisy),
        ..Variant::of("parallel IMM cv 1 + ct ±3°/s 3", Mode::Parallel)
    },
    Variant {
        imm: Some(imm_cv_ct_cv),
        ..Variant::of(
            "parallel IMM cv 0.5 + ct ±1.5°/s 1.5 + cv 5",
            Mode::Parallel,
        )
    },
    Variant {
        noise: Some((NoiseModel::Cwna, 3.0)),
        ..Variant::of(
            "parallel CV √q = 3 (the default before the IMM)",
            Mode::Parallel,
        )
    },
    Variant {
        noise: Some((NoiseModel::Cwna, 3.0)),
        ..Variant::of(
            "serial CV √q = 3 (the default before the IMM)",
            Mode::Serial,
        )
    },
    Variant {
        noise: FORMER_NOISE,
        sigma_t: FORMER_SIGMA_T,
        max_misses: FORMER_MISSES,
        duplicate: FORMER_DUPLICATE,
        ..Variant::of("parallel former defaults", Mode::Parallel)
    },
    Variant {
        noise: FORMER_NOISE,
        sigma_t: FORMER_SIGMA_T,
        max_misses: FORMER_MISSES,
        duplicate: FORMER_DUPLICATE,
        ..Variant::of("serial former defaults", Mode::Serial)
    },
    Variant {
        single: true,
        noise: FORMER_NOISE,
        sigma_t: FORMER_SIGMA_T,
        max_misses: FORMER_MISSES,
        duplicate: FORMER_DUPLICATE,
        ..Variant::of("best single radar former defaults", Mode::Serial)
    },
    Variant {
        sigma_t: FORMER_SIGMA_T,
        ..Variant::of("parallel σ_t = 100 m/s", Mode::Parallel)
    },
    Variant {
        max_misses: Some(3 * DIAGNOSTIC_RADARS as u32),
        ..Variant::of("parallel 3 × radars misses delete", Mode::Parallel)
    },
    Variant {
        max_misses: Some(3 * DIAGNOSTIC_RADARS as u32),
        ..Variant::of("serial 3 × radars misses delete", Mode::Serial)
    },
    Variant {
        max_misses: FORMER_MISSES,
        ..Variant::of("serial 3 misses delete", Mode::Serial)
    },
    Variant {
        duplicate: Some(0.0),
        ..Variant::of("serial without duplicate deletion", Mode::Serial)
    },
    Variant {
        duplicate: Some(0.0),
        ..Variant::of("parallel without duplicate deletion", Mode::Parallel)
    },
    Variant {
        method: Method::GlobalNearestNeighbour,
        ..Variant::of("serial GNN", Mode::Serial)
    },
    Variant {
        method: Method::GlobalNearestNeighbour,
        ..Variant::of("parallel GNN", Mode::Parallel)
    },
];

/// Σ squared error, samples, Σ NEES of one class of targets.
#[derive(Debug, Clone, Copy, Default)]
struct ClassSums {
    error_sq: f64,
    samples: usize,
    nees: f64,
}

/// One tracker's result in one run; `classes`: straight, turning targets.
#[derive(Debug, Clone, Default)]
struct MethodRun {
    summary: Summary,
    classes: [ClassSums; 2],
    seconds: f64,
}

/// Everything one run produced.
struct RunOut {
    /// Parallel and serial fusion.
    fused: [MethodRun; 2],
    /// Each radar alone.
    singles: Vec<MethodRun>,
    /// The [`VARIANTS`] (only on [`DIAGNOSTIC_RADARS`] scenes).
    variants: Vec<MethodRun>,
}

/// Per-run figures of one method, as in the tables.
#[derive(Debug, Clone, Copy, Default)]
struct Figures {
    rmse: f64,
    nees: f64,
    nees_over: f64,
    gospa: f64,
    missed: f64,
    false_per_frame: f64,
    duplicates: f64,
    switches_per_h: f64,
    breaks_per_h: f64,
    false_tracks_per_h: f64,
    confirmed: f64,
    confirm_s: f64,
    rmse_straight: f64,
    rmse_turning: f64,
    nees_straight: f64,
    nees_turning: f64,
}

impl Figures {
    fn of(m: &MethodRun, hours: f64) -> Self {
        let s = &m.summary;
        let n = s.samples.max(1) as f64;
        let frames = s.frames.max(1) as f64;
        let delays: Vec<f64> = s.confirm_delay.iter().flatten().copied().collect();
        let [a, b] = m.classes;
        Self {
            rmse: rmse(s.error_sq, s.samples),
            nees: s.nees / n,
            nees_over: s.nees_over_99 as f64 / n,
            gospa: s.gospa / frames,
            missed: s.missed as f64 / frames,
            false_per_frame: s.unassigned_tracks as f64 / frames,
            duplicates: s.duplicates as f64 / frames,
            switches_per_h: s.switches as f64 / hours,
            breaks_per_h: s.breaks as f64 / hours,
            false_tracks_per_h: s.false_tracks as f64 / hours,
            confirmed: delays.len() as f64 / s.confirm_delay.len().max(1) as f64,
            confirm_s: mean_se(&delays).0,
            rmse_straight: rmse(a.error_sq, a.samples),
            rmse_turning: rmse(b.error_sq, b.samples),
            nees_straight: a.nees / a.samples.max(1) as f64,
            nees_turning: b.nees / b.samples.max(1) as f64,
        }
    }

    const HEADER: &str = "rmse_m,mean_nees,nees_over_99,gospa_m,missed_per_frame,false_per_frame,duplicates_per_frame,id_switches_per_h,track_breaks_per_h,false_tracks_per_h,targets_confirmed,mean_confirm_s,rmse_straight_m,rmse_turning_m,nees_straight,nees_turning";

    fn csv(&self) -> String {
        [
            self.rmse,
            self.nees,
            self.nees_over,
            self.gospa,
            self.missed,
            self.false_per_frame,
            self.duplicates,
            self.switches_per_h,
            self.breaks_per_h,
            self.false_tracks_per_h,
            self.confirmed,
            self.confirm_s,
            self.rmse_straight,
            self.rmse_turning,
            self.nees_straight,
            self.nees_turning,
        ]
        .map(|v| format!("{v:.4}"))
        .join(",")
    }
}

/// Mean ± SE over runs of one figure, with `digits` decimals.
fn pm(figures: &[Figures], g: impl Fn(&Figures) -> f64, digits: usize) -> String {
    let (v, se) = mean_se(&figures.iter().map(g).collect::<Vec<_>>());
    format!("{v:.digits$} ± {se:.digits$}")
}

/// Mean over runs of one figure.
fn mean(figures: &[Figures], g: impl Fn(&Figures) -> f64) -> f64 {
    mean_se(&figures.iter().map(g).collect::<Vec<_>>()).0
}

/// Runs the experiment: one row group per radar count.
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let targets = opts.targets.unwrap_or(DEFAULT_TARGETS).max(1);
    let scans = opts.scans.unwrap_or(DEFAULT_SCANS).max(2);
    let duration = SCAN_UNIT_S * scans as f64;
    let hours = duration / 3600.0;
    let started = Instant::now();
    let mut csv = format!("radars,run,method,best_radar,{}\n", Figures::HEADER);
    let mut rows = Vec::new();
    let mut diagnostic_rows = Vec::new();
    let mut verdicts = String::new();
    let mut rmse_series: Vec<Series> = METHODS
        .iter()
        .map(|m| Series {
            name: (*m).into(),
            points: Vec::new(),
            dashed: false,
        })
        .collect();
    let mut gospa_series = rmse_series.clone();
    let mut nees_samples = 0usize;
    for &n in &RADAR_COUNTS {
        let per_run = run_batch(
            &opts.runner,
            &format!("seed001-montecarlo {n} radars"),
            |_, rng| one_run(n, targets, duration, rng),
        );
        let per_run: Vec<RunOut> = per_run.into_iter().collect::<Result<_, _>>()?;
        // table[m][r]: method m (the three METHODS, then the variants) in run r.
        let mut table: Vec<Vec<Figures>> = vec![Vec::new(); 3 + VARIANTS.len()];
        let mut seconds = vec![0.0; 3 + VARIANTS.len()];
        let mut nees_pooled = vec![(0.0, 0usize); 3 + VARIANTS.len()];
        for (r, run) in per_run.iter().enumerate() {
            let singles: Vec<Figures> = run.singles.iter().map(|m| Figures::of(m, hours)).collect();
            let best = (0..singles.len())
                .min_by(|&a, &b| singles[a].rmse.total_cmp(&singles[b].rmse))
                .unwrap_or(0);
            let sources: Vec<&MethodRun> = [&run.fused[0], &run.fused[1], &run.singles[best]]
                .into_iter()
                .chain(&run.variants)
                .collect();
            for (m, source) in sources.iter().enumerate() {
                let f = Figures::of(source, hours);
                let name = METHODS
                    .get(m)
                    .copied()
                    .unwrap_or_else(|| VARIANTS[m - 3].name);
                let _ = writeln!(csv, "{n},{r},{name},{},{}", best + 1, f.csv());
                table[m].push(f);
                nees_pooled[m].0 += source.summary.nees;
                nees_pooled[m].1 += source.summary.samples;
                seconds[m] += if m == 2 {
                    run.singles.iter().map(|x| x.seconds).sum::<f64>()
                } else {
                    source.seconds
                };
            }
        }
        let runs = per_run.len().max(1) as f64;
        for (m, figures) in table.iter().enumerate() {
            if figures.is_empty() {
                continue;
            }
            let name = METHODS
                .get(m)
                .copied()
                .unwrap_or_else(|| VARIANTS[m - 3].name);
            let (pooled_nees, samples) = nees_pooled[m];
            nees_samples = nees_samples.max(samples);
            let nees_text = format!("{:.2}", pooled_nees / samples.max(1) as f64);
            let over = format!("{:.1} %", 100.0 * mean(figures, |f| f.nees_over));
            if m < 3 {
                rows.push(vec![
                    n.to_string(),
                    name.into(),
                    pm(figures, |f| f.rmse, 1),
                    nees_text.clone(),
                    over.clone(),
                    pm(figures, |f| f.gospa, 0),
                    format!("{:.2}", mean(figures, |f| f.missed)),
                    format!(
                        "{:.2} / {:.2}",
                        mean(figures, |f| f.duplicates),
                        mean(figures, |f| f.false_per_frame - f.duplicates)
                    ),
                    pm(figures, |f| f.switches_per_h, 1),
                    pm(figures, |f| f.breaks_per_h, 1),
                    pm(figures, |f| f.false_tracks_per_h, 1),
                    format!("{:.3}", mean(figures, |f| f.confirmed)),
                    pm(figures, |f| f.confirm_s, 2),
                    format!("{:.0}", 1e3 * seconds[m] / runs),
                ]);
                rmse_series[m]
                    .points
                    .push((n as f64, mean(figures, |f| f.rmse)));
                gospa_series[m]
                    .points
                    .push((n as f64, mean(figures, |f| f.gospa)));
            }
            if n == DIAGNOSTIC_RADARS {
                diagnostic_rows.push(vec![
                    name.into(),
                    format!("{:.1}", mean(figures, |f| f.rmse_straight)),
                    format!("{:.1}", mean(figures, |f| f.rmse_turning)),
                    format!("{:.2}", mean(figures, |f| f.nees_straight)),
                    format!("{:.2}", mean(figures, |f| f.nees_turning)),
                    over,
                    format!("{:.2}", mean(figures, |f| f.duplicates)),
                    format!("{:.1}", mean(figures, |f| f.switches_per_h)),
                    format!("{:.1}", mean(figures, |f| f.breaks_per_h)),
                    format!("{:.1}", mean(figures, |f| f.false_tracks_per_h)),
                    format!("{:.2}", mean(figures, |f| f.confirm_s)),
                    format!("{:.0}", mean(figures, |f| f.gospa)),
                ]);
            }
        }
        let single = &table[2];
        for m in 0..2 {
            let f = &table[m];
            let (r, r1) = (mean(f, |x| x.rmse), mean(single, |x| x.rmse));
            let (c, c1) = (mean(f, |x| x.confirm_s), mean(single, |x| x.confirm_s));
            let _ = writeln!(
                verdicts,
                "- {n} radars, {}: RMSE {r:.1} m vs {r1:.1} m for the best single radar ({:+.1} %, \
                 {}); time to confirm {c:.1} s vs {c1:.1} s ({:+.1} s, {}); GOSPA {:.0} m vs {:.0} m.",
                METHODS[m],
                100.0 * (r / r1 - 1.0),
                if r < r1 { "better" } else { "worse" },
                c - c1,
                if c < c1 { "faster" } else { "slower" },
                mean(f, |x| x.gospa),
                mean(single, |x| x.gospa),
            );
        }
    }
    let wall = started.elapsed().as_secs_f64();
    let (lo, hi) = nees_bounds(2, nees_samples.max(1), 0.95)?;

    let mut md = String::from("# seed001-montecarlo (beyond the patent)\n\n");
    let _ = writeln!(
        md,
        "{targets} targets (half of them turning at 2–4 m/s²) over {duration} s, 2D Doppler radars \
         20 km from the centre with periods 4–6 s and random phases, P_D = 0.9, \
         {FALSE_PLOTS_PER_SCAN} false plots per scan per radar; the trackers' defaults (exact JPDA, \
         CWNA √q = 3, 3-of-4, 2 × radars missed frames delete in serial mode and 3 in parallel mode, \
         σ_t = 300 m/s, duplicates deleted inside the χ² 0.99 gate). Scored at every frame of each \
         method against the targets born by then: GOSPA assignment with c = 1 km (p = 1, α = 2; \
         GOSPA is a sum over the ≈ {targets} targets, not a per-target figure). {} runs per radar \
         count from seed {}; wall time {wall:.1} s.\n",
        opts.runner.runs, opts.runner.seed
    );
    md.push_str(&markdown_table(
        &[
            "radars",
            "method",
            "position RMSE (m)",
            "mean NEES (2 dof)",
            "NEES > χ²₂(0.99)",
            "GOSPA (m)",
            "missed per frame",
            "unassigned tracks per frame: duplicates / others",
            "ID switches per hour",
            "track breaks per hour",
            "false tracks per hour",
            "targets confirmed",
            "time to confirm (s)",
            "tracker time per run (ms)",
        ],
        &rows,
    ));
    let _ = writeln!(
        md,
        "\n± is one standard error over runs. A consistent tracker has mean NEES 2 and 1 % of \
         samples above χ²₂(0.99) = 9.21; the 95 % band of the mean of {nees_samples} independent \
         samples is [{lo:.3}, {hi:.3}] (successive samples of a track are correlated, so the real \
         band is wider). \"Best single radar\" is, per run, the radar whose own tracker had the \
         lowest RMSE; its tracker time is that of all single-radar trackers. Rates per hour are \
         per hour of simulated time for the whole scene.\n"
    );
    md.push_str("Fused against the best single radar:\n\n");
    md.push_str(&verdicts);
    let _ = writeln!(
        md,
        "\nDiagnostics on the {DIAGNOSTIC_RADARS}-radar scenes (same runs): straight and turning \
         targets apart, and trackers with options changed (\"former defaults\": DWNA σ_a = 1 m/s², \
         σ_t = 100 m/s, 3 consecutive misses delete, no duplicate deletion).\n"
    );
    md.push_str(&markdown_table(
        &[
            "tracker",
            "RMSE straight (m)",
            "RMSE turning (m)",
            "NEES straight",
            "NEES turning",
            "NEES > χ²₂(0.99)",
            "duplicate tracks per frame",
            "ID switches per hour",
            "track breaks per hour",
            "false tracks per hour",
            "time to confirm (s)",
            "GOSPA (m)",
        ],
        &diagnostic_rows,
    ));
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![
            (
                "rmse".into(),
                LinePlot {
                    title: "seed 001 Monte Carlo: position RMSE".into(),
                    x_label: "radars".into(),
                    y_label: "RMSE (m)".into(),
                    series: rmse_series,
                    y_range: None,
                }
                .to_svg(),
            ),
            (
                "gospa".into(),
                LinePlot {
                    title: "seed 001 Monte Carlo: mean GOSPA (c = 1 km)".into(),
                    x_label: "radars".into(),
                    y_label: "GOSPA (m)".into(),
                    series: gospa_series,
                    y_range: None,
                }
                .to_svg(),
            ),
        ],
    })
}

/// The radars of a run.
pub(crate) fn radars(n: usize, rng: &mut SimRng) -> Vec<Radar> {
    let rotation = rng.random_range(0.0..TAU);
    (0..n)
        .map(|i| {
            let a = rotation + TAU * i as f64 / n as f64;
            let period = rng.random_range(4.0..6.0);
            let mut r = Radar::two_d(
                [SITE_RADIUS_M * a.sin(), SITE_RADIUS_M * a.cos(), 0.0],
                rng.random_range(30.0..80.0),
                rng.random_range(0.1f64..0.25).to_radians(),
                period,
            );
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

/// The targets of a run, each with `true` when it turns.
pub(crate) fn targets(
    n: usize,
    duration: f64,
    rng: &mut SimRng,
) -> Result<Vec<(Trajectory, bool)>, SimError> {
    (0..n)
        .map(|_| {
            let birth = rng.random_range(0.0..duration / 3.0);
            let (vx, vy) = velocity(rng.random_range(100.0..300.0), rng.random_range(0.0..TAU));
            let mut legs = Vec::new();
            if rng.random_bool(0.5) {
                let mut t = birth;
                let mut turn = false;
                while t < duration {
                    let length = rng.random_range(20.0..60.0);
                    let manoeuvre = if turn {
                        let a = rng.random_range(2.0..4.0) / STANDARD_GRAVITY;
                        Manoeuvre::Turn {
                            g_load: if rng.random_bool(0.5) { a } else { -a },
                        }
                    } else {
                        Manoeuvre::ConstantVelocity
                    };
                    legs.push(Leg {
                        duration: length,
                        manoeuvre,
                    });
                    t += length;
                    turn = !turn;
                }
            }
            let plan = TargetPlan {
                birth,
                initial: [
                    rng.random_range(-BOX_HALF_M..BOX_HALF_M),
                    vx,
                    rng.random_range(-BOX_HALF_M..BOX_HALF_M),
                    vy,
                    0.0,
                    0.0,
                ],
                legs,
                noise_factor: 0.0,
            };
            let turning = !plan.legs.is_empty();
            Ok((simulate(&plan, TRUTH_DT_S, duration, rng)?, turning))
        })
        .collect()
}

fn one_run(
    n: usize,
    n_targets: usize,
    duration: f64,
    rng: &mut SimRng,
) -> Result<RunOut, SimError> {
    let radars = radars(n, rng);
    let (truth, turning): (Vec<Trajectory>, Vec<bool>) =
        targets(n_targets, duration, rng)?.into_iter().unzip();
    let (plots, _) = scan_plots(&radars, &truth, duration, rng)?;
    let specs: Vec<RadarSpec> = radars.iter().map(|r| radar_spec(r, 1e-9)).collect();
    let config = |specs: Vec<RadarSpec>, mode: Mode| {
        let mut c = TrackerConfig::new(2, specs);
        // The service's default for the mode (2 × radars missed frames in
        // serial mode, 3 in parallel mode).
        c.set_mode(mode);
        c
    };
    let track = |cfg: TrackerConfig, plots: &[Plot]| -> Result<MethodRun, SimError> {
        let started = Instant::now();
        let (frames, _) = run_tracker(cfg, plots)?;
        let seconds = started.elapsed().as_secs_f64();
        let scores = score_frames(&frames, &truth, CUTOFF_M)?;
        let mut classes = [ClassSums::default(); 2];
        for p in scores.iter().flat_map(|f| &f.pairs) {
            let c = &mut classes[usize::from(turning[p.target])];
            c.error_sq += p.error_sq;
            c.samples += 1;
            c.nees += p.nees;
        }
        Ok(MethodRun {
            summary: summarise(&scores, &truth),
            classes,
            seconds,
        })
    };
    let fused = [
        track(config(specs.clone(), Mode::Parallel), &plots)?,
        track(config(specs.clone(), Mode::Serial), &plots)?,
    ];
    let singles = specs
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            track(
                config(vec![spec.clone()], Mode::Serial),
                &only_radar(&plots, i),
            )
        })
        .collect::<Result<_, _>>()?;
    let variants = if n == DIAGNOSTIC_RADARS {
        VARIANTS
            .iter()
            .map(|v| {
                let variant = |specs: Vec<RadarSpec>| {
                    let mut c = config(specs, v.mode);
                    if let Some((noise, sigma)) = v.noise {
                        c.motion = Motion::ConstantVelocity;
                        c.noise = noise;
                        c.sigma_a = [sigma; 3];
                    }
                    if let Some(sigma_t) = v.sigma_t {
                        c.sigma_tangential_speed = sigma_t;
                    }
                    if v.max_misses.is_some() {
                        c.deletion.max_consecutive_misses = v.max_misses;
                    }
                    if let Some(p) = v.duplicate {
                        c.duplicate_gate_probability = p;
                    }
                    c.association.method = v.method;
                    if let Some(imm) = v.imm {
                        c.motion = Motion::Imm(imm());
                    }
                    c
                };
                if !v.single {
                    return track(variant(specs.clone()), &plots);
                }
                let alone = specs
                    .iter()
                    .enumerate()
                    .map(|(i, s)| track(variant(vec![s.clone()]), &only_radar(&plots, i)))
                    .collect::<Result<Vec<_>, _>>()?;
                let score = |m: &MethodRun| rmse(m.summary.error_sq, m.summary.samples);
                Ok(alone
                    .into_iter()
                    .min_by(|a, b| score(a).total_cmp(&score(b)))
                    .unwrap_or_default())
            })
            .collect::<Result<_, _>>()?
    } else {
        Vec::new()
    };
    Ok(RunOut {
        fused,
        singles,
        variants,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::montecarlo::run_rng;

    #[test]
    fn the_scene_is_as_documented() {
        let mut rng = run_rng(3, 0);
        let r = radars(3, &mut rng);
        for (i, a) in r.iter().enumerate() {
            assert!((a.site[0].hypot(a.site[1]) - SITE_RADIUS_M).abs() < 1e-6);
            assert!((4.0..6.0).contains(&a.period) && a.phase < a.period);
            let lambda = a.clutter_per_km2 * a.coverage_area_km2();
            assert!((lambda - FALSE_PLOTS_PER_SCAN).abs() < 1e-9);
            let b = &r[(i + 1) % 3];
            let d = (a.site[0] - b.site[0]).hypot(a.site[1] - b.site[1]);
            assert!((d - SITE_RADIUS_M * 3f64.sqrt()).abs() < 1e-6, "{d}");
        }
        let t = targets(40, 300.0, &mut rng).unwrap();
        for (tr, _) in &t {
            assert!(tr.birth < 100.0);
            let s = tr.states[0];
            assert!(s[0].abs() <= BOX_HALF_M && s[2].abs() <= BOX_HALF_M);
            let v = s[1].hypot(s[3]);
            assert!((100.0..300.0).contains(&v));
            // Coordinated turns keep the speed.
            let e = tr.states.last().unwrap();
            assert!((e[1].hypot(e[3]) - v).abs() < 1e-6);
        }
        // Some turn: their final heading differs from the initial one.
        for (tr, turning) in &t {
            let (a, b) = (tr.states[0], tr.states.last().unwrap());
            let turned = (a[1] - b[1]).abs() + (a[3] - b[3]).abs() > 1.0;
            assert_eq!(turned, *turning);
        }
        let turning = t.iter().filter(|(_, turning)| *turning).count();
        assert!((5..35).contains(&turning), "{turning}");
    }
}
