//! Short runs of every registered experiment through the same entry point
//! as `radar-fusion-eval`: the files are written and every rate is in [0, 1].

use std::path::PathBuf;

use eval::experiments::{EvalOptions, REGISTRY, run_and_write};
use eval::montecarlo::Progress;

fn small(runs: usize, threads: usize) -> EvalOptions {
    let mut o = EvalOptions::new(runs, 18);
    o.runner.progress = Progress::Never;
    o.runner.threads = threads;
    o.targets = Some(6);
    o.scans = Some(14);
    o
}

fn out_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!(
        "radar-fusion-sim-eval-{}-{tag}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn every_experiment_writes_markdown_csv_and_svg() {
    for exp in REGISTRY {
        let dir = out_dir(exp.name);
        let files = run_and_write(exp.name, &small(3, 2), &dir).unwrap();
        let md = dir.join(format!("{}.md", exp.name));
        let csv = dir.join(format!("{}.csv", exp.name));
        assert!(files.contains(&md) && files.contains(&csv));
        assert!(
            files
                .iter()
                .any(|f| f.extension().is_some_and(|e| e == "svg"))
        );
        for f in &files {
            let text = std::fs::read_to_string(f).unwrap();
            assert!(!text.is_empty(), "{} is empty", f.display());
            assert!(!text.contains("NaN"), "{} has NaN", f.display());
        }
        let csv_text = std::fs::read_to_string(&csv).unwrap();
        // Header + at least one row per run.
        assert!(csv_text.lines().count() > 3);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

#[test]
fn miss_probability_rates_are_probabilities() {
    let dir = out_dir("miss");
    run_and_write("seed000-miss-probability", &small(3, 2), &dir).unwrap();
    let csv = std::fs::read_to_string(dir.join("seed000-miss-probability.csv")).unwrap();
    for line in csv.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let n: Vec<f64> = f[3..].iter().map(|v| v.parse().unwrap()).collect();
        // exceedances ≤ samples, misses ≤ windows: every rate in [0, 1].
        let rates = [
            n[1] / n[0].max(1.0),
            n[3] / n[2].max(1.0),
            n[5] / n[4].max(1.0),
        ];
        assert!(rates.iter().all(|r| (0.0..=1.0).contains(r)), "{line}");
    }
    // Every figure in the Markdown tables written as "x ± se" is in [0, 1].
    let md = std::fs::read_to_string(dir.join("seed000-miss-probability.md")).unwrap();
    let mut seen = 0;
    let table_cells = md
        .lines()
        .filter(|l| l.starts_with('|'))
        .flat_map(|l| l.split('|'));
    for cell in table_cells {
        if let Some((v, _)) = cell.trim().split_once(" ± ") {
            let v: f64 = v.parse().unwrap();
            assert!((0.0..=1.0).contains(&v), "{cell}");
            seen += 1;
        }
    }
    assert!(seen >= 8);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn outputs_do_not_depend_on_the_thread_count() {
    // The CSV holds every per-run figure; the Markdown also holds the wall
    // time, so it is not compared.
    let a = out_dir("t1");
    let b = out_dir("t2");
    for exp in REGISTRY {
        run_and_write(exp.name, &small(4, 1), &a).unwrap();
        run_and_write(exp.name, &small(4, 2), &b).unwrap();
        let name = format!("{}.csv", exp.name);
        assert_eq!(
            std::fs::read(a.join(&name)).unwrap(),
            std::fs::read(b.join(&name)).unwrap(),
            "{}",
            exp.name
        );
    }
    let _ = std::fs::remove_dir_all(&a);
    let _ = std::fs::remove_dir_all(&b);
}

#[test]
fn unknown_experiment_and_zero_runs_are_errors() {
    let dir = out_dir("err");
    assert!(run_and_write("no-such-experiment", &small(1, 1), &dir).is_err());
    assert!(run_and_write(REGISTRY[0].name, &small(0, 1), &dir).is_err());
}

/// The CSV of `name` run with `opts`: header and rows split on commas.
fn csv_rows(name: &str, opts: &EvalOptions, tag: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let dir = out_dir(tag);
    run_and_write(name, opts, &dir).unwrap();
    let text = std::fs::read_to_string(dir.join(format!("{name}.csv"))).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect());
    (lines.next().unwrap(), lines.collect())
}

fn column(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap()
}

#[test]
fn seed001_plot_association_pairs_and_fuses() {
    // The patent's three targets over 21 scans: most target-scans paired,
    // and the fused plots beat the better radar's plots.
    let mut o = small(3, 2);
    o.targets = None;
    o.scans = Some(21);
    let (h, rows) = csv_rows("seed001-plot-association", &o, "s001-fig3");
    assert_eq!(rows.len(), 3);
    for r in &rows {
        let v = |c: &str| r[column(&h, c)].parse::<f64>().unwrap();
        let rates = [v("correct_pair_rate"), v("mispaired_rate"), v("split_rate")];
        assert!((rates.iter().sum::<f64>() - 1.0).abs() < 1e-9, "{r:?}");
        assert!(rates[0] > 0.8 && (0.0..=1.0).contains(&v("group_purity")));
        assert!(v("rmse_fused_m") < v("rmse_radar2_m") && v("rmse_radar2_m") < v("rmse_radar1_m"));
    }
}

#[test]
fn seed001_serial_fusion_confirms_before_either_radar_alone() {
    let mut o = small(3, 2);
    o.scans = None;
    let (h, rows) = csv_rows("seed001-serial-jpda", &o, "s001-fig5");
    assert_eq!(rows.len(), 9);
    let confirm = |method: &str| -> f64 {
        let c = column(&h, "confirm_s_target1");
        let picked: Vec<f64> = rows
            .iter()
            .filter(|r| r[1] == method)
            .flat_map(|r| [r[c].parse::<f64>().unwrap(), r[c + 1].parse().unwrap()])
            .collect();
        picked.iter().sum::<f64>() / picked.len() as f64
    };
    let serial = confirm("serial fusion");
    assert!(serial < confirm("radar 1 alone") && serial < confirm("radar 2 alone"));
}

#[test]
fn seed001_initiation_confirms_the_patent_targets() {
    let mut o = small(3, 2);
    o.targets = None;
    o.scans = Some(6);
    let (h, rows) = csv_rows("seed001-initiation", &o, "s001-fig6");
    assert_eq!(rows.len(), 9);
    for r in &rows {
        let confirmed: usize = r[column(&h, "targets_confirmed")].parse().unwrap();
        assert!(confirmed <= 5);
        if r[0] == "1" {
            // P_D = 1, no clutter: all five within the patent's four scans.
            assert_eq!(confirmed, 5, "{r:?}");
            assert_eq!(r[column(&h, "clutter_plots")], "0");
        }
    }
}

#[test]
fn seed001_montecarlo_rows_cover_every_method_and_variant() {
    let (h, rows) = csv_rows("seed001-montecarlo", &small(2, 2), "s001-mc");
    // 2 runs × (3 methods × 3 radar counts + the 3-radar variants).
    let variants = rows.iter().filter(|r| r[0] == "3").count() / 2 - 3;
    assert!(variants >= 1);
    assert_eq!(rows.len(), 2 * (9 + variants));
    for r in &rows {
        for cell in &r[4..] {
            assert!(cell.parse::<f64>().unwrap().is_finite(), "{r:?}");
        }
        let confirmed: f64 = r[column(&h, "targets_confirmed")].parse().unwrap();
        assert!((0.0..=1.0).contains(&confirmed));
        let best: usize = r[column(&h, "best_radar")].parse().unwrap();
        assert!(best >= 1 && best <= r[0].parse().unwrap());
    }
}
