//! Radar registration in the tracker: the seed-001 Monte Carlo scene (2, 3
//! and 4 unsynchronised Doppler radars, turning targets, clutter, P_D 0.9)
//! with every radar biased at random (range uniform in ±500 m, azimuth in
//! ±0.5°), tracked three ways on the same plots:
//! - **unbiased**: the scene without biases, the defaults (the floor);
//! - **unregistered**: the biased plots, registration off;
//! - **registered**: the biased plots, the defaults (registration on);
//! - the unbiased and the registered rows again in parallel mode
//!   (`Mode::Parallel`, its default fusion period and deletion), which
//!   learns from the plots of several radars fused at each instant.
//!
//! Scored as `seed001-montecarlo` (every frame against the truth at its
//! time, 1 km cut-off): RMSE, NEES, GOSPA, false and duplicate tracks. For
//! the registered tracker, the final bias estimates against the truth:
//! errors, their normalised squares (a consistent σ gives 1 per component)
//! and the share within 2σ; and the time until every radar's estimate is
//! applied (converged).
//!
//! Only relative biases are observable without a reference radar: the
//! estimates are compared with the truth minus the biases' mean over the
//! radars (range) and over the radars (azimuth), i.e. what the network
//! can see; the table also gives the raw errors.

use std::fmt::Write as _;

use algo::tracking::{Mode, Plot, RadarSpec, Tracker, TrackerConfig};
use rand::RngExt;

use super::seed001_montecarlo::{
    CUTOFF_M, DEFAULT_SCANS, DEFAULT_TARGETS, SCAN_UNIT_S, radars, targets,
};
use super::{EvalOptions, mean_se};
use crate::metrics::rmse;
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario001::{Frame, frame_of, radar_spec, scan_plots, score_frames, summarise};
use crate::{SimError, SimRng};

const RANGE_BIAS_M: f64 = 500.0;
const AZIMUTH_BIAS_DEG: f64 = 0.5;
/// Frames from this time on are scored apart ("settled"): every run's
/// estimates converged by then (median 30–40 s).
const SETTLED_S: f64 = 100.0;
const METHODS: [&str; 5] = [
    "unbiased (floor)",
    "biased, unregistered",
    "biased, registered",
    "parallel mode, unbiased",
    "parallel mode, biased, registered",
];

#[derive(Debug, Clone, Copy, Default)]
struct Figures {
    rmse: f64,
    /// After [`SETTLED_S`].
    rmse_settled: f64,
    nees: f64,
    gospa: f64,
    false_per_h: f64,
    duplicates: f64,
    breaks_per_h: f64,
}

#[derive(Debug, Clone, Default)]
struct RunOut {
    figures: [Figures; 5],
    /// Per radar: (range error m, azimuth error °, range σ, azimuth σ,
    /// absolute range error, absolute azimuth error °); the first two
    /// relative to the network's mean bias.
    errors: Vec<[f64; 6]>,
    /// Time when every radar's estimate was applied (s), if it was.
    converged_at: Option<f64>,
    /// The same two for parallel mode.
    errors_parallel: Vec<[f64; 6]>,
    converged_parallel: Option<f64>,
}

/// Per radar, the final estimate against the truth (see [`RunOut::errors`]).
fn bias_errors(tracker: &Tracker, biases: &[[f64; 2]]) -> Vec<[f64; 6]> {
    let n = biases.len() as f64;
    let mean = |k: usize| biases.iter().map(|b| b[k]).sum::<f64>() / n;
    let est = tracker.biases();
    let est_mean = |k: usize| est.iter().map(|b| b.bias[k]).sum::<f64>() / n;
    est.iter()
        .zip(biases)
        .map(|(e, b)| {
            [
                (e.bias[0] - est_mean(0)) - (b[0] - mean(0)),
                ((e.bias[1] - est_mean(1)) - (b[1] - mean(1))).to_degrees(),
                e.sigma[0],
                e.sigma[1].to_degrees(),
                e.bias[0] - b[0],
                (e.bias[1] - b[1]).to_degrees(),
            ]
        })
        .collect()
}

fn run_frames(
    config: TrackerConfig,
    plots: &[Plot],
    converged_at: &mut Option<f64>,
) -> Result<(Vec<Frame>, Tracker), SimError> {
    let mut tracker = Tracker::new(config)?;
    let mut frames = Vec::new();
    tracker.process_with(plots, true, &mut |tr: &Tracker| {
        let t = tr.last_time().unwrap_or(f64::NAN);
        if converged_at.is_none() && tr.biases().iter().all(|b| b.converged) {
            *converged_at = Some(t);
        }
        frames.push(frame_of(tr));
        std::ops::ControlFlow::Continue(())
    })?;
    Ok((frames, tracker))
}

/// The scenes: every radar biased at random, for 2, 3 and 4 radars; then
/// two radars, the second biased by a fixed amount (range m, azimuth °).
const SCENES: [(usize, Option<[f64; 2]>); 5] = [
    (2, None),
    (3, None),
    (4, None),
    (2, Some([300.0, 0.3])),
    (2, Some([600.0, 0.6])),
];

