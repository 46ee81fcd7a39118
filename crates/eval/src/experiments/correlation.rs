//! The reusable body of a track-to-track correlation experiment on the seed
//! 000 scene (§5): E_c, E_e and E_s of several methods on the same runs, for
//! one or more scene sizes, with the per-scan curves of the paper's figs. 1–4.
//!
//! The `seed000-correlation` experiment is then a few lines: build the
//! [`Method`]s (each a name and a [`crate::scenario000::Driver`]: a
//! factory of a per-scan [`crate::scenario000::Correlator`], or a causal
//! batch function over the whole run) and call [`correlation_report`] with
//! the paper's sizes `[60, 120]` and `from_scan` = R of the final rule.

use std::fmt::Write as _;

use super::{EvalOptions, f4};
use crate::SimError;
use crate::metrics::CorrelationCounts;
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario000::{Method, score_correlators};

/// Runs every method on the same `opts.runner.runs` runs of the seed 000
/// scene for each size in `sizes` (overridden by `opts.targets`), and
/// reports E_c/E_e/E_s averaged over scans ≥ `from_scan` (e.g. R = 8 for a
/// 6/8 rule, when a decision is first possible) plus the per-scan curves.
pub fn correlation_report(
    name: &str,
    opts: &EvalOptions,
    sizes: &[usize],
    from_scan: usize,
    methods: &[Method<'_>],
) -> Result<Report, SimError> {
    let sizes: Vec<usize> = match opts.targets {
        Some(t) => vec![t],
        None => sizes.to_vec(),
    };
    let mut md = format!("# {name}\n\n");
    let mut csv = String::from("targets,run,method,scan,correct,error,missed\n");
    let mut plots = Vec::new();
    for &targets in &sizes {
        let mut scene = opts.seed000_scene(targets);
        scene.keep_gains = true;
        let from = from_scan.min(scene.scans.saturating_sub(1)).max(1);
        let started = std::time::Instant::now();
        let runs = run_batch(&opts.runner, name, |_, rng| {
            score_correlators(&scene, methods, rng)
        });
        let runs: Vec<Vec<Vec<CorrelationCounts>>> = runs.into_iter().collect::<Result<_, _>>()?;
        let wall = started.elapsed().as_secs_f64();
        let mut rows = Vec::new();
        let mut ec_series = Vec::new();
        let mut ee_series = Vec::new();
        let times = scene.times();
        for (m, method) in methods.iter().enumerate() {
            let mut per_scan = vec![CorrelationCounts::default(); scene.scans];
            let mut tot = CorrelationCounts::default();
            for (r, run) in runs.iter().enumerate() {
                for (l, c) in run[m].iter().enumerate() {
                    per_scan[l].add(c);
                    if l >= from {
                        tot.add(c);
                    }
                    let _ = writeln!(
                        csv,
                        "{targets},{r},{},{l},{},{},{}",
                        method.name, c.correct, c.error, c.missed
                    );
                }
            }
            rows.push(vec![
                method.name.to_string(),
                f4(tot.correct_rate()),
                f4(tot.error_rate()),
                f4(tot.missed_rate()),
            ]);
            let curve = |f: fn(&CorrelationCounts) -> f64| -> Vec<(f64, f64)> {
                (1..scene.scans)
                    .map(|l| (times[l], f(&per_scan[l])))
                    .collect()
            };
            ec_series.push(Series {
                name: method.name.to_string(),
                points: curve(CorrelationCounts::correct_rate),
                dashed: false,
            });
            ee_series.push(Series {
                name: method.name.to_string(),
                points: curve(CorrelationCounts::error_rate),
                dashed: false,
            });
        }
        let _ = writeln!(
            md,
            "## {targets} targets\n\n{} runs, seed {}, {} scans of T = {} s; rates pooled over scans ≥ {from}. \
             Wall time {wall:.2} s.\n",
            runs.len(),
            opts.runner.seed,
            scene.scans,
            scene.period
        );
        md.push_str(&markdown_table(&["method", "E_c", "E_e", "E_s"], &rows));
        md.push('\n');
        for (kind, series) in [("correct", ec_series), ("error", ee_series)] {
            plots.push((
                format!("{kind}-{targets}"),
                LinePlot {
                    title: format!("{kind} correlation rate, {targets} targets"),
                    x_label: "time (s)".into(),
                    y_label: format!("{kind} correlation rate"),
                    series,
                    y_range: Some((0.0, 1.0)),
                }
                .to_svg(),
            ));
        }
    }
    Ok(Report {
        markdown: md,
        csv,
        plots,
    })
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;
    use crate::montecarlo::Progress;
    use crate::scenario000::{Correlator, Driver, LocalTrack, Seed000Scene};

    /// Pairs tracks by nearest position, greedily: a test double to drive
    /// the harness, not a method of the service.
    struct Nearest;
    impl Correlator for Nearest {
        fn correlate(
            &mut self,
            _t: f64,
            n1: &[LocalTrack],
            n2: &[LocalTrack],
        ) -> Result<Vec<(u32, u32)>, SimError> {
            let mut used: HashMap<u32, ()> = HashMap::new();
            let mut out = Vec::new();
            for a in n1 {
                let best = n2
                    .iter()
                    .filter(|b| !used.contains_key(&b.id))
                    .map(|b| {
                        let d = (a.estimate.x[0] - b.estimate.x[0])
                            .hypot(a.estimate.x[2] - b.estimate.x[2]);
                        (d, b.id)
                    })
                    .min_by(|x, y| x.0.total_cmp(&y.0));
                if let Some((_, id)) = best {
                    used.insert(id, ());
                    out.push((a.id, id));
                }
            }
            Ok(out)
        }
    }

    #[test]
    fn report_has_one_row_per_method_and_rates_sum_to_one() {
        let mut opts = EvalOptions::new(2, 5);
        opts.runner.progress = Progress::Never;
        opts.targets = Some(6);
        opts.scans = Some(5);
        let build = |_: &Seed000Scene| -> Box<dyn Correlator> { Box::new(Nearest) };
        // The same method through both drivers must score the same.
        let batch = |scene: &Seed000Scene,
                     run: &crate::scenario000::TwoNodeRun|
         -> Result<Vec<Vec<(u32, u32)>>, SimError> {
            let mut c = build(scene);
            (0..run.times.len())
                .map(|l| c.correlate(run.times[l], &run.nodes[0][l], &run.nodes[1][l]))
                .collect()
        };
        let methods = [
            Method {
                name: "greedy nearest (test double)",
                driver: Driver::PerScan(&build),
            },
            Method {
                name: "batch greedy nearest (test double)",
                driver: Driver::Batch(&batch),
            },
        ];
        let rep = correlation_report("t", &opts, &[60, 120], 2, &methods).unwrap();
        let row = rep
            .markdown
            .lines()
            .find(|l| l.starts_with("| greedy"))
            .unwrap();
        let batch_row = rep
            .markdown
            .lines()
            .find(|l| l.starts_with("| batch greedy"))
            .unwrap();
        assert_eq!(
            row.split_once(')').unwrap().1,
            batch_row.split_once(')').unwrap().1
        );
        let rates: Vec<f64> = row
            .split('|')
            .skip(2)
            .filter_map(|c| c.trim().parse().ok())
            .collect();
        assert_eq!(rates.len(), 3);
        assert!((rates.iter().sum::<f64>() - 1.0).abs() < 2e-4);
        // 2 runs × 2 methods × 5 scans rows plus the header.
        assert_eq!(rep.csv.lines().count(), 1 + 2 * 2 * 5);
        assert_eq!(rep.plots.len(), 2);
    }
}
