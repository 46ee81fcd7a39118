//! Late and reordered plots in a stream: the seed-001 Monte Carlo scene
//! (three unsynchronised Doppler radars, turning targets, clutter,
//! P_D = 0.9) with the plots reaching the fusion centre late, streamed in
//! 1-s batches of arrival.
//!
//! Arrival: radar 1's plots 0.3–0.8 s after their time, radar 2's 1–3.5 s,
//! radar 3's 0.5–2 s (uniform per plot), and 3 % of all plots held up 6–10
//! s more (a link hiccup), at most 13.5 s late.
//!
//! Three trackers with the service's defaults (IMM, serial):
//! - **batch**: one call over every plot sorted by time (the batch
//!   endpoint), the reference;
//! - **before**: the session of earlier releases, a `Tracker` fed each
//!   batch as it arrives: a plot older than the last processed frame is
//!   dropped, and a frame is processed only when a later frame's plot has
//!   arrived (flushed once at the end);
//! - **reprocessing**: what the session's default (auto) does at this
//!   scale (its replays stay within the bound), a `LagWindow` (lag 15 s)
//!   under `LatePolicy::Reprocess`: after every batch its picture holds
//!   every plot received, bit for bit the batch call's;
//! - **retrodiction**: a `LagWindow` under
//!   `LatePolicy::Retrodict`: a late plot updates the tracks it gates with
//!   where they stand, nothing is replayed.
//!
//! Besides equality, the largest distance of a final track from the batch
//! call's nearest (the tracks matched one to one; a run whose count of
//! tracks differs counts as such).
//!
//! Per run: plots dropped; whether the final tracks equal the batch call's
//! bit for bit (the batch call over the plots in arrival order, sorted by
//! time: plots of equal times keep their order, so the reference is the
//! one a client sending the plots as they arrived would get); position RMSE and mean GOSPA of the output after every
//! batch against the truth at its time (1 km cut-off); the output latency,
//! from a plot's arrival to the end of the batch whose output first uses it
//! (data time: the batch boundary, so at most 1 s when used at once); and
//! the compute time per plot.

use std::fmt::Write as _;
use std::time::Instant;

use algo::tracking::{LagWindow, LatePolicy, Plot, Tracker, TrackerConfig, window};
use rand::RngExt;

use super::seed001_montecarlo::{
    CUTOFF_M, DEFAULT_SCANS, DEFAULT_TARGETS, SCAN_UNIT_S, radars, targets,
};
use super::{EvalOptions, mean_se};
use crate::metrics::rmse;
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario001::{frame_of, radar_spec, run_tracker, scan_plots, score_frames, summarise};
use crate::{SimError, SimRng};

const RADARS: usize = 3;
/// Per-radar delay ranges (s).
const DELAYS: [(f64, f64); RADARS] = [(0.3, 0.8), (1.0, 3.5), (0.5, 2.0)];
const HELD_FRACTION: f64 = 0.03;
const HELD_S: (f64, f64) = (6.0, 10.0);
const BATCH_S: f64 = 1.0;

/// One method's figures in one run.
#[derive(Debug, Clone, Copy, Default)]
struct Figures {
    dropped: f64,
    equal_to_batch: f64,
    rmse: f64,
    gospa: f64,
    latency_mean: f64,
    latency_p95: f64,
    us_per_plot: f64,
    /// Largest distance of a final track from the reference's (m).
    gap_m: f64,
    /// The median distance of a final track from the reference's (m).
    median_gap_m: f64,
    /// Whether the final count of confirmed tracks differs from the
    /// reference's.
    count_differs: f64,
}

const N: usize = 4;
const METHODS: [&str; N] = [
    "batch call (all plots sorted)",
    "earlier releases: tracker fed as plots arrive",
    "lag window (15 s), reprocessing (the default, auto, at this scale)",
    "lag window (15 s), retrodiction",
];

/// The distances of `b`'s confirmed tracks from `a`'s, each matched to the
/// nearest (one to one): the median and the largest; and whether the
/// counts differ.
fn final_gap(a: &Tracker, b: &Tracker) -> (f64, f64, bool) {
    let (ta, tb) = (a.confirmed_tracks(), b.confirmed_tracks());
    let mut taken = vec![false; ta.len()];
    let mut gaps = Vec::with_capacity(tb.len());
    for y in &tb {
        let best = ta
            .iter()
            .enumerate()
            .filter(|(i, _)| !taken[*i])
            .map(|(i, x)| (i, (x.state[0] - y.state[0]).hypot(x.state[2] - y.state[2])))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, d)) = best {
            taken[i] = true;
            gaps.push(d);
        }
    }
    gaps.sort_by(f64::total_cmp);
    let median = if gaps.is_empty() {
        0.0
    } else {
        quantile(&gaps, 0.5)
    };
    (
        median,
        gaps.last().copied().unwrap_or(0.0),
        ta.len() != tb.len(),
    )
}

