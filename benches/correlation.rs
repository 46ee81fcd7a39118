//! Benchmarks of batch track-to-track correlation (issue: "at any scale"):
//! two nodes, n targets each, 8 samples per track, the independent
//! double-threshold method (6/8), with the spatial grid and by brute force
//! over all pairs, through the service-layer function the endpoints call.
//!
//! Scene: `radar_fusion::sim::benchmark::correlation_request`.
//!
//! `cargo bench --bench correlation` runs 120 and 1000 in criterion;
//! `cargo bench --bench correlation -- --once 10000` times one 10k × 10k
//! request each way (brute force there is 10⁸ pairs × 8 instants).

use std::{hint::black_box, time::Instant};

use criterion::{BatchSize, Criterion, criterion_group};
use radar_fusion::{
    service::correlation::{CorrelateInput, correlate},
    sim::benchmark::correlation_request,
};

fn scene(n: usize, pruning: &str) -> CorrelateInput {
    correlation_request(n, pruning)
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("correlate_tracks");
    group.sample_size(10);
    for n in [120, 1000] {
        for pruning in ["grid", "none"] {
            let input = scene(n, pruning);
            group.bench_function(format!("{n}x{n}x8 {pruning}"), |b| {
                // The clone is setup, outside the timing: the service receives
                // the request by value.
                b.iter_batched(
                    || input.clone(),
                    |i| correlate(black_box(i)).expect("valid scene"),
                    BatchSize::LargeInput,
                )
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--once") {
        let n: usize = args
            .get(i + 1)
            .and_then(|s| s.parse().ok())
            .unwrap_or(10_000);
        let only = args.get(i + 2).map(String::as_str);
        for pruning in ["grid", "none"] {
            if only.is_some_and(|o| o != pruning) {
                continue;
            }
            let input = scene(n, pruning);
            let start = Instant::now();
            let out = correlate(input).expect("valid scene");
            let correlated = out
                .pairs
                .iter()
                .filter(|p| {
                    p.decision == radar_fusion::algo::correlation::engine::Decision::Correlated
                })
                .count();
            println!(
                "{n}x{n}x8 {pruning}: {:.4} s wall, compute {:.4} s (align {:.4} s, correlate {:.4} s, fuse {:.4} s), {} correlated, {} listed pairs",
                start.elapsed().as_secs_f64(),
                out.timing.compute_us / 1e6,
                out.timing.align_us / 1e6,
                out.timing.correlate_us / 1e6,
                out.timing.fuse_us / 1e6,
                correlated,
                out.pairs.len()
            );
        }
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
