//! Writes the correlation benchmark request (`sim::benchmark`) as the JSON
//! body of `POST /v1/correlation/tracks`, for load tests through REST:
//!
//! ```sh
//! cargo run --release --example correlation_payload -- 120 grid > /tmp/corr-120.json
//! wrk -t2 -c4 -d10s --latency -s benches/load/correlation.lua http://127.0.0.1:8080
//! ```

use eval::benchmark::correlation_request;
use serde_json::{Value, json};

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().map_or(Ok(120), |s| s.parse())?;
    let pruning = args.next().unwrap_or_else(|| "grid".into());
    let input = correlation_request(n, &pruning);
    let method = input.method.expect("the benchmark names a method");
    let rule = method.rule.expect("the benchmark names a rule");
    let nodes: Vec<Value> = input
        .nodes
        .iter()
        .map(|node| {
            json!({
                "id": node.id,
                "tracks": node.tracks.iter().map(|t| json!({
                    "id": t.id,
                    "samples": t.samples.iter().map(|s| json!({
                        "t": s.t,
                        "state": s.state,
                        "covariance": s.covariance,
                    })).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let body = json!({
        "state_layout": input.state_layout,
        "method": {"kind": method.kind, "rule": {"l": rule.l, "r": rule.r}},
        "nodes": nodes,
        "pruning": input.pruning,
    });
    println!("{body}");
    Ok(())
}