fn scene_name(n: usize, fixed: Option<[f64; 2]>) -> String {
    match fixed {
        None => format!("{n}, all biased"),
        Some([r, a]) => format!("{n}, one at +{r} m +{a}°"),
    }
}

fn one_run(
    n: usize,
    fixed: Option<[f64; 2]>,
    n_targets: usize,
    duration: f64,
    rng: &mut SimRng,
) -> Result<RunOut, SimError> {
    let radars = radars(n, rng);
    let (truth, _): (Vec<_>, Vec<bool>) = targets(n_targets, duration, rng)?.into_iter().unzip();
    let (plots, _) = scan_plots(&radars, &truth, duration, rng)?;
    let biases: Vec<[f64; 2]> = (0..n)
        .map(|r| match fixed {
            Some([range, az]) if r == 1 => [range, az.to_radians()],
            Some(_) => [0.0, 0.0],
            None => [
                rng.random_range(-RANGE_BIAS_M..RANGE_BIAS_M),
                rng.random_range(-AZIMUTH_BIAS_DEG..AZIMUTH_BIAS_DEG)
                    .to_radians(),
            ],
        })
        .collect();
    let biased: Vec<Plot> = plots
        .iter()
        .map(|p| {
            let mut q = *p;
            q.range = (q.range + biases[p.radar][0]).max(0.0);
            q.azimuth += biases[p.radar][1];
            q
        })
        .collect();
    let specs: Vec<RadarSpec> = radars.iter().map(|r| radar_spec(r, 1e-9)).collect();
    let config = TrackerConfig::new(2, specs);
    let mut unregistered = config.clone();
    unregistered.registration.enabled = false;
    let mut parallel = config.clone();
    parallel.set_mode(Mode::Parallel);
    let hours = duration / 3600.0;
    let mut out = RunOut::default();
    let mut converged_at = None;
    for (m, (cfg, data)) in [
        (config.clone(), &plots),
        (unregistered, &biased),
        (config, &biased),
        (parallel.clone(), &plots),
        (parallel, &biased),
    ]
    .into_iter()
    .enumerate()
    {
        let mut at = None;
        let (frames, tracker) = run_frames(cfg, data, &mut at)?;
        let scores = score_frames(&frames, &truth, CUTOFF_M)?;
        let late: Vec<_> = scores
            .iter()
            .filter(|f| f.t >= SETTLED_S)
            .cloned()
            .collect();
        let settled = summarise(&late, &truth);
        let s = summarise(&scores, &truth);
        let samples = s.samples.max(1) as f64;
        let nframes = s.frames.max(1) as f64;
        out.figures[m] = Figures {
            rmse: rmse(s.error_sq, s.samples),
            rmse_settled: rmse(settled.error_sq, settled.samples),
            nees: s.nees / samples,
            gospa: s.gospa / nframes,
            false_per_h: s.false_tracks as f64 / hours,
            duplicates: s.duplicates as f64 / nframes,
            breaks_per_h: s.breaks as f64 / hours,
        };
        if m == 2 {
            converged_at = at;
            out.errors = bias_errors(&tracker, &biases);
        } else if m == 4 {
            out.converged_parallel = at;
            out.errors_parallel = bias_errors(&tracker, &biases);
        }
    }
    out.converged_at = converged_at;
    Ok(out)
}

/// A row of the estimates' table: errors as [`RunOut::errors`], the
/// convergence times of the runs that converged.
fn bias_row(scene: String, errors: &[[f64; 6]], converged: &[f64], runs: usize) -> Vec<String> {
    let k = errors.len().max(1) as f64;
    let rms = |i: usize| (errors.iter().map(|e| e[i] * e[i]).sum::<f64>() / k).sqrt();
    let nees = |i: usize, s: usize| {
        errors
            .iter()
            .map(|e| (e[i] / e[s].max(1e-12)).powi(2))
            .sum::<f64>()
            / k
    };
    let within = |i: usize, s: usize| {
        100.0 * errors.iter().filter(|e| e[i].abs() <= 2.0 * e[s]).count() as f64 / k
    };
    vec![
        scene,
        format!("{:.1} / {:.3}", rms(0), rms(1)),
        format!("{:.1} / {:.3}", rms(4), rms(5)),
        format!(
            "{:.1} / {:.3}",
            errors.iter().map(|e| e[2]).sum::<f64>() / k,
            errors.iter().map(|e| e[3]).sum::<f64>() / k
        ),
        format!("{:.2} / {:.2}", nees(4, 2), nees(5, 3)),
        format!("{:.0} % / {:.0} %", within(4, 2), within(5, 3)),
        if converged.is_empty() {
            format!("0 of {runs}")
        } else {
            format!(
                "{} of {runs}, median {:.0} s",
                converged.len(),
                median(converged)
            )
        },
    ]
}

