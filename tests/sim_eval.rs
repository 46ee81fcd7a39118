//! Short runs of every registered experiment through the same entry point
//! as `radar-fusion eval`: the files are written and every rate is in [0, 1].

use std::path::PathBuf;

use radar_fusion::sim::experiments::{EvalOptions, REGISTRY, run_and_write};
use radar_fusion::sim::montecarlo::Progress;

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
