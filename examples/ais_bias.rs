//! AIS–radar association benchmark (issue 17): the compute time of one
//! `associate` call on a busy harbour (72 radar tracks, 20 minutes of AIS,
//! moored ships 10–70 m apart, a quarter without AIS) and on seed 004's open
//! sea (10 and 30 ships), with the decisions and the bias of every scene so
//! two builds can be compared line by line.
//!
//! ```sh
//! cargo run --release --example ais_bias [-- REPEATS SEEDS]
//! cargo run --release --example ais_bias -- coverage [RUNS]
//! cargo run --release --example ais_bias -- dump [SEEDS] > outcomes.txt
//! ```
//!
//! `coverage` runs Monte Carlo scenes (harbour, 72 tracks; open sea, 20
//! ships) with whole-second AIS times and counts how often the true bias
//! falls inside the 95 % ellipse (χ²₂ = 5.991) of: the plain CR1 covariance
//! with the truncated times taken as exact (the service before issue 17),
//! CR1 with the times at the middle of their second, and the reported
//! covariance (CR2, small-sample scaling, stated-error floor) with them.
//!
//! `dump` prints the whole `Outcome` (Debug, every float to the last bit) of
//! every kind at range bias 0, 0.5, 3 and 6 km and azimuth 0.5° and −1°,
//! under each seeding and without widening, so the results of two builds can
//! be diffed.
//!
//! Output: one line per scene, `kind seed bias_range_m: median_ms min_ms
//! cpu median_ms correct/false/missed est_range_m est_azimuth_deg
//! decisions`, and per kind the median over its scenes of the per-scene
//! medians, minima and CPU-time medians. CPU time is the thread's own (from
//! /proc/thread-self/schedstat), so other processes on a shared machine do
//! not inflate it, but on some virtual machines it only advances in
//! scheduler ticks (4 ms): then the minimum is the fair compute figure.

use std::time::Instant;

use algo::bias::associate::{self, Config};
use eval::ais::AisSceneConfig;
use eval::montecarlo::run_rng;

/// A scene kind from its range and azimuth bias.
type MakeScene = fn(f64, f64) -> AisSceneConfig;

/// Nanoseconds this thread has run on a CPU (Linux), if readable.
fn thread_cpu_ns() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

/// χ²₂ statistic of `d` under covariance `c`.
fn nees(d: [f64; 2], c: [[f64; 2]; 2]) -> f64 {
    let det = c[0][0] * c[1][1] - c[0][1] * c[1][0];
    (c[1][1] * d[0] * d[0] - 2.0 * c[0][1] * d[0] * d[1] + c[0][0] * d[1] * d[1]) / det
}

fn coverage(runs: usize) {
    use algo::bias::associate::quantisation_sigma;
    let bias = [500.0, 0.5f64.to_radians()];
    let kinds = [
        ("harbour72", AisSceneConfig::harbour(72, bias[0], bias[1])),
        ("open_sea20", AisSceneConfig::open_sea(20, bias[0], bias[1])),
    ];
    for (name, scene_cfg) in kinds {
        // [as before, CR1 centred, reported]: (inside, Σ NEES, Σ azimuth error)
        let mut stats = [(0usize, 0.0f64, 0.0f64); 3];
        let mut clusters = 0.0;
        for run in 0..runs {
            let scene = scene_cfg
                .generate(&mut run_rng(1717, run as u64))
                .expect("valid scene");
            let mut floored = scene.ais.clone();
            let mut centred = scene.ais.clone();
            for (f, c) in floored.iter_mut().zip(centred.iter_mut()) {
                for (a, b) in f.iter_mut().zip(c.iter_mut()) {
                    a.t = a.t.floor();
                    b.t = b.t.floor() + 0.5;
                    b.time_sigma = quantisation_sigma(1.0);
                }
            }
            let cfg = Config::default();
            let old = associate::associate(&scene.radar, &floored, &cfg).estimate;
            let new = associate::associate(&scene.radar, &centred, &cfg).estimate;
            let (Some(old), Some(new)) = (old, new) else {
                continue;
            };
            clusters += new.effective_pairs;
            let err =
                |e: &associate::BiasEstimate| [e.bias.range - bias[0], e.bias.azimuth - bias[1]];
            for (k, (e, c)) in [
                (err(&old), old.covariance_cr1),
                (err(&new), new.covariance_cr1),
                (err(&new), new.covariance),
            ]
            .into_iter()
            .enumerate()
            {
                let q = nees(e, c);
                stats[k].0 += usize::from(q <= 5.991);
                stats[k].1 += q;
                stats[k].2 += e[1].to_degrees();
            }
        }
        for (k, label) in [
            "CR1, truncated times as exact (before)",
            "CR1, times centred",
            "reported (CR2 × T², floor), times centred",
        ]
        .iter()
        .enumerate()
        {
            println!(
                "{name} {label}: inside 95 % ellipse {}/{runs} = {:.1} %, mean NEES {:.2}, mean azimuth error {:+.5} deg",
                stats[k].0,
                100.0 * stats[k].0 as f64 / runs as f64,
                stats[k].1 / runs as f64,
                stats[k].2 / runs as f64
            );
        }
        println!("{name}: mean effective pairs {:.1}", clusters / runs as f64);
    }
}

