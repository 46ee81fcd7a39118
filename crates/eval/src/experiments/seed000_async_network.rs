//! `seed000-async-network`: track-to-track correlation of unsynchronised
//! radar networks with the endpoint's defaults (issue 14).
//!
//! The networks of [`crate::async_network::cases`]: 4 s / 4 s offset
//! 2 s, 4 s / 5 s, 10 s / 12 s offset 3 s, and three radars; 20 aircraft
//! well apart, P_D = 0.9 (local filters coast through misses), 3 % of track
//! reports lost, node 2 silent for 20 s, 300 s. Each run's local tracks go
//! to `service::correlation::correlate` as one request with the
//! independent double-threshold method (6/8) and the paper's motion model,
//! alignment left to its default (the grid), and again with the previous
//! default (clusters of 0.5 s, predicted). The final decisions are scored
//! against the truth over every node pair.

use std::fmt::Write as _;

use super::EvalOptions;
use crate::async_network::{Score, cases, generate, old_default, score};
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::{SimError, SimRng};
use service::correlation::correlate;

pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let mut md = String::new();
    let mut csv = String::from("network,alignment,run,true_pairs,correct,wrong,missed\n");
    let _ = writeln!(
        md,
        "# Correlation of unsynchronised radar networks with the defaults\n\n\
         {} runs per network (seed {}); 20 aircraft 100–300 m/s, P_D 0.9, 3 % of reports \
         lost, node 2 silent for 20 s, 300 s; independent double threshold 6/8, \
         velocity-proportional motion model (factor 0.05). `grid` is the default alignment \
         (period and staleness estimated from the data); `clusters 0.5 s` the previous \
         default. Rates are over every same-target track pair of every node pair.\n",
        opts.runner.runs, opts.runner.seed
    );
    let mut rows = Vec::new();
    let mut rates: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    for (ni, net) in cases().into_iter().enumerate() {
        let results: Vec<Result<(Score, Score), SimError>> =
            run_batch(&opts.runner, net.name, |_, rng: &mut SimRng| {
                let run = generate(&net, rng)?;
                let out = correlate(run.request.clone())
                    .map_err(|e| SimError::InvalidConfig(e.to_string()))?;
                let mut old = run.request.clone();
                old.alignment = Some(old_default());
                let before = correlate(old).map_err(|e| SimError::InvalidConfig(e.to_string()))?;
                Ok((score(&run, &out), score(&run, &before)))
            });
        let mut grid = Score::default();
        let mut clusters = Score::default();
        for (i, r) in results.into_iter().enumerate() {
            let (g, c) = r?;
            for (name, s) in [("grid", g), ("clusters", c)] {
                let _ = writeln!(
                    csv,
                    "{},{name},{i},{},{},{},{}",
                    net.name, s.true_pairs, s.correct, s.wrong, s.missed
                );
            }
            grid.add(g);
            clusters.add(c);
        }
        rates[0].push(((ni + 1) as f64, grid.rate()));
        rates[1].push(((ni + 1) as f64, clusters.rate()));
        for (name, s) in [
            ("grid (default)", grid),
            ("clusters 0.5 s (before)", clusters),
        ] {
            rows.push(vec![
                net.name.to_string(),
                name.to_string(),
                s.true_pairs.to_string(),
                format!("{} ({:.1} %)", s.correct, 100.0 * s.rate()),
                s.wrong.to_string(),
                s.missed.to_string(),
            ]);
        }
    }
    md.push_str(&markdown_table(
        &[
            "network",
            "alignment",
            "true pairs",
            "correct",
            "wrong",
            "missed",
        ],
        &rows,
    ));
    md.push_str("\nNetworks on the plot's x axis in the table's order (1 to 4).\n");
    let [grid, clusters] = rates;
    let series = vec![
        Series {
            name: "grid (default)".into(),
            points: grid,
            dashed: false,
        },
        Series {
            name: "clusters 0.5 s (before)".into(),
            points: clusters,
            dashed: true,
        },
    ];
    Ok(Report {
        markdown: md,
        csv,
        plots: vec![(
            "correct".into(),
            LinePlot {
                title: "Same-target pairs correlated, by network".into(),
                x_label: "network".into(),
                y_label: "correct-correlation rate".into(),
                series,
                y_range: Some((0.0, 1.0)),
            }
            .to_svg(),
        )],
    })
}
