//! `seed001-plot-association`: seed 001 Fig. 3 — plot-to-plot association
//! across two radars by global nearest neighbour, and the ML ("parallel
//! compression") fusion of the associated plots (step 4,
//! [`algo::tracking::plot_association::associate_and_fuse`]).
//!
//! The patent: three targets in crossing motion, radar 1 noise "60 m × 60 m",
//! radar 2 "30 m × 30 m", plots aligned in space and time. We read the noise
//! as σ = 60 m and 30 m per Cartesian axis and put it directly into the
//! Cartesian plots (R = σ²I), as the patent's statement is Cartesian; no
//! polar radar is simulated. The patent gives no geometry, speed or scan
//! period; ours: the targets fly at 50 m/s on headings 0°, 60° and 120°
//! (`truth::crossing`) through one point 50 km north of the origin, which
//! they reach at the middle scan; 51 scans 2 s apart (100 s). Neighbouring
//! targets are then 50 m·|t − t_cross|/s apart, so the 99 % gate
//! (radius ≈ 3.03·√(60² + 30²) = 204 m) holds two or three targets for
//! about ±4 s about the crossing. P_D = 1, no clutter (the patent has none).
//!
//! Measures, per target and scan: **correctly paired** when its radar-1 and
//! radar-2 plots end in the same fused plot; **mis-paired** when either is
//! fused with another target's plot; **split** otherwise (both left alone).
//! Per fused group (a fused plot with both radars): **pure** when both
//! plots are the same target's. RMSE: each radar's plots, the fused plots of
//! correctly paired targets, and "as output" — the output plot holding the
//! target's radar-1 plot, whatever it was fused with — all against the truth.
//! `associate_and_fuse` returns fused plots, not their members; members are
//! recovered exactly: the first clusters are the radar-1 plots in input
//! order, and a two-radar cluster's radar-2 member is the plot whose ML
//! fusion with that radar-1 plot reproduces the cluster.

use std::fmt::Write as _;

use nalgebra::{DMatrix, DVector};
use rand::RngExt;
use rand::seq::SliceRandom;
use rand_distr::StandardNormal;

use super::{EvalOptions, f4, mean_se};
use crate::metrics::rmse;
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::truth::{crossing, cv_step};
use crate::{SimError, SimRng};
use algo::tracking::CartesianPlot;
use algo::tracking::plot_association::{associate_and_fuse, fuse};

/// Position σ per axis of radar 1 and radar 2 (m): the patent's figures.
pub const SIGMA_M: [f64; 2] = [60.0, 30.0];
const PERIOD_S: f64 = 2.0;
const SPEED: f64 = 50.0;
const DEFAULT_SCANS: usize = 51;
const DEFAULT_TARGETS: usize = 3;
const GATE_PROBABILITY: f64 = 0.99;

/// Per-scan sums of one run.
#[derive(Debug, Clone, Default)]
struct ScanSums {
    /// Target-scans: correctly paired, mis-paired, split.
    correct: usize,
    wrong: usize,
    split: usize,
    /// Fused groups with both radars, and the pure ones.
    groups: usize,
    pure: usize,
    /// Σ squared errors: radar 1 plots, radar 2 plots, fused plots of
    /// correct pairs (and their number), output plot of each target.
    sq_r1: f64,
    sq_r2: f64,
    sq_fused: f64,
    n_fused: usize,
    sq_output: f64,
    n: usize,
}

impl ScanSums {
    fn add(&mut self, o: &ScanSums) {
        self.correct += o.correct;
        self.wrong += o.wrong;
        self.split += o.split;
        self.groups += o.groups;
        self.pure += o.pure;
        self.sq_r1 += o.sq_r1;
        self.sq_r2 += o.sq_r2;
        self.sq_fused += o.sq_fused;
        self.n_fused += o.n_fused;
        self.sq_output += o.sq_output;
        self.n += o.n;
    }

    fn rate(&self, k: usize) -> f64 {
        k as f64 / self.n.max(1) as f64
    }
}