/// The p-quantile of sorted values.
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() as f64 * p).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

/// How a radar's link delivers its plots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Links {
    /// Each plot delayed independently within its radar's range: a radar's
    /// plots reorder among themselves (a scan arrives in pieces).
    Jittered,
    /// Each radar's plots delayed by the low end of its range, in order (a
    /// link that keeps order, as TCP or one UDP path), the held 3 % aside.
    Fifo,
}

fn one_run(
    n_targets: usize,
    duration: f64,
    links: Links,
    rng: &mut SimRng,
) -> Result<[Figures; N], SimError> {
    let radars = radars(RADARS, rng);
    let (truth, _): (Vec<_>, Vec<bool>) = targets(n_targets, duration, rng)?.into_iter().unzip();
    let (plots, _) = scan_plots(&radars, &truth, duration, rng)?;
    let specs = radars.iter().map(|r| radar_spec(r, 1e-9)).collect();
    let config = TrackerConfig::new(2, specs);

    // Arrivals, then 1-s batches of arrival.
    let mut arrivals: Vec<(f64, Plot)> = plots
        .iter()
        .map(|p| {
            let (lo, hi) = DELAYS[p.radar % RADARS];
            let mut d = rng.random_range(lo..hi);
            if links == Links::Fifo {
                d = lo;
            }
            if rng.random_bool(HELD_FRACTION) {
                d += rng.random_range(HELD_S.0..HELD_S.1);
            }
            (p.t + d, *p)
        })
        .collect();
    arrivals.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut batches: Vec<(f64, Vec<(f64, Plot)>)> = Vec::new();
    for (arrival, p) in arrivals {
        let end = (arrival / BATCH_S).floor() * BATCH_S + BATCH_S;
        match batches.last_mut() {
            Some((e, b)) if *e == end => b.push((arrival, p)),
            _ => batches.push((end, vec![(arrival, p)])),
        }
    }

    let mut out = [Figures::default(); N];
    // The batch call.
    let started = Instant::now();
    let (frames, _) = run_tracker(config.clone(), &plots)?;
    out[0].us_per_plot = 1e6 * started.elapsed().as_secs_f64() / plots.len().max(1) as f64;
    let s = summarise(&score_frames(&frames, &truth, CUTOFF_M)?, &truth);
    out[0].rmse = rmse(s.error_sq, s.samples);
    out[0].gospa = s.gospa / s.frames.max(1) as f64;
    out[0].equal_to_batch = 1.0;
    // The batch call over the plots as they arrived, sorted by time
    // (stably: plots of equal times, a simulated scan's, keep their
    // arrival order, as in the batch endpoint).
    let mut arrived: Vec<Plot> = batches
        .iter()
        .flat_map(|(_, b)| b.iter().map(|(_, p)| *p))
        .collect();
    arrived.sort_by(|a, b| a.t.total_cmp(&b.t));
    let mut reference = Tracker::new(config.clone())?;
    reference.process(&arrived)?;
    reference.flush()?;

    // Before and after, batch by batch.
    let mut before = Tracker::new(config.clone())?;
    let mut windows = [LatePolicy::Reprocess, LatePolicy::Retrodict].map(|policy| {
        LagWindow::with_policy(
            Tracker::new(config.clone()).expect("a valid configuration"),
            window::DEFAULT_MAX_LAG_S,
            policy,
        )
        .expect("a valid lag")
    });
    let mut frames_before = Vec::new();
    let mut frames_after = [Vec::new(), Vec::new()];
    let mut seconds_before = 0.0;
    let mut seconds_after = [0.0, 0.0];
    // Plots waiting to be used by `before`: (arrival, t).
    let mut waiting: Vec<(f64, f64)> = Vec::new();
    let mut latency_before = Vec::new();
    let mut latency_after = [Vec::new(), Vec::new()];
    let mut dropped_after = [0usize; 2];
    for (i, (end, batch)) in batches.iter().enumerate() {
        let plots: Vec<Plot> = batch.iter().map(|(_, p)| *p).collect();
        let last = i + 1 == batches.len();
        let started = Instant::now();
        let report =
            before.process_with(&plots, last, &mut |_| std::ops::ControlFlow::Continue(()))?;
        seconds_before += started.elapsed().as_secs_f64();
        let late: std::collections::HashSet<usize> = report.late.iter().copied().collect();
        waiting.extend(
            batch
                .iter()
                .enumerate()
                .filter(|(k, _)| !late.contains(k))
                .map(|(_, (a, p))| (*a, p.t)),
        );
        let processed = before.last_time().unwrap_or(f64::NEG_INFINITY);
        waiting.retain(|&(arrival, t)| {
            if t <= processed {
                latency_before.push(end - arrival);
                false
            } else {
                true
            }
        });
        frames_before.push(frame_of(&before));

        for (w, after) in windows.iter_mut().enumerate() {
            let started = Instant::now();
            let push = after.push(&plots)?;
            seconds_after[w] += started.elapsed().as_secs_f64();
            dropped_after[w] += push.late.len();
            latency_after[w].extend(
                batch
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| !push.late.contains(k))
                    .map(|(_, (a, _))| end - a),
            );
            frames_after[w].push(frame_of(after.picture()));
        }
    }
    let n = plots.len().max(1) as f64;
    let [frames_reprocess, frames_retro] = frames_after;
    let [latency_reprocess, latency_retro] = &mut latency_after;
    for (k, (frames, seconds, latency)) in [
        (frames_before, seconds_before, &mut latency_before),
        (frames_reprocess, seconds_after[0], latency_reprocess),
        (frames_retro, seconds_after[1], latency_retro),
    ]
    .into_iter()
    .enumerate()
    {
        let s = summarise(&score_frames(&frames, &truth, CUTOFF_M)?, &truth);
        latency.sort_by(f64::total_cmp);
        let f = &mut out[k + 1];
        f.rmse = rmse(s.error_sq, s.samples);
        f.gospa = s.gospa / s.frames.max(1) as f64;
        f.us_per_plot = 1e6 * seconds / n;
        f.latency_mean = latency.iter().sum::<f64>() / latency.len().max(1) as f64;
        f.latency_p95 = quantile(latency, 0.95);
    }
    out[1].dropped = before.counters().late as f64;
    out[1].equal_to_batch = f64::from(u8::from(before == reference));
    let (median, gap, differs) = final_gap(&before, &reference);
    out[1].median_gap_m = median;
    out[1].gap_m = gap;
    out[1].count_differs = f64::from(u8::from(differs));
    for (w, after) in windows.iter().enumerate() {
        let f = &mut out[w + 2];
        f.dropped = dropped_after[w] as f64;
        f.equal_to_batch = f64::from(u8::from(after.picture() == &reference));
        let (median, gap, differs) = final_gap(after.picture(), &reference);
        f.median_gap_m = median;
        f.gap_m = gap;
        f.count_differs = f64::from(u8::from(differs));
    }
    Ok(out)
}

