//! Benchmarks of batch track-to-track correlation.
//!
//! Engine (issue 14): every method on the realistic scene of
//! `eval::benchmark::realistic_scene` (two radars' Kalman
//! tracks of the same targets, already aligned), timing the pair correlator
//! and the grouping on the prebuilt scene, so that alignment changes do not
//! move the figures. `cargo bench --bench correlation` runs 120 × 120 tracks
//! × 12 instants for each method in criterion, then the service benchmarks
//! below.
//!
//! `cargo bench --bench correlation -- --engine [120|10000]` prints, in one
//! run, the median engine compute of 120 × 120 × 12 for every method and of
//! 10,000 × 10,000 × 11 for the weighted and independent double-threshold
//! methods, each next to the service's `timing.correlate_us` on the same
//! samples for reference; a method name after the size keeps that method only.
//!
//! Service: two nodes, n targets each, 8 samples per track, the independent
//! double-threshold method (6/8), with the spatial grid and by brute force
//! over all pairs, through the service-layer function the endpoints call
//! (scene: `eval::benchmark::correlation_request`). Criterion
//! runs 120 and 1000; `cargo bench --bench correlation -- --once 10000`
//! times one 10k × 10k request each way (brute force there is 10⁸ pairs × 8
//! instants).
//!
//! `cargo bench --bench correlation -- --small [repeat] [n] [body.json]`
//! repeats the small request of issue 18 (n = 5 targets, 2 nodes × 8
//! samples, the body of `correlation_payload 5 grid`) through the service
//! function and prints the median and minimum of its compute, align,
//! correlate and fuse times (and is the loop to run under `perf record`);
//! given the request's JSON body, it also times the REST adapter's work on
//! the compute lane: parsing the body, the handler (conversion, service,
//! answer) and encoding the answer.

use std::{hint::black_box, time::Instant};

use algo::correlation::engine::{Decision, Pruning};
use common::{median, median_min};
use criterion::{BatchSize, Criterion, criterion_group};
use eval::benchmark::{
    METHODS, RealisticScene, correlate_scene, correlation_request, engine_config, realistic_scene,
};
use radar_fusion::http::{correlation as http, problem::parse_json};
use service::correlation::{CorrelateInput, MethodInput, correlate};

mod common;

/// The server's allocator, so that allocation costs what it costs there.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn scene(n: usize, pruning: &str) -> CorrelateInput {
    correlation_request(n, pruning)
}