/// Runs the experiment (3 targets, 51 scans unless overridden).
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let targets = opts.targets.unwrap_or(DEFAULT_TARGETS).max(1);
    let scans = opts.scans.unwrap_or(DEFAULT_SCANS).max(1);
    let t_cross = PERIOD_S * (scans - 1) as f64 / 2.0;
    let started = std::time::Instant::now();
    let per_run = run_batch(&opts.runner, "seed001-plot-association", |_, rng| {
        one_run(targets, scans, t_cross, rng)
    });
    let per_run: Vec<Vec<ScanSums>> = per_run.into_iter().collect::<Result<_, _>>()?;
    let wall = started.elapsed().as_secs_f64();

    let mut csv = String::from(
        "run,correct_pair_rate,mispaired_rate,split_rate,group_purity,rmse_radar1_m,rmse_radar2_m,rmse_fused_m,rmse_output_m\n",
    );
    let mut pooled = vec![ScanSums::default(); scans];
    let mut per_run_totals = Vec::new();
    for (r, run) in per_run.iter().enumerate() {
        let mut tot = ScanSums::default();
        for (k, s) in run.iter().enumerate() {
            tot.add(s);
            pooled[k].add(s);
        }
        let purity = tot.pure as f64 / tot.groups.max(1) as f64;
        let _ = writeln!(
            csv,
            "{r},{:.6},{:.6},{:.6},{purity:.6},{:.3},{:.3},{:.3},{:.3}",
            tot.rate(tot.correct),
            tot.rate(tot.wrong),
            tot.rate(tot.split),
            rmse(tot.sq_r1, tot.n),
            rmse(tot.sq_r2, tot.n),
            rmse(tot.sq_fused, tot.n_fused),
            rmse(tot.sq_output, tot.n),
        );
        per_run_totals.push(tot);
    }
    let stat = |f: &dyn Fn(&ScanSums) -> f64| {
        let v: Vec<f64> = per_run_totals.iter().map(f).collect();
        let (m, se) = mean_se(&v);
        format!("{} ± {}", f4(m), f4(se))
    };
    let mut all = ScanSums::default();
    for s in &pooled {
        all.add(s);
    }

    let mut md = String::from("# seed001-plot-association (patent Fig. 3)\n\n");
    let _ = writeln!(
        md,
        "{targets} targets crossing at {SPEED} m/s (headings k·180°/{targets}) through one point at \
         t = {t_cross} s; {scans} scans {PERIOD_S} s apart; Cartesian plot noise σ = {} m (radar 1) \
         and {} m (radar 2) per axis, aligned in space and time, P_D = 1, no clutter; GNN \
         plot-to-plot association with a {} χ² gate and ML fusion (`associate_and_fuse`). \
         {} runs from seed {}; wall time {wall:.2} s.\n",
        SIGMA_M[0], SIGMA_M[1], GATE_PROBABILITY, opts.runner.runs, opts.runner.seed
    );
    md.push_str(&markdown_table(
        &["measure", "mean ± SE over runs", "what it counts"],
        &[
            vec![
                "correctly paired target-scans".into(),
                stat(&|s| s.rate(s.correct)),
                "a target's two plots in one fused plot".into(),
            ],
            vec![
                "mis-paired target-scans".into(),
                stat(&|s| s.rate(s.wrong)),
                "a target's plot fused with another target's".into(),
            ],
            vec![
                "split target-scans".into(),
                stat(&|s| s.rate(s.split)),
                "both plots left unfused".into(),
            ],
            vec![
                "pure fused groups".into(),
                stat(&|s| s.pure as f64 / s.groups.max(1) as f64),
                "fused plots whose two members are one target".into(),
            ],
        ],
    ));
    let fused_theory = (2.0 * SIGMA_M[0].powi(2) * SIGMA_M[1].powi(2)
        / (SIGMA_M[0].powi(2) + SIGMA_M[1].powi(2)))
    .sqrt();
    md.push('\n');
    md.push_str(&markdown_table(
        &["plots", "position RMSE (m), pooled", "theory (m)"],
        &[
            vec![
                "radar 1".into(),
                format!("{:.1}", rmse(all.sq_r1, all.n)),
                format!("{:.1}", SIGMA_M[0] * 2f64.sqrt()),
            ],
            vec![
                "radar 2".into(),
                format!("{:.1}", rmse(all.sq_r2, all.n)),
                format!("{:.1}", SIGMA_M[1] * 2f64.sqrt()),
            ],
            vec![
                "fused (correctly paired)".into(),
                format!("{:.1}", rmse(all.sq_fused, all.n_fused)),
                format!("{fused_theory:.1}"),
            ],
            vec![
                "output plot holding the radar-1 plot".into(),
                format!("{:.1}", rmse(all.sq_output, all.n)),
                "—".into(),
            ],
        ],
    ));
    // Pairing near the crossing, by |t − t_cross|.
    let mut near = Vec::new();
    let mut dts: Vec<f64> = (0..scans)
        .map(|k| (PERIOD_S * k as f64 - t_cross).abs())
        .collect();
    dts.sort_by(f64::total_cmp);
    dts.dedup();
    for dt in dts.iter().take(6) {
        let mut s = ScanSums::default();
        for (k, p) in pooled.iter().enumerate() {
            if ((PERIOD_S * k as f64 - t_cross).abs() - dt).abs() < 1e-9 {
                s.add(p);
            }
        }
        near.push(vec![
            format!("{dt}"),
            format!("{:.0}", SPEED * dt),
            f4(s.rate(s.correct)),
            f4(s.rate(s.wrong)),
            f4(s.rate(s.split)),
            format!("{:.1}", rmse(s.sq_output, s.n)),
        ]);
    }
    md.push_str("\nNear the crossing (pooled over runs and targets):\n\n");
    md.push_str(&markdown_table(
        &[
            "|t − t_cross| (s)",
            "neighbour separation (m)",
            "correctly paired",
            "mis-paired",
            "split",
            "output RMSE (m)",
        ],
        &near,
    ));
    let _ = writeln!(
        md,
        "\nThe patent shows the associated plots (Fig. 3) and gives no number. Theory: each \
         radar's 2D RMSE is σ√2; the ML fusion of σ₁ = {} m and σ₂ = {} m has σ = {:.1} m per axis \
         ({fused_theory:.1} m in 2D).",
        SIGMA_M[0],
        SIGMA_M[1],
        fused_theory / 2f64.sqrt()
    );

    let times: Vec<f64> = (0..scans).map(|k| PERIOD_S * k as f64).collect();
    let series_of = |name: &str, f: &dyn Fn(&ScanSums) -> f64, dashed: bool| Series {
        name: name.into(),
        points: pooled.iter().zip(&times).map(|(s, &t)| (t, f(s))).collect(),
        dashed,
    };
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![
            (
                "pairing".into(),
                LinePlot {
                    title: "seed 001 Fig. 3: plot-to-plot association against time".into(),
                    x_label: "time (s)".into(),
                    y_label: "fraction of target-scans".into(),
                    series: vec![
                        series_of("correct", &|s| s.rate(s.correct), false),
                        series_of("mis-paired", &|s| s.rate(s.wrong), false),
                        series_of("split", &|s| s.rate(s.split), false),
                    ],
                    y_range: Some((0.0, 1.0)),
                }
                .to_svg(),
            ),
            (
                "rmse".into(),
                LinePlot {
                    title: "seed 001 Fig. 3: plot position RMSE".into(),
                    x_label: "time (s)".into(),
                    y_label: "RMSE (m)".into(),
                    series: vec![
                        series_of("radar 1", &|s| rmse(s.sq_r1, s.n), true),
                        series_of("radar 2", &|s| rmse(s.sq_r2, s.n), true),
                        series_of(
                            "fused, correct pairs",
                            &|s| rmse(s.sq_fused, s.n_fused),
                            false,
                        ),
                        series_of("output", &|s| rmse(s.sq_output, s.n), false),
                    ],
                    y_range: None,
                }
                .to_svg(),
            ),
        ],
    })
}