fn dump(seeds: u64) {
    use algo::bias::associate::Seeding;
    let kinds: [(&str, MakeScene); 3] = [
        ("harbour72", |b, a| AisSceneConfig::harbour(72, b, a)),
        ("open_sea30", |b, a| AisSceneConfig::open_sea(30, b, a)),
        ("open_sea10", |b, a| AisSceneConfig::open_sea(10, b, a)),
    ];
    let configs = [
        ("auto", Config::default()),
        (
            "cfar",
            Config {
                seeding: Seeding::Cfar,
                ..Config::default()
            },
        ),
        (
            "search",
            Config {
                seeding: Seeding::Search,
                ..Config::default()
            },
        ),
        (
            "fixed",
            Config {
                widen: false,
                ..Config::default()
            },
        ),
    ];
    for (name, make) in &kinds {
        for seed in 0..seeds {
            for bias in [0.0, 500.0, 3000.0, 6000.0] {
                for az in [0.5f64, -1.0] {
                    let mut rng = run_rng(23, seed * 1000 + bias as u64);
                    let scene = make(bias, az.to_radians())
                        .generate(&mut rng)
                        .expect("valid scene");
                    for (label, cfg) in &configs {
                        let o = associate::associate(&scene.radar, &scene.ais, cfg);
                        println!("{name} seed {seed} bias {bias} az {az} {label}: {o:?}");
                    }
                }
            }
        }
    }
}

fn main() {
    if std::env::args().nth(1).as_deref() == Some("dump") {
        let seeds = std::env::args()
            .nth(2)
            .and_then(|a| a.parse().ok())
            .unwrap_or(2);
        dump(seeds);
        return;
    }
    if std::env::args().nth(1).as_deref() == Some("coverage") {
        let runs = std::env::args()
            .nth(2)
            .and_then(|a| a.parse().ok())
            .unwrap_or(200);
        coverage(runs);
        return;
    }
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let repeats = args.first().copied().unwrap_or(5).max(1);
    let seeds = args.get(1).copied().unwrap_or(3).max(1);
    let az = 0.5f64.to_radians();
    let kinds: [(&str, MakeScene); 3] = [
        ("harbour72", |b, a| AisSceneConfig::harbour(72, b, a)),
        ("open_sea30", |b, a| AisSceneConfig::open_sea(30, b, a)),
        ("open_sea10", |b, a| AisSceneConfig::open_sea(10, b, a)),
    ];
    let cfg = Config::default();
    for (name, make) in &kinds {
        let (mut medians, mut minima, mut cpu_medians) = (Vec::new(), Vec::new(), Vec::new());
        for seed in 0..seeds {
            for bias in [500.0, 3000.0] {
                let mut rng = run_rng(17, seed as u64 * 1000 + bias as u64);
                let scene = make(bias, az).generate(&mut rng).expect("valid scene");
                let mut times = Vec::new();
                let mut cpu = Vec::new();
                let mut out = None;
                for _ in 0..repeats {
                    let c0 = thread_cpu_ns();
                    let start = Instant::now();
                    let o = associate::associate(&scene.radar, &scene.ais, &cfg);
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                    if let (Some(a), Some(b)) = (c0, thread_cpu_ns()) {
                        cpu.push((b - a) / 1e6);
                    }
                    out = Some(o);
                }
                cpu.sort_by(f64::total_cmp);
                let cpu_median = cpu.get(cpu.len() / 2).copied().unwrap_or(f64::NAN);
                let o = out.expect("at least one repeat");
                times.sort_by(f64::total_cmp);
                let median = times[times.len() / 2];
                medians.push(median);
                minima.push(times[0]);
                cpu_medians.push(cpu_median);
                let (mut c, mut f, mut m) = (0, 0, 0);
                let mut decisions = Vec::new();
                for j in 0..scene.ais.len() {
                    match o.associations.iter().find(|a| a.ais == j) {
                        Some(a) => {
                            decisions.push(format!("{}-{}", a.radar, j));
                            if a.radar == scene.owner[j] {
                                c += 1
                            } else {
                                f += 1
                            }
                        }
                        None => m += 1,
                    }
                }
                let (br, ba) = o.estimate.map_or((f64::NAN, f64::NAN), |e| {
                    (e.bias.range, e.bias.azimuth.to_degrees())
                });
                let reports: usize = scene.ais.iter().map(Vec::len).sum();
                println!(
                    "{name} seed {seed} bias {bias}: {median:.3} ms (min {:.3}, cpu {cpu_median:.3}) tracks {} ais {} reports {reports} \
                     c/f/m {c}/{f}/{m} bias {br:.4} m {ba:.6} deg decisions {}",
                    times[0],
                    scene.radar.len(),
                    scene.ais.len(),
                    decisions.join(",")
                );
            }
        }
        let mid = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        println!(
            "{name}: median over scenes of the per-scene medians {:.3} ms, of the minima {:.3} ms, of the CPU-time medians {:.3} ms",
            mid(&mut medians),
            mid(&mut minima),
            mid(&mut cpu_medians)
        );
    }
}
