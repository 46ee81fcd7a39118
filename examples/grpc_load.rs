//! A closed-loop gRPC load generator for `CorrelationService/EvaluateRules`,
//! to measure latency on loopback at a fixed concurrency:
//!
//! ```sh
//! cargo run --release --example grpc_load -- 127.0.0.1:50051 16 10
//! ```
//! (address, concurrent callers, seconds). It prints the request count, the
//! throughput and the latency percentiles.

use std::time::{Duration, Instant};

use radar_fusion::proto::{
    EvaluateRulesRequest, LrRule, correlation_service_client::CorrelationServiceClient,
};

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let addr = args.next().unwrap_or_else(|| "127.0.0.1:50051".into());
    let concurrency: usize = args.next().map_or(Ok(16), |s| s.parse())?;
    let seconds: f64 = args.next().map_or(Ok(10.0), |s| s.parse())?;
    let duration = Duration::from_secs_f64(seconds);

    let request = EvaluateRulesRequest {
        alpha: Some(0.05),
        rules: vec![
            LrRule {
                l: Some(3),
                r: Some(4),
            },
            LrRule {
                l: Some(6),
                r: Some(8),
            },
        ],
    };
    // Four HTTP/2 connections shared by the callers, as a client library would pool them.
    let mut clients = Vec::new();
    for _ in 0..4 {
        clients.push(CorrelationServiceClient::connect(format!("http://{addr}")).await?);
    }
    let start = Instant::now();
    let mut tasks = Vec::new();
    for i in 0..concurrency {
        let mut client = clients[i % clients.len()].clone();
        let request = request.clone();
        tasks.push(tokio::spawn(async move {
            let mut latencies = Vec::new();
            let mut errors = 0usize;
            while start.elapsed() < duration {
                let t = Instant::now();
                match client.evaluate_rules(request.clone()).await {
                    Ok(_) => latencies.push(t.elapsed()),
                    Err(_) => errors += 1,
                }
            }
            (latencies, errors)
        }));
    }
    let mut all = Vec::new();
    let mut errors = 0;
    for task in tasks {
        let (l, e) = task.await?;
        all.extend(l);
        errors += e;
    }
    let elapsed = start.elapsed().as_secs_f64();
    all.sort();
    let pct = |p: f64| {
        let i = ((all.len() as f64 * p).ceil() as usize).clamp(1, all.len()) - 1;
        all[i].as_secs_f64() * 1e6
    };
    anyhow::ensure!(!all.is_empty(), "no request succeeded ({errors} errors)");
    println!(
        "requests {} errors {} concurrency {} duration {:.1}s throughput {:.0}/s \
         latency p50 {:.0} us p90 {:.0} us p99 {:.0} us max {:.0} us",
        all.len(),
        errors,
        concurrency,
        elapsed,
        all.len() as f64 / elapsed,
        pct(0.50),
        pct(0.90),
        pct(0.99),
        pct(1.0)
    );
    Ok(())
}