/// A plot of `radar` at `truth` with noise σ per axis.
fn noisy_plot(
    t: f64,
    truth: [f64; 2],
    sigma: f64,
    radar: usize,
    rng: &mut SimRng,
) -> CartesianPlot {
    let mut g = || -> f64 { rng.sample(StandardNormal) };
    CartesianPlot {
        t,
        z: DVector::from_vec(vec![truth[0] + sigma * g(), truth[1] + sigma * g()]),
        r: DMatrix::identity(2, 2) * sigma * sigma,
        radars: vec![radar],
        measured: None,
        range_rates: Vec::new(),
        velocity: Vec::new(),
    }
}

fn sq_dist(z: &DVector<f64>, x: [f64; 2]) -> f64 {
    (z[0] - x[0]).powi(2) + (z[1] - x[1]).powi(2)
}

fn one_run(
    targets: usize,
    scans: usize,
    t_cross: f64,
    rng: &mut SimRng,
) -> Result<Vec<ScanSums>, SimError> {
    let plans = crossing(targets, [0.0, 50_000.0, 0.0], 0.0, t_cross, SPEED);
    let mut out = Vec::with_capacity(scans);
    for k in 0..scans {
        let t = PERIOD_S * k as f64;
        let truth: Vec<[f64; 2]> = plans
            .iter()
            .map(|p| {
                let s = cv_step(&p.initial, t - p.birth);
                [s[0], s[2]]
            })
            .collect();
        // Each radar's plots in a random order (origin[r][i]: target of plot i).
        let mut origin = [Vec::new(), Vec::new()];
        let mut plots: [Vec<CartesianPlot>; 2] = [Vec::new(), Vec::new()];
        for r in 0..2 {
            let mut order: Vec<usize> = (0..targets).collect();
            order.shuffle(rng);
            for &i in &order {
                plots[r].push(noisy_plot(t, truth[i], SIGMA_M[r], r, rng));
            }
            origin[r] = order;
        }
        let input: Vec<CartesianPlot> = plots.iter().flatten().cloned().collect();
        let fused = associate_and_fuse(&input, GATE_PROBABILITY)?;
        let members = members(&plots, &fused)?;

        let mut s = ScanSums::default();
        // partner[i]: the radar-2 plot fused with radar-1 plot i.
        let mut partner_of_r2 = vec![None; targets];
        for (i, m) in members.iter().enumerate() {
            if let Some(j) = m {
                partner_of_r2[*j] = Some(i);
                s.groups += 1;
                if origin[0][i] == origin[1][*j] {
                    s.pure += 1;
                }
            }
        }
        for (target, &x) in truth.iter().enumerate() {
            let i = origin[0]
                .iter()
                .position(|&o| o == target)
                .expect("one plot");
            let j = origin[1]
                .iter()
                .position(|&o| o == target)
                .expect("one plot");
            s.n += 1;
            s.sq_r1 += sq_dist(&plots[0][i].z, x);
            s.sq_r2 += sq_dist(&plots[1][j].z, x);
            s.sq_output += sq_dist(&fused[i].z, x);
            match (members[i], partner_of_r2[j]) {
                (Some(jj), _) if jj == j => {
                    s.correct += 1;
                    s.sq_fused += sq_dist(&fused[i].z, x);
                    s.n_fused += 1;
                }
                (None, None) => s.split += 1,
                _ => s.wrong += 1,
            }
        }
        out.push(s);
    }
    Ok(out)
}

