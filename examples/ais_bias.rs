//! AIS–radar association benchmark (issue 17): the compute time of one
//! `associate` call on a busy harbour (72 radar tracks, 20 minutes of AIS,
//! moored ships 10–70 m apart, a quarter without AIS) and on seed 004's open
//! sea (10 and 30 ships), with the decisions and the bias of every scene so
//! two builds can be compared line by line.
//!
//! ```sh
//! cargo run --release --example ais_bias [-- REPEATS SEEDS]
//! ```
//!
//! Output: one line per scene, `kind seed bias_range_m: median_ms min_ms
//! cpu median_ms correct/false/missed est_range_m est_azimuth_deg
//! decisions`. CPU time is the thread's own (from /proc/thread-self/schedstat),
//! so other processes on a shared machine do not inflate it.

use std::time::Instant;

use radar_fusion::algo::bias::associate::{self, Config};
use radar_fusion::sim::ais::AisSceneConfig;
use radar_fusion::sim::montecarlo::run_rng;

/// Nanoseconds this thread has run on a CPU (Linux), if readable.
fn thread_cpu_ns() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let repeats = args.first().copied().unwrap_or(5).max(1);
    let seeds = args.get(1).copied().unwrap_or(3).max(1);
    let kinds: Vec<(&str, Box<dyn Fn(f64) -> AisSceneConfig>)> = vec![
        (
            "harbour72",
            Box::new(|b| AisSceneConfig::harbour(72, b, 0.5f64.to_radians())),
        ),
        (
            "open_sea30",
            Box::new(|b| AisSceneConfig::open_sea(30, b, 0.5f64.to_radians())),
        ),
        (
            "open_sea10",
            Box::new(|b| AisSceneConfig::open_sea(10, b, 0.5f64.to_radians())),
        ),
    ];
    let cfg = Config::default();
    for (name, make) in &kinds {
        let mut medians = Vec::new();
        for seed in 0..seeds {
            for bias in [500.0, 3000.0] {
                let mut rng = run_rng(17, seed as u64 * 1000 + bias as u64);
                let scene = make(bias).generate(&mut rng).expect("valid scene");
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
                medians.push(cpu_median);
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
        medians.sort_by(f64::total_cmp);
        println!(
            "{name}: median over scenes of the CPU-time medians {:.3} ms",
            medians[medians.len() / 2]
        );
    }
}