/// Runs the experiment.
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let targets = opts.targets.unwrap_or(DEFAULT_TARGETS).max(1);
    let scans = opts.scans.unwrap_or(DEFAULT_SCANS).max(2);
    let duration = SCAN_UNIT_S * scans as f64;
    let mut csv = String::from(
        "scene,run,method,rmse_m,mean_nees,gospa_m,false_tracks_per_h,duplicates_per_frame,track_breaks_per_h\n",
    );
    let mut rows = Vec::new();
    let mut bias_rows = Vec::new();
    let mut series: Vec<Series> = METHODS
        .iter()
        .map(|m| Series {
            name: (*m).into(),
            points: Vec::new(),
            dashed: false,
        })
        .collect();
    for &(n, fixed) in &SCENES {
        let scene = scene_name(n, fixed);
        let per_run = run_batch(&opts.runner, &format!("registration {scene}"), |_, rng| {
            one_run(n, fixed, targets, duration, rng)
        });
        let per_run: Vec<RunOut> = per_run.into_iter().collect::<Result<_, _>>()?;
        for (r, run) in per_run.iter().enumerate() {
            for (m, f) in run.figures.iter().enumerate() {
                let _ = writeln!(
                    csv,
                    "{scene},{r},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}",
                    METHODS[m],
                    f.rmse,
                    f.nees,
                    f.gospa,
                    f.false_per_h,
                    f.duplicates,
                    f.breaks_per_h
                );
            }
        }
        let pm = |m: usize, g: fn(&Figures) -> f64, digits: usize| {
            let (v, se) = mean_se(&per_run.iter().map(|r| g(&r.figures[m])).collect::<Vec<_>>());
            format!("{v:.digits$} ± {se:.digits$}")
        };
        for m in 0..METHODS.len() {
            rows.push(vec![
                scene.clone(),
                METHODS[m].into(),
                pm(m, |f| f.rmse, 1),
                pm(m, |f| f.rmse_settled, 1),
                pm(m, |f| f.nees, 2),
                pm(m, |f| f.gospa, 0),
                pm(m, |f| f.false_per_h, 1),
                pm(m, |f| f.duplicates, 2),
                pm(m, |f| f.breaks_per_h, 1),
            ]);
            if fixed.is_some() {
                continue;
            }
            series[m].points.push((
                n as f64,
                mean_se(
                    &per_run
                        .iter()
                        .map(|r| r.figures[m].rmse)
                        .collect::<Vec<_>>(),
                )
                .0,
            ));
        }
        for parallel in [false, true] {
            let errors: Vec<[f64; 6]> = per_run
                .iter()
                .flat_map(|r| {
                    if parallel {
                        r.errors_parallel.clone()
                    } else {
                        r.errors.clone()
                    }
                })
                .collect();
            let converged: Vec<f64> = per_run
                .iter()
                .filter_map(|r| {
                    if parallel {
                        r.converged_parallel
                    } else {
                        r.converged_at
                    }
                })
                .collect();
            let name = if parallel {
                format!("{scene}, parallel mode")
            } else {
                scene.clone()
            };
            bias_rows.push(bias_row(name, &errors, &converged, per_run.len()));
        }
    }
    let mut md = String::from("# registration (radar biases estimated in the tracker)\n\n");
    let _ = writeln!(
        md,
        "{targets} targets (half turning at 2–4 m/s²) over {duration} s, 2D Doppler radars 20 km \
         from the centre (periods 4–6 s, random phases, P_D 0.9, 3 false plots per scan), every \
         radar biased at random (range in ±{RANGE_BIAS_M} m, azimuth in ±{AZIMUTH_BIAS_DEG}°), or \
         two radars of which the second is biased by a fixed amount; the tracker's defaults (IMM, \
         serial), and parallel mode in the last two rows. {} runs per scene from seed {}.\n",
        opts.runner.runs, opts.runner.seed
    );
    md.push_str(&markdown_table(
        &[
            "scene (radars)",
            "tracker",
            "position RMSE (m)",
            "RMSE after 100 s (m)",
            "mean NEES (2 dof)",
            "GOSPA (m)",
            "false tracks per hour",
            "duplicate tracks per frame",
            "track breaks per hour",
        ],
        &rows,
    ));
    md.push_str(
        "\nThe registered tracker's final estimates against the truth, range (m) / azimuth (°): \
         relative to the network's mean bias, absolute, and the absolute error against the \
         reported σ (every radar converged in every run):\n\n",
    );
    md.push_str(&markdown_table(
        &[
            "scene (radars)",
            "RMS error (relative)",
            "RMS error (absolute)",
            "mean reported σ",
            "mean (absolute error/σ)² (1 if consistent)",
            "absolute error within 2σ",
            "runs with every radar converged",
        ],
        &bias_rows,
    ));
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![(
            "rmse".into(),
            LinePlot {
                title: "registration: position RMSE".into(),
                x_label: "radars".into(),
                y_label: "RMSE (m)".into(),
                series,
                y_range: None,
            }
            .to_svg(),
        )],
    })
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s[s.len() / 2]
}