/// Runs the experiment (every plot jittered within its radar's delays).
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    run_with(opts, Links::Jittered)
}

/// Runs the experiment with in-order links (`late-plots-fifo`).
pub fn run_fifo(opts: &EvalOptions) -> Result<Report, SimError> {
    run_with(opts, Links::Fifo)
}

fn run_with(opts: &EvalOptions, links: Links) -> Result<Report, SimError> {
    let targets = opts.targets.unwrap_or(DEFAULT_TARGETS).max(1);
    let scans = opts.scans.unwrap_or(DEFAULT_SCANS).max(2);
    let duration = SCAN_UNIT_S * scans as f64;
    let started = Instant::now();
    let per_run = run_batch(&opts.runner, "late-plots", |_, rng| {
        one_run(targets, duration, links, rng)
    });
    let per_run: Vec<[Figures; N]> = per_run.into_iter().collect::<Result<_, _>>()?;
    // Compute times are in the Markdown only: the CSV is the same for any
    // thread count.
    let mut csv = String::from(
        "run,method,dropped,equal_to_batch,rmse_m,gospa_m,latency_mean_s,latency_p95_s,median_gap_m,gap_m,count_differs\n",
    );
    for (r, figures) in per_run.iter().enumerate() {
        for (m, f) in figures.iter().enumerate() {
            let _ = writeln!(
                csv,
                "{r},{},{},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{}",
                METHODS[m],
                f.dropped,
                f.equal_to_batch,
                f.rmse,
                f.gospa,
                f.latency_mean,
                f.latency_p95,
                f.median_gap_m,
                f.gap_m,
                f.count_differs,
            );
        }
    }
    let pm = |m: usize, g: fn(&Figures) -> f64, digits: usize| {
        let (v, se) = mean_se(&per_run.iter().map(|f| g(&f[m])).collect::<Vec<_>>());
        format!("{v:.digits$} ± {se:.digits$}")
    };
    let rows: Vec<Vec<String>> = (0..N)
        .map(|m| {
            let equal: f64 = per_run.iter().map(|f| f[m].equal_to_batch).sum();
            let differs: f64 = per_run.iter().map(|f| f[m].count_differs).sum();
            let mut gaps: Vec<f64> = per_run.iter().map(|f| f[m].gap_m).collect();
            gaps.sort_by(f64::total_cmp);
            vec![
                METHODS[m].to_string(),
                pm(m, |f| f.dropped, 1),
                format!("{equal:.0} of {}", per_run.len()),
                if m == 0 {
                    "–".into()
                } else {
                    format!(
                        "{} / {:.1} / {:.1} ({differs:.0} runs)",
                        pm(m, |f| f.median_gap_m, 1),
                        quantile(&gaps, 0.5),
                        quantile(&gaps, 1.0)
                    )
                },
                pm(m, |f| f.rmse, 1),
                pm(m, |f| f.gospa, 0),
                if m == 0 {
                    "–".into()
                } else {
                    format!(
                        "{} / {}",
                        pm(m, |f| f.latency_mean, 2),
                        pm(m, |f| f.latency_p95, 2)
                    )
                },
                pm(m, |f| f.us_per_plot, 1),
            ]
        })
        .collect();
    let wall = started.elapsed().as_secs_f64();
    let (title, arrival) = match links {
        Links::Jittered => (
            "late-plots (a stream of late and reordered plots)",
            "Plots arrive 0.3–0.8 s (radar 1), 1–3.5 s (radar 2) and 0.5–2 s (radar 3) after \
             their time, each independently (a radar's plots reorder)",
        ),
        Links::Fifo => (
            "late-plots-fifo (late plots over links that keep each radar's order)",
            "Plots arrive 0.3 s (radar 1), 1 s (radar 2) and 0.5 s (radar 3) after their time, \
             in order within each radar",
        ),
    };
    let mut md = format!("# {title}\n\n");
    let _ = writeln!(
        md,
        "{targets} targets (half turning at 2–4 m/s²) over {duration} s, {RADARS} Doppler radars \
         (periods 4–6 s, random phases, P_D 0.9, clutter), the tracker's defaults. {arrival}, \
         3 % of them 6–10 s more, in {BATCH_S}-s batches of arrival. {} runs from seed {}; \
         wall time {wall:.1} s.\n",
        opts.runner.runs, opts.runner.seed
    );
    md.push_str(&markdown_table(
        &[
            "tracker",
            "plots dropped per run",
            "final tracks equal to the batch call's",
            "final tracks' distance from the batch call's: median track (mean over runs) / largest, median run / largest, worst run (m) (runs with another count of tracks)",
            "position RMSE (m)",
            "GOSPA (m)",
            "latency from arrival to output, mean / p95 (s)",
            "compute per plot (µs)",
        ],
        &rows,
    ));
    let _ = writeln!(
        md,
        "\nRMSE and GOSPA score the output after every batch (the batch call: after every frame) \
         against the truth at its time. Latency is data time, to the end of the batch whose \
         output first uses the plot (at most {BATCH_S} s when used at once). ± is one standard \
         error over runs."
    );
    let series = (0..N)
        .map(|m| Series {
            name: METHODS[m].into(),
            points: per_run
                .iter()
                .enumerate()
                .map(|(r, f)| (r as f64, f[m].gospa))
                .collect(),
            dashed: m == 0,
        })
        .collect();
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![(
            "gospa".into(),
            LinePlot {
                title: "late plots: mean GOSPA per run (c = 1 km)".into(),
                x_label: "run".into(),
                y_label: "GOSPA (m)".into(),
                series,
                y_range: None,
            }
            .to_svg(),
        )],
    })
}
