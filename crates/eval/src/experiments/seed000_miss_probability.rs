//! `seed000-miss-probability`: a Monte Carlo check of seed 000 eq. 23.
//!
//! For every target, the pair of its local tracks (node 1, node 2) gives
//! per scan the weighted statistic α_ij(l) = d'(P_i + P_j)⁻¹d (eq. 10,
//! [`algo::gaussian::mahalanobis_sq`]), tested against
//! δ = χ²₄(0.95) (eq. 14, [`algo::gating::chi2_threshold`]). We
//! measure (a) the per-sample exceedance rate against the nominal α = 0.05,
//! and (b) the miss rate of the L/R rules 3/4 and 6/8 over every window of R
//! consecutive scans against eq. 23
//! ([`algo::correlation::rules::miss_probability`]).
//!
//! Eq. 23 assumes the R samples are independent and each exceeds δ with
//! probability α. Neither holds exactly for filtered tracks: successive
//! estimates share most of their information (the errors are correlated in
//! time), and the common process noise correlates the two nodes' errors
//! (P_ij ≠ 0), so P_i + P_j is not the covariance of d. To separate the two
//! effects the experiment also computes the statistic with the
//! cross-covariance of Bar-Shalom (seed 000 eqs. 12–13),
//! β = d'(P_i + P_j − P_ij − P_ij')⁻¹d, and evaluates eq. 23 at the
//! *measured* per-sample rate as well as at 0.05.

use std::fmt::Write as _;

use nalgebra::{DMatrix, DVector};

use super::{EvalOptions, f4, mean_se};
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario000::{Seed000Scene, generate};
use crate::tracker::position_h;
use crate::{SimError, SimRng};
use algo::correlation::rules::{LrRule, miss_probability};
use algo::gating::chi2_threshold;
use algo::gaussian::mahalanobis_sq;
use algo::motion::{ConstantVelocity, MotionModel, ProcessNoise, cv_transition};

/// Significance α of the first threshold (the paper's value).
pub const ALPHA: f64 = 0.05;
/// First scan counted as steady state (after the two-point initialisation
/// transient).
pub const STEADY_FROM: usize = 10;

/// Counts for one statistic over one subset of scans.
#[derive(Debug, Clone, Copy, Default)]
struct Tally {
    samples: usize,
    exceed: usize,
    windows: [usize; 2],
    misses: [usize; 2],
}

impl Tally {
    fn add(&mut self, o: &Tally) {
        self.samples += o.samples;
        self.exceed += o.exceed;
        for i in 0..2 {
            self.windows[i] += o.windows[i];
            self.misses[i] += o.misses[i];
        }
    }

    fn rate(&self) -> f64 {
        self.exceed as f64 / self.samples.max(1) as f64
    }

    fn miss_rate(&self, i: usize) -> f64 {
        self.misses[i] as f64 / self.windows[i].max(1) as f64
    }
}

/// One run's figures: `tally[stat][subset]` with stat 0 = α (weighted),
/// 1 = β (with cross-covariance) and subset 0 = all scans, 1 = steady;
/// per-scan exceedances; lag-1 sums of α for its autocorrelation.
#[derive(Debug, Clone, Default)]
struct RunOut {
    tally: [[Tally; 2]; 2],
    per_scan: Vec<[usize; 3]>,
    lag: Lag,
    /// Pairs with a steady-state sequence, and those with ≥ 1 α exceedance in it.
    pairs: [usize; 2],
}

/// Sums for the Pearson correlation of consecutive α values.
#[derive(Debug, Clone, Copy, Default)]
struct Lag {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    syy: f64,
    sxy: f64,
}

impl Lag {
    fn push(&mut self, x: f64, y: f64) {
        self.n += 1.0;
        self.sx += x;
        self.sy += y;
        self.sxx += x * x;
        self.syy += y * y;
        self.sxy += x * y;
    }

