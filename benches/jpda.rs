//! Time per scan of JPDA (seed 002) on the scenes of issue 6: 5, 10 and 20
//! targets with 6 detections each in one dense (chain-shaped) cluster and
//! well separated, and 100 targets; exact JPDA, AMSJPDA and naive
//! enumeration in the same run. `scan/*` is the whole single-sensor update
//! (gating, clustering, β, combined update); `beta/*` is β alone on the
//! scene's clusters, where naive enumeration is run when the product of
//! the gate sizes (a bound on the number of joint events) is at most 10⁸.

use std::hint::black_box;

use criterion::{BatchSize, Criterion, criterion_group, criterion_main};
use radar_fusion::{
    algo::jpda::{
        self, Config, Method, amsjpda_marginals, cluster_problems, exact_marginals, naive_marginals,
    },
    sim::experiments::seed002_jpda::bench_scene,
};

const DETECTIONS: usize = 6;
const NAIVE_EVENT_BOUND: f64 = 1e8;

fn bench_jpda(c: &mut Criterion) {
    let mut group = c.benchmark_group("jpda");
    group.sample_size(10);
    group.warm_up_time(std::time::Duration::from_millis(500));
    group.measurement_time(std::time::Duration::from_secs(2));
    for (targets, dense) in [
        (5, true),
        (7, true),
        (10, true),
        (20, true),
        (100, true),
        (5, false),
        (10, false),
        (20, false),
        (100, false),
    ] {
        let label = format!("{}{targets}", if dense { "dense" } else { "separated" });
        let (tracks, scan) = bench_scene(targets, DETECTIONS, dense, 2002);
        for (method, name) in [(Method::Exact, "exact"), (Method::Amsjpda, "amsjpda")] {
            let config = Config {
                method,
                max_exact_tracks: 128,
                max_hypotheses: u64::MAX,
            };
            group.bench_function(format!("scan/{name}/{label}"), |b| {
                b.iter_batched_ref(
                    || tracks.clone(),
                    |t| jpda::scan(t, black_box(&scan), &config).expect("scan"),
                    BatchSize::SmallInput,
                )
            });
        }
        let problems = cluster_problems(&tracks, &scan).expect("problems");
        let largest = problems.iter().map(|p| p.gates.len()).max().unwrap_or(0);
        let bound: f64 = problems
            .iter()
            .map(|p| {
                p.gates
                    .iter()
                    .map(|g| (g.len() + 1) as f64)
                    .product::<f64>()
            })
            .fold(0.0, f64::max);
        let edges: u64 = problems
            .iter()
            .map(|p| exact_marginals(p, u64::MAX).map_or(0, |m| m.hypotheses))
            .sum();
        eprintln!(
            "{label}: {} clusters, largest {largest} tracks, event bound {bound:.3e}, \
             exact edges {edges}",
            problems.len()
        );
        group.bench_function(format!("beta/exact/{label}"), |b| {
            b.iter(|| {
                for p in &problems {
                    black_box(exact_marginals(black_box(p), u64::MAX).expect("exact"));
                }
            })
        });
        group.bench_function(format!("beta/amsjpda/{label}"), |b| {
            b.iter(|| {
                for p in &problems {
                    black_box(amsjpda_marginals(black_box(p)));
                }
            })
        });
        if bound <= NAIVE_EVENT_BOUND {
            let events: u64 = problems.iter().map(|p| naive_marginals(p).hypotheses).sum();
            eprintln!("{label}: naive enumerates {events} joint events");
            group.bench_function(format!("beta/naive/{label}"), |b| {
                b.iter(|| {
                    for p in &problems {
                        black_box(naive_marginals(black_box(p)));
                    }
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_jpda);
criterion_main!(benches);
