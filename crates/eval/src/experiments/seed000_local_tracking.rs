//! `seed000-local-tracking`: how well the local Kalman filters of seed 000
//! §5.1 track, per node: position RMSE against time (filtered and raw
//! converted plots) and the average NEES of the 4-dimensional state against
//! its χ² bounds (filter consistency). The correlation tests of seed 000
//! assume these filters are consistent (eq. 14 relies on it), so this is the
//! ground every correlation figure stands on.

use std::fmt::Write as _;

use nalgebra::DVector;

use super::{EvalOptions, mean_se};
use crate::SimError;
use crate::metrics::{nees, nees_bounds, rmse};
use crate::montecarlo::run_batch;
use crate::report::{LinePlot, Report, Series, markdown_table};
use crate::scenario000::{Seed000Scene, generate};
use algo::polar::plot_to_local;

/// Per-scan sums of one node in one run.
#[derive(Debug, Clone, Default)]
struct ScanSums {
    sq_filtered: f64,
    sq_raw: f64,
    nees: f64,
    n: usize,
    n_raw: usize,
}

/// Runs the experiment (default 60 targets, 40 scans).
pub fn run(opts: &EvalOptions) -> Result<Report, SimError> {
    let scene = opts.seed000_scene(60);
    let started = std::time::Instant::now();
    let per_run = run_batch(&opts.runner, "seed000-local-tracking", |_, rng| {
        one_run(&scene, rng)
    });
    let per_run: Vec<[Vec<ScanSums>; 2]> = per_run.into_iter().collect::<Result<_, _>>()?;
    let wall = started.elapsed().as_secs_f64();
    let runs = per_run.len();
    let times = scene.times();
    let steady_from = scene.scans.saturating_sub(10).max(1);

    let mut rows = Vec::new();
    let mut csv = String::from("run,node,rmse_filtered_m,rmse_converted_plot_m,mean_nees\n");
    let mut rmse_series = Vec::new();
    let mut nees_series = Vec::new();
    for node in 0..2 {
        // Pooled over runs, per scan.
        let mut pooled = vec![ScanSums::default(); scene.scans];
        for (r, run) in per_run.iter().enumerate() {
            let mut tot = ScanSums::default();
            for (l, s) in run[node].iter().enumerate() {
                add(&mut pooled[l], s);
                add(&mut tot, s);
            }
            let _ = writeln!(
                csv,
                "{r},{},{:.3},{:.3},{:.4}",
                node + 1,
                rmse(tot.sq_filtered, tot.n),
                rmse(tot.sq_raw, tot.n_raw),
                tot.nees / tot.n.max(1) as f64
            );
        }
        let mut all = ScanSums::default();
        let mut steady = ScanSums::default();
        for (l, s) in pooled.iter().enumerate() {
            add(&mut all, s);
            if l >= steady_from {
                add(&mut steady, s);
            }
        }
        let run_nees: Vec<f64> = per_run
            .iter()
            .map(|run| {
                let (s, n) = run[node]
                    .iter()
                    .fold((0.0, 0), |(a, b), x| (a + x.nees, b + x.n));
                s / n.max(1) as f64
            })
            .collect();
        let (nees_mean, nees_se) = mean_se(&run_nees);
        // Per-scan average NEES of runs·targets samples against its 95 % band.
        let per_scan_n = pooled.get(1).map_or(0, |s| s.n);
        let (lo, hi) = nees_bounds(4, per_scan_n.max(1), 0.95)?;
        let inside = pooled[1..]
            .iter()
            .filter(|s| {
                let a = s.nees / s.n.max(1) as f64;
                (lo..=hi).contains(&a)
            })
            .count();
        let radar = &scene.radars[node];
        rows.push(vec![
            format!("{}", node + 1),
            format!("{:.0}", radar.sigma_range),
            format!("{:.1}", radar.sigma_azimuth.to_degrees()),
            format!("{:.1}", rmse(all.sq_filtered, all.n)),
            format!("{:.1}", rmse(steady.sq_filtered, steady.n)),
            format!("{:.1}", rmse(all.sq_raw, all.n_raw)),
            format!("{:.3} ± {:.3}", nees_mean, nees_se),
            format!("[{:.3}, {:.3}]", lo, hi),
            format!("{inside}/{}", scene.scans - 1),
        ]);
        rmse_series.push(Series {
            name: format!("node {} filtered", node + 1),
            points: pooled[1..]
                .iter()
                .enumerate()
                .map(|(i, s)| (times[i + 1], rmse(s.sq_filtered, s.n)))
                .collect(),
            dashed: false,
        });
        rmse_series.push(Series {
            name: format!("node {} plots", node + 1),
            points: pooled
                .iter()
                .enumerate()
                .map(|(l, s)| (times[l], rmse(s.sq_raw, s.n_raw)))
                .collect(),
            dashed: true,
        });
        nees_series.push(Series {
            name: format!("node {}", node + 1),
            points: pooled[1..]
                .iter()
                .enumerate()
                .map(|(i, s)| (times[i + 1], s.nees / s.n.max(1) as f64))
                .collect(),
            dashed: false,
        });
        if node == 1 {
            for (name, v) in [("95% low", lo), ("95% high", hi)] {
                nees_series.push(Series {
                    name: name.into(),
                    points: vec![(times[1], v), (*times.last().unwrap_or(&0.0), v)],
                    dashed: true,
                });
            }
        }
    }

    let mut md = String::new();
    let _ = writeln!(md, "# seed000-local-tracking\n");
    let _ = writeln!(
        md,
        "Local Kalman filters of seed 000 §5.1 (eqs. 24–30): {} targets, {} scans of T = {} s, \
         {} runs, seed {}; radars at ({:.0} km, {:.0} km) and ({:.0} km, {:.0} km); targets normal \
         about ({:.0} km, {:.0} km) with σ = {:.0} km; speeds {}–{} m/s; eq. 26 factor {}. \
         Wall time {:.2} s.\n",
        scene.targets,
        scene.scans,
        scene.period,
        runs,
        opts.runner.seed,
        scene.radars[0].site[0] / 1e3,
        scene.radars[0].site[1] / 1e3,
        scene.radars[1].site[0] / 1e3,
        scene.radars[1].site[1] / 1e3,
        scene.region_centre[0] / 1e3,
        scene.region_centre[1] / 1e3,
        scene.region_sigma / 1e3,
        scene.speed.0,
        scene.speed.1,
        scene.noise_factor,
        wall
    );
    md.push_str(&markdown_table(
        &[
            "node",
            "σρ (m)",
            "σθ (°)",
            "position RMSE, all scans (m)",
            &format!("RMSE, scans ≥ {steady_from} (m)"),
            "converted-plot RMSE (m)",
            "average NEES (4 dof) ± SE over runs",
            "95 % band of a per-scan average",
            "scans inside the band",
        ],
        &rows,
    ));
    let _ = writeln!(
        md,
        "\nA consistent filter has average NEES 4. The per-scan band is the 95 % interval of an \
         average of {} independent χ²₄ values (runs × targets). The paper reports no local \
         tracking figure; this checks the filters its correlation tests rely on.",
        per_run.len() * scene.targets
    );

    Ok(Report {
        markdown: md,
        csv,
        plots: vec![
            (
                "rmse".into(),
                LinePlot {
                    title: "seed 000 local tracking: position RMSE".into(),
                    x_label: "time (s)".into(),
                    y_label: "RMSE (m)".into(),
                    series: rmse_series,
                    y_range: None,
                }
                .to_svg(),
            ),
            (
                "nees".into(),
                LinePlot {
                    title: "seed 000 local tracking: average NEES (4 dof)".into(),
                    x_label: "time (s)".into(),
                    y_label: "average NEES".into(),
                    series: nees_series,
                    y_range: None,
                }
                .to_svg(),
            ),
        ],
    })
}