    fn add(&mut self, o: &Lag) {
        self.n += o.n;
        self.sx += o.sx;
        self.sy += o.sy;
        self.sxx += o.sxx;
        self.syy += o.syy;
        self.sxy += o.sxy;
    }

    fn correlation(&self) -> f64 {
        let n = self.n;
        if n < 2.0 {
            return 0.0;
        }
        let cov = self.sxy / n - (self.sx / n) * (self.sy / n);
        let vx = self.sxx / n - (self.sx / n).powi(2);
        let vy = self.syy / n - (self.sy / n).powi(2);
        if vx <= 0.0 || vy <= 0.0 {
            0.0
        } else {
            cov / (vx * vy).sqrt()
        }
    }
}

fn rules() -> Result<[LrRule; 2], SimError> {
    Ok([LrRule::new(3, 4)?, LrRule::new(6, 8)?])
}

/// Runs the experiment (default 60 targets, 40 scans).
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let mut scene = opts.seed000_scene(60);
    scene.keep_gains = true;
    let delta = chi2_threshold(4, ALPHA)?;
    let rules = rules()?;
    let started = std::time::Instant::now();
    let outs = run_batch(&opts.runner, "seed000-miss-probability", |_, rng| {
        one_run(&scene, delta, &rules, rng)
    });
    let outs: Vec<RunOut> = outs.into_iter().collect::<Result<_, _>>()?;
    let wall = started.elapsed().as_secs_f64();

    let mut total = [[Tally::default(); 2]; 2];
    let mut csv = String::from(
        "run,statistic,subset,samples,exceedances,windows_3of4,misses_3of4,windows_6of8,misses_6of8\n",
    );
    for (r, o) in outs.iter().enumerate() {
        for (s, stat) in ["alpha", "beta"].iter().enumerate() {
            for (u, subset) in ["all", "steady"].iter().enumerate() {
                let t = &o.tally[s][u];
                total[s][u].add(t);
                let _ = writeln!(
                    csv,
                    "{r},{stat},{subset},{},{},{},{},{},{}",
                    t.samples, t.exceed, t.windows[0], t.misses[0], t.windows[1], t.misses[1]
                );
            }
        }
    }
    let se_of = |f: &dyn Fn(&RunOut) -> f64| {
        let v: Vec<f64> = outs.iter().map(f).collect();
        mean_se(&v).1
    };

    // (a) per-sample exceedance.
    let mut rows_a = Vec::new();
    for (s, name) in ["weighted α = d'(P_i+P_j)⁻¹d", "with cross-covariance β"]
        .iter()
        .enumerate()
    {
        let mut row = vec![name.to_string(), f4(ALPHA)];
        for (u, t) in total[s].iter().enumerate() {
            let se = se_of(&|o: &RunOut| o.tally[s][u].rate());
            row.push(format!("{} ± {}", f4(t.rate()), f4(se)));
        }
        rows_a.push(row);
    }
    // (b) rule miss rates.
    let paper_printed = ["0.002256", "0.000102"];
    let mut rows_b = Vec::new();
    for (i, rule) in rules.iter().enumerate() {
        let nominal = miss_probability(*rule, ALPHA)?;
        let mut row = vec![
            format!("{}/{}", rule.l(), rule.r()),
            paper_printed[i].to_string(),
            format!("{nominal:.6}"),
        ];
        for (s, stat) in total.iter().enumerate() {
            let t = &stat[1];
            let se = se_of(&|o: &RunOut| o.tally[s][1].miss_rate(i));
            row.push(format!("{:.6} ± {:.6}", t.miss_rate(i), se));
            let at_measured = miss_probability(*rule, t.rate().clamp(1e-12, 1.0 - 1e-12))?;
            row.push(format!("{at_measured:.6}"));
        }
        rows_b.push(row);
    }
    // Lag-1 autocorrelation of α over steady scans, pooled.
    let rho = outs
        .iter()
        .fold(Lag::default(), |mut a, o| {
            a.add(&o.lag);
            a
        })
        .correlation();
    let pairs = outs
        .iter()
        .fold([0usize; 2], |a, o| [a[0] + o.pairs[0], a[1] + o.pairs[1]]);
    let steady_len = scene.scans.saturating_sub(STEADY_FROM);
    let alpha_hat = total[0][1].rate();
    let independent_any = 1.0 - (1.0 - alpha_hat).powi(steady_len as i32);

    let mut md = String::new();
    let _ = writeln!(md, "# seed000-miss-probability\n");
    let _ = writeln!(
        md,
        "Same-target track pairs of the seed 000 §5.1 scene ({} targets, {} scans of T = {} s, {} runs, \
         seed {}); first threshold δ = χ²₄(1 − {ALPHA}) = {delta:.4}; steady state = scans ≥ {STEADY_FROM}. \
         ± is one standard error over runs. Wall time {wall:.2} s.\n",
        scene.targets,
        scene.scans,
        scene.period,
        outs.len(),
        opts.runner.seed
    );
    let _ = writeln!(
        md,
        "## (a) Per-sample exceedance Pr{{statistic > δ}} (eq. 14)\n"
    );
    md.push_str(&markdown_table(
        &[
            "statistic",
            "nominal α",
            "all scans ≥ 1",
            &format!("scans ≥ {STEADY_FROM}"),
        ],
        &rows_a,
    ));
    let _ = writeln!(
        md,
        "\n## (b) Missed-correlation probability of L/R rules (eq. 23), steady state\n"
    );
    md.push_str(&markdown_table(
        &[
            "L/R",
            "paper (printed)",
            "eq. 23 at α = 0.05",
            "empirical, α statistic",
            "eq. 23 at measured α rate",
            "empirical, β statistic",
            "eq. 23 at measured β rate",
        ],
        &rows_b,
    ));
    let _ = writeln!(
        md,
        "\nLag-1 autocorrelation of the α statistic between consecutive scans (steady state): {rho:.3}. \
         Same-target pairs with at least one α exceedance in their {steady_len} steady scans: \
         {} of {} ({:.1} %); independent samples at the measured rate would give {:.1} %. \
         Windows are all runs of R consecutive scans (overlapping). The paper's printed values \
         disagree with its own eq. 23 (see `algo::correlation::rules`).",
        pairs[1],
        pairs[0],
        100.0 * pairs[1] as f64 / pairs[0].max(1) as f64,
        100.0 * independent_any
    );

    // Exceedance rate per scan.
    let scans = scene.scans;
    let mut per_scan = vec![[0usize; 3]; scans];
    for o in &outs {
        for (l, c) in o.per_scan.iter().enumerate() {
            for i in 0..3 {
                per_scan[l][i] += c[i];
            }
        }
    }
    let times = scene.times();
    let series = |idx: usize, name: &str| Series {
        name: name.into(),
        points: (1..scans)
            .map(|l| {
                (
                    times[l],
                    per_scan[l][idx] as f64 / per_scan[l][0].max(1) as f64,
                )
            })
            .collect(),
        dashed: false,
    };
    let plot = LinePlot {
        title: "seed 000: per-scan exceedance of δ by same-target pairs".into(),
        x_label: "time (s)".into(),
        y_label: "Pr{statistic > δ}".into(),
        series: vec![
            series(1, "weighted α"),
            series(2, "with P_ij (β)"),
            Series {
                name: "nominal 0.05".into(),
                points: vec![(times[1], ALPHA), (times[scans - 1], ALPHA)],
                dashed: true,
            },
        ],
        y_range: None,
    };
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![("exceedance".into(), plot.to_svg())],
    })
}

