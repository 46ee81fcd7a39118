//! Time per scan of JPDA (seed 002) on the scenes of issue 6: 5, 10 and 20
//! targets with 6 detections each in one dense (chain-shaped) cluster and
//! well separated, and 100 targets; exact JPDA, AMSJPDA and naive
//! enumeration in the same run. `scan/*` is the whole single-sensor update
//! (gating, clustering, β, combined update); `beta/*` is β alone on the
//! scene's clusters, where naive enumeration is run when the product of
//! the gate sizes (a bound on the number of joint events) is at most 10⁸.
//!
//! `cargo bench --bench jpda -- --request BODY.json BODY.pb [repeat]` times
//! issue 18's request in process, one stage at a time: the REST adapter's
//! parse, handler (conversion, validation, compute, answer) and encoding of
//! the JSON body, and the gRPC adapter's decoding, handler and encoding of
//! the protobuf message, with the algorithm's own `compute_us` beside them
//! (`request_path --dump BODY.json --dump-proto BODY.pb` writes both).

use std::{hint::black_box, time::Instant};

use algo::jpda::{
    self, Config, Method, amsjpda_marginals, cluster_problems, exact_marginals, naive_marginals,
};
use common::median_min;
use criterion::{BatchSize, Criterion, criterion_group};
use eval::experiments::seed002_jpda::bench_scene;
use prost::Message;
use radar_fusion::{grpc, http, http::problem::parse_json, proto as pb};

mod common;

/// The server's allocator, so that allocation costs what it costs there.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

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

/// Median and minimum of each stage of the request over `repeat` calls per
/// transport, calls alternating between the transports.
fn request_table(json_path: &str, proto_path: &str, repeat: usize) {
    let json = std::fs::read(json_path).expect("the JSON body reads");
    let proto = std::fs::read(proto_path).expect("the protobuf body reads");
    let mut rest: [Vec<f64>; 4] = Default::default();
    let mut grpc: [Vec<f64>; 4] = Default::default();
    let mut sizes = (0, 0);
    let us = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e6;
    for _ in 0..repeat {
        let t0 = Instant::now();
        let req: http::jpda::JpdaUpdateRequest =
            black_box(parse_json(black_box(&json)).expect("the body parses"));
        let t1 = Instant::now();
        let answer = black_box(http::jpda::update_on_lane(req).expect("the request is valid"));
        let t2 = Instant::now();
        let encoded = black_box(serde_json::to_vec(&answer).expect("the answer encodes"));
        let t3 = Instant::now();
        sizes.0 = encoded.len();
        record(
            &mut rest,
            [us(t0, t1), us(t1, t2), answer.timing.compute_us, us(t2, t3)],
        );
        drop((answer, encoded));
        let t0 = Instant::now();
        let req = black_box(pb::JpdaUpdateRequest::decode(black_box(&proto[..])).expect("decodes"));
        let t1 = Instant::now();
        let answer = black_box(grpc::jpda::update_on_lane(req).expect("the request is valid"));
        let t2 = Instant::now();
        let encoded = black_box(answer.encode_to_vec());
        let t3 = Instant::now();
        sizes.1 = encoded.len();
        let compute = answer.timing.map_or(f64::NAN, |t| t.compute_us);
        record(&mut grpc, [us(t0, t1), us(t1, t2), compute, us(t2, t3)]);
    }
    println!(
        "REST, {} bytes in, {} bytes out; gRPC, {} bytes in, {} bytes out; {repeat} calls each, µs: median (min)",
        json.len(),
        sizes.0,
        proto.len(),
        sizes.1
    );
    let names = ["parse", "handler", "compute", "encode"];
    for (label, times) in [("REST", rest), ("gRPC", grpc)] {
        let stats: Vec<(f64, f64)> = times.iter().map(|t| median_min(t)).collect();
        let medians: Vec<f64> = stats.iter().map(|&(m, _)| m).collect();
        let line: Vec<String> = names
            .iter()
            .zip(&stats)
            .map(|(name, (m, min))| format!("{name} {m:.1} ({min:.1})"))
            .collect();
        let total = medians[0] + medians[1] + medians[3];
        println!(
            "  {label}: {}; parse + handler + encode = {total:.1} = {:.2}× compute",
            line.join(", "),
            total / medians[2]
        );
    }
}

/// Appends one call's stage times to their series.
fn record<const N: usize>(series: &mut [Vec<f64>; N], times: [f64; N]) {
    for (s, t) in series.iter_mut().zip(times) {
        s.push(t);
    }
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(i) = args.iter().position(|a| a == "--request") {
        let (Some(json), Some(proto)) = (args.get(i + 1), args.get(i + 2)) else {
            eprintln!("usage: --request BODY.json BODY.pb [repeat]");
            std::process::exit(2);
        };
        let repeat = args.get(i + 3).and_then(|s| s.parse().ok()).unwrap_or(200);
        request_table(json, proto, repeat);
        return;
    }
    benches();
    criterion::Criterion::default()
        .configure_from_args()
        .final_summary();
}