/// For each radar-1 plot (cluster i of the output), the radar-2 plot fused
/// with it, if any (see the module header).
fn members(
    plots: &[Vec<CartesianPlot>; 2],
    fused: &[CartesianPlot],
) -> Result<Vec<Option<usize>>, SimError> {
    let n1 = plots[0].len();
    let mut taken = vec![false; plots[1].len()];
    // Radar-2 plots left alone follow the radar-1 clusters, in input order.
    for single in &fused[n1..] {
        if let Some(j) = plots[1].iter().position(|p| p.z == single.z) {
            taken[j] = true;
        }
    }
    let mut out = vec![None; n1];
    for (i, cluster) in fused[..n1].iter().enumerate() {
        if cluster.radars.len() < 2 {
            continue;
        }
        let mut best: Option<(usize, f64)> = None;
        for (j, p) in plots[1].iter().enumerate() {
            if taken[j] {
                continue;
            }
            let d = sq_dist(&fuse(&plots[0][i], p)?.z, [cluster.z[0], cluster.z[1]]);
            if best.is_none_or(|(_, b)| d < b) {
                best = Some((j, d));
            }
        }
        match best {
            Some((j, d)) if d < 1e-6 => {
                taken[j] = true;
                out[i] = Some(j);
            }
            _ => {
                return Err(SimError::InvalidConfig(
                    "a fused plot matches no radar-2 plot".into(),
                ));
            }
        }
    }
    Ok(out)
}