fn add(a: &mut ScanSums, b: &ScanSums) {
    a.sq_filtered += b.sq_filtered;
    a.sq_raw += b.sq_raw;
    a.nees += b.nees;
    a.n += b.n;
    a.n_raw += b.n_raw;
}

fn one_run(scene: &Seed000Scene, rng: &mut crate::SimRng) -> Result<[Vec<ScanSums>; 2], SimError> {
    let run = generate(scene, rng)?;
    let mut out: [Vec<ScanSums>; 2] = [Vec::new(), Vec::new()];
    for (node, sums) in out.iter_mut().enumerate() {
        let radar = &scene.radars[node];
        for l in 0..run.times.len() {
            let mut s = ScanSums::default();
            for tr in &run.nodes[node][l] {
                let k = run.track_target[node][tr.id as usize];
                let truth = run.truth[k].states[l];
                let e = DVector::from_vec(vec![
                    tr.estimate.x[0] - truth[0],
                    tr.estimate.x[1] - truth[1],
                    tr.estimate.x[2] - truth[2],
                    tr.estimate.x[3] - truth[3],
                ]);
                s.sq_filtered += e[0] * e[0] + e[2] * e[2];
                s.nees += nees(&e, &tr.estimate.p)?;
                s.n += 1;
            }
            for (k, plot) in run.plots[node][l].iter().enumerate() {
                if let Some(p) = plot {
                    let z = plot_to_local(radar.site, &radar.polar_measurement(p))?;
                    let truth = run.truth[k].states[l];
                    s.sq_raw += (z.mean()[0] - truth[0]).powi(2) + (z.mean()[1] - truth[2]).powi(2);
                    s.n_raw += 1;
                }
            }
            sums.push(s);
        }
    }
    Ok(out)
}