/// One run: per target, the α and β sequences of its two local tracks.
fn one_run(
    scene: &Seed000Scene,
    delta: f64,
    rules: &[LrRule; 2],
    rng: &mut SimRng,
) -> Result<RunOut, SimError> {
    let run = generate(scene, rng)?;
    let scans = run.times.len();
    let mut out = RunOut {
        per_scan: vec![[0; 3]; scans],
        ..RunOut::default()
    };
    // id of target k at node n.
    let mut id_of = [vec![0u32; scene.targets], vec![0u32; scene.targets]];
    for (ids, truth) in id_of.iter_mut().zip(&run.track_target) {
        for (id, &k) in truth.iter().enumerate() {
            ids[k] = id as u32;
        }
    }
    // The nodes' own motion model, for G Q G' of the cross-covariance.
    let model = ConstantVelocity::new(
        2,
        ProcessNoise::VelocityProportional {
            factor: scene.noise_factor,
        },
    )?;
    let h = position_h();
    let eye = DMatrix::<f64>::identity(4, 4);
    for ids in id_of[0].iter().zip(&id_of[1]).map(|(&a, &b)| [a, b]) {
        let mut exceed: [Vec<bool>; 2] = [Vec::new(), Vec::new()];
        let mut alphas = Vec::new();
        let mut p12: Option<DMatrix<f64>> = None;
        let mut prev_mean: Option<DVector<f64>> = None;
        for l in 1..scans {
            let find = |n: usize| {
                run.nodes[n][l]
                    .binary_search_by_key(&ids[n], |tr| tr.id)
                    .ok()
                    .map(|i| &run.nodes[n][l][i].estimate)
            };
            let (Some(e1), Some(e2)) = (find(0), find(1)) else {
                continue;
            };
            // Cross-covariance recursion (seed 000 eq. 13, Bar-Shalom 1981):
            // P12(l) = (I − K1 H)[Φ P12(l−1) Φ' + G Q G'](I − K2 H)', P12 = 0
            // at initialisation (independent measurement errors).
            let cross = match (&p12, &e1.gain, &e2.gain, &prev_mean) {
                (Some(prev), Some(k1), Some(k2), Some(xm)) => {
                    let dt = scene.period;
                    let f = cv_transition(2, dt)?;
                    let q = model.process_noise(dt, xm)?;
                    let mid = &f * prev * f.transpose() + q;
                    (&eye - k1 * &h) * mid * (&eye - k2 * &h).transpose()
                }
                _ => DMatrix::zeros(4, 4),
            };
            let d = &e1.x - &e2.x;
            let s_alpha = &e1.p + &e2.p;
            let s_beta = &s_alpha - &cross - cross.transpose();
            let a = mahalanobis_sq(&d, &s_alpha)?;
            let b = mahalanobis_sq(&d, &s_beta)?;
            exceed[0].push(a > delta);
            exceed[1].push(b > delta);
            out.per_scan[l][0] += 1;
            out.per_scan[l][1] += usize::from(a > delta);
            out.per_scan[l][2] += usize::from(b > delta);
            if l > STEADY_FROM
                && let Some(&prev) = alphas.last()
            {
                out.lag.push(prev, a);
            }
            alphas.push(a);
            prev_mean = Some((&e1.x + &e2.x) / 2.0);
            p12 = Some(cross);
        }
        let steady = exceed[0].get(STEADY_FROM - 1..).unwrap_or(&[]);
        if !steady.is_empty() {
            out.pairs[0] += 1;
            out.pairs[1] += usize::from(steady.iter().any(|&e| e));
        }
        // Sample i is scan i + 1; steady samples are scans ≥ STEADY_FROM.
        for (s, ex) in exceed.iter().enumerate() {
            for subset in 0..2 {
                let first = if subset == 0 { 0 } else { STEADY_FROM - 1 };
                let t = &mut out.tally[s][subset];
                let seq = if first < ex.len() {
                    &ex[first..]
                } else {
                    &[][..]
                };
                t.samples += seq.len();
                t.exceed += seq.iter().filter(|&&e| e).count();
                for (i, rule) in rules.iter().enumerate() {
                    let r = rule.r() as usize;
                    for w in seq.windows(r) {
                        t.windows[i] += 1;
                        let misses = w.iter().filter(|&&e| e).count() as u32;
                        t.misses[i] += usize::from(misses >= rule.misses_from());
                    }
                }
            }
        }
    }
    Ok(out)
}