fn bench_engine(c: &mut Criterion) {
    let s = realistic_scene(120, 12, false);
    let mut group = c.benchmark_group("correlation_engine");
    group.sample_size(30);
    for method in METHODS {
        let cfg = engine_config(method, Pruning::Grid);
        group.bench_function(format!("120x120x12 {method}"), |b| {
            b.iter(|| correlate_scene(black_box(&s), &cfg))
        });
    }
    group.finish();
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

criterion_group!(benches, bench_engine, bench);

/// One line of the engine table: median engine compute over `runs` runs and
/// the service's correlate time (median over `service_runs`).
fn engine_line(s: &RealisticScene, label: &str, method: &str, runs: usize, service_runs: usize) {
    let cfg = engine_config(method, Pruning::Grid);
    let mut times = Vec::with_capacity(runs);
    let mut outcome = None;
    for _ in 0..runs {
        let start = Instant::now();
        let o = correlate_scene(black_box(s), &cfg);
        times.push(start.elapsed().as_secs_f64() * 1e3);
        outcome = Some(o);
    }
    let o = outcome.expect("at least one run");
    let mut service = Vec::with_capacity(service_runs);
    let mut service_correlated = 0;
    for _ in 0..service_runs {
        let mut input = s.request.clone();
        input.method = Some(MethodInput {
            kind: Some(method.into()),
            ..Default::default()
        });
        input.fuse = Some(false);
        let out = correlate(input).expect("valid request");
        service.push(out.timing.correlate_us / 1e3);
        service_correlated = out
            .pairs
            .iter()
            .filter(|p| p.decision == Decision::Correlated)
            .count();
    }
    println!(
        "| {label} | {method} | {:.3} | {:.3} | {:.3} | {} | {} | {} | {} |",
        median(times.clone()),
        times.iter().copied().fold(f64::INFINITY, f64::min),
        median(service),
        o.pairs,
        o.correlated,
        o.right,
        service_correlated,
    );
}

fn engine_table(only: Option<usize>, method_only: Option<&str>) {
    let wanted = |m: &str| method_only.is_none_or(|o| o == m);
    println!(
        "| scene | method | engine median ms | engine min ms | service correlate_us median ms | candidate pairs | correlated | right | service correlated |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    if only.is_none_or(|n| n == 120) {
        let s = realistic_scene(120, 12, false);
        for method in METHODS.into_iter().filter(|m| wanted(m)) {
            engine_line(&s, "120x120x12", method, 101, 11);
        }
    }
    if only.is_none_or(|n| n == 10_000) {
        let s = realistic_scene(10_000, 11, false);
        for method in ["weighted", "independent_double_threshold"]
            .into_iter()
            .filter(|m| wanted(m))
        {
            engine_line(&s, "10000x10000x11", method, 3, 1);
        }
    }
}

/// Median and minimum of the small request's timings over `repeat` calls.
fn small_table(repeat: usize, n: usize) {
    let input = scene(n, "grid");
    let mut times: [Vec<f64>; 5] = Default::default();
    for _ in 0..repeat {
        let copy = input.clone();
        let start = Instant::now();
        let out = black_box(correlate(black_box(copy)).expect("valid scene"));
        times[0].push(start.elapsed().as_secs_f64() * 1e6);
        times[1].push(out.timing.compute_us);
        times[2].push(out.timing.align_us);
        times[3].push(out.timing.correlate_us);
        times[4].push(out.timing.fuse_us);
    }
    println!("{n}x{n}x8 grid, {repeat} calls, µs: median (min)");
    print_median_min(&["call", "compute", "align", "correlate", "fuse"], times);
}

/// One line per timing: its median and (minimum).
fn print_median_min<const N: usize>(names: &[&str; N], times: [Vec<f64>; N]) {
    for (name, t) in names.iter().zip(times) {
        let (median, min) = median_min(&t);
        println!("  {name:>9}: {median:8.2} ({min:.2})");
    }
}

/// Median and minimum of the REST adapter's parse, handler and encoding
/// times for the JSON body in `path`.
fn small_rest(repeat: usize, path: &str) {
    let body = std::fs::read(path).expect("the body file reads");
    let mut times: [Vec<f64>; 3] = Default::default();
    let mut size = 0;
    for _ in 0..repeat {
        let t0 = Instant::now();
        let req: http::CorrelateTracksRequest =
            black_box(parse_json(black_box(&body)).expect("the body parses"));
        let t1 = Instant::now();
        let answer = black_box(http::correlate_on_lane(req).expect("the request is valid"));
        let t2 = Instant::now();
        let encoded = black_box(serde_json::to_vec(&answer).expect("the answer encodes"));
        let t3 = Instant::now();
        size = encoded.len();
        for (k, (a, b)) in [(t0, t1), (t1, t2), (t2, t3)].into_iter().enumerate() {
            times[k].push((b - a).as_secs_f64() * 1e6);
        }
    }
    println!(
        "REST on the lane, {} bytes in, {size} bytes out, µs: median (min)",
        body.len()
    );
    print_median_min(&["parse", "handler", "encode"], times);
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--engine") {
        engine_table(
            args.get(i + 1).and_then(|s| s.parse().ok()),
            args.get(i + 2).map(String::as_str),
        );
        return;
    }
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
                .filter(|p| p.decision == Decision::Correlated)
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
    if let Some(i) = args.iter().position(|a| a == "--small") {
        let repeat: usize = args
            .get(i + 1)
            .and_then(|s| s.parse().ok())
            .unwrap_or(20_000);
        let n: usize = args.get(i + 2).and_then(|s| s.parse().ok()).unwrap_or(5);
        small_table(repeat, n);
        if let Some(path) = args.get(i + 3) {
            small_rest(repeat, path);
        }
        return;
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
