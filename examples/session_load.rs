//! Load on streaming correlation sessions: batches per second and latency for
//! one session and for many sessions pushed concurrently, over REST and over
//! the gRPC stream, on the memory and on the Redis store, all in one run so
//! that the ratios compare like with like.
//!
//! ```sh
//! cargo run --release --example session_load -- \
//!     [--tracks 100] [--batches 200] [--warmup 40] [--sessions 1,16] \
//!     [--stores memory,redis://127.0.0.1:6379/0] [--transports rest,grpc]
//! ```
//!
//! Each configuration starts the real application in-process (REST and gRPC
//! on loopback ports), creates its sessions, and pushes `batches` batches to
//! each; a batch is one scan of both radars: `tracks` reports from node `a` at
//! t = 2k s and `tracks` from node `b` at t = 2k + 0.3 s (alignment tolerance
//! 0.5 s), straight targets with 10 m Gaussian noise, history 32 instants.
//! Each session is a closed loop (the next batch is sent when the previous
//! update arrives). The first `warmup` batches of each session, while the
//! state grows to its window, are not timed. Client and server share the
//! machine. It prints, per configuration, the throughput (timed batches over
//! the wall time of the timed part), the latency percentiles, the encoded
//! session size, the bytes the memory store holds per session, and the
//! throughput relative to the first row of the same session count.

use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use radar_fusion::{
    app::Application,
    config::Settings,
    proto::{self as pb, session_service_client::SessionServiceClient},
};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;
use serde_json::{Value, json};
use store::SessionStore;
use tokio::sync::oneshot;
use tonic::transport::Channel;

struct Args {
    tracks: usize,
    batches: usize,
    warmup: usize,
    sessions: Vec<usize>,
    stores: Vec<String>,
    transports: Vec<String>,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = Args {
        tracks: 100,
        batches: 200,
        warmup: 40,
        sessions: vec![1, 16],
        stores: vec!["memory".into(), "redis://127.0.0.1:6379/0".into()],
        transports: vec!["rest".into(), "grpc".into()],
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().with_context(|| format!("{flag} needs a value"))?;
        let list = || value.split(',').map(str::to_string).collect::<Vec<_>>();
        match flag.as_str() {
            "--tracks" => args.tracks = value.parse()?,
            "--batches" => args.batches = value.parse()?,
            "--warmup" => args.warmup = value.parse()?,
            "--sessions" => {
                args.sessions = list().iter().map(|s| s.parse()).collect::<Result<_, _>>()?
            }
            "--stores" => args.stores = list(),
            "--transports" => args.transports = list(),
            _ => bail!("unknown flag {flag}"),
        }
    }
    ensure!(
        args.warmup < args.batches,
        "--warmup must be below --batches"
    );
    Ok(args)
}

/// One report: node, track, t, state [x, vx, y, vy], diagonal covariance.
struct Report {
    node: &'static str,
    track: String,
    t: f64,
    state: [f64; 4],
}

const COV_DIAG: [f64; 4] = [100.0, 25.0, 100.0, 25.0];

/// The scans: batch k holds node a's reports at 2k and node b's at 2k + 0.3.
fn scans(tracks: usize, batches: usize) -> Vec<Vec<Report>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    (0..batches)
        .map(|k| {
            let mut batch = Vec::with_capacity(2 * tracks);
            for (node, offset) in [("a", 0.0), ("b", 0.3)] {
                for i in 0..tracks {
                    let t = 2.0 * k as f64 + offset;
                    let heading = i as f64 * 0.7;
                    let (vx, vy) = (150.0 * heading.cos(), 150.0 * heading.sin());
                    let (x0, y0) = ((i % 10) as f64 * 4000.0, (i / 10) as f64 * 4000.0);
                    let nx: f64 = rng.sample(StandardNormal);
                    let ny: f64 = rng.sample(StandardNormal);
                    batch.push(Report {
                        node,
                        track: format!("{node}{i}"),
                        t,
                        state: [x0 + vx * t + 10.0 * nx, vx, y0 + vy * t + 10.0 * ny, vy],
                    });
                }
            }
            batch
        })
        .collect()
}

fn rest_bodies(scans: &[Vec<Report>]) -> Vec<String> {
    scans
        .iter()
        .enumerate()
        .map(|(k, batch)| {
            let reports: Vec<Value> = batch
                .iter()
                .map(|r| {
                    let mut cov = [[0.0; 4]; 4];
                    for (i, row) in cov.iter_mut().enumerate() {
                        row[i] = COV_DIAG[i];
                    }
                    json!({"node": r.node, "track": r.track, "t": r.t,
                           "state": r.state, "covariance": cov})
                })
                .collect();
            json!({"sequence": k + 1, "reports": reports}).to_string()
        })
        .collect()
}

fn grpc_batches(scans: &[Vec<Report>]) -> Vec<pb::PushBatchRequest> {
    scans
        .iter()
        .enumerate()
        .map(|(k, batch)| pb::PushBatchRequest {
            sequence: Some(k as u64 + 1),
            reports: batch
                .iter()
                .map(|r| {
                    let mut values = vec![0.0; 16];
                    for (i, v) in COV_DIAG.iter().enumerate() {
                        values[i * 5] = *v;
                    }
                    pb::TrackReport {
                        node: r.node.into(),
                        track: r.track.clone(),
                        sample: Some(pb::TrackSample {
                            t: Some(r.t),
                            state: r.state.to_vec(),
                            covariance: Some(pb::Matrix {
                                rows: 4,
                                cols: 4,
                                values,
                            }),
                            gain: None,
                        }),
                    }
                })
                .collect(),
            ..Default::default()
        })
        .collect()
}

fn rest_config() -> Value {
    json!({
        "state_layout": ["x", "vx", "y", "vy"],
        "method": {"kind": "independent_double_threshold", "rule": {"l": 3, "r": 4}},
        "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0},
        "alignment": {"tolerance_s": 0.5},
        "nodes": ["a", "b"],
        "history_instants": 32,
    })
}

fn grpc_config() -> pb::CreateSessionRequest {
    pb::CreateSessionRequest {
        state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
        method: Some(pb::CorrelationMethod {
            kind: Some("independent_double_threshold".into()),
            rule: Some(pb::LrRule {
                l: Some(3),
                r: Some(4),
            }),
            ..Default::default()
        }),
        motion_model: Some(pb::MotionModel {
            process_noise: Some("dwna".into()),
            sigma_a_mps2: Some(1.0),
            ..Default::default()
        }),
        alignment: Some(pb::Alignment {
            tolerance_s: Some(0.5),
            ..Default::default()
        }),
        nodes: vec!["a".into(), "b".into()],
        history_instants: Some(32),
        ..Default::default()
    }
}

/// The latencies of the timed batches of one session, and its encoded size.
struct SessionRun {
    latencies: Vec<Duration>,
    timed_from: Instant,
    encoded_bytes: u64,
}

async fn run_rest(
    base: String,
    bodies: std::sync::Arc<Vec<String>>,
    warmup: usize,
    start_timed: std::sync::Arc<tokio::sync::Barrier>,
) -> anyhow::Result<SessionRun> {
    let client = reqwest::Client::new();
    let created: Value = client
        .post(format!("{base}/v1/sessions"))
        .json(&rest_config())
        .send()
        .await?
        .error_for_status()?
        .json()
        .await?;
    let id = created["id"].as_str().context("session id")?.to_string();
    let url = format!("{base}/v1/sessions/{id}/batches");
    let mut latencies = Vec::new();
    let mut timed_from = Instant::now();
    for (k, body) in bodies.iter().enumerate() {
        if k == warmup {
            start_timed.wait().await;
            timed_from = Instant::now();
        }
        let t = Instant::now();
        let response = client
            .post(&url)
            .header("content-type", "application/json")
            .body(body.clone())
            .send()
            .await?;
        ensure!(
            response.status() == 200,
            "batch {k}: {}",
            response.text().await?
        );
        let _update: Value = response.json().await?;
        if k >= warmup {
            latencies.push(t.elapsed());
        }
    }
    let state: Value = client
        .get(format!("{base}/v1/sessions/{id}"))
        .send()
        .await?
        .json()
        .await?;
    ensure!(
        state["batches"].as_u64() == Some(bodies.len() as u64),
        "{state}"
    );
    Ok(SessionRun {
        latencies,
        timed_from,
        encoded_bytes: state["encoded_bytes"].as_u64().unwrap_or_default(),
    })
}

async fn run_grpc(
    channel: Channel,
    batches: std::sync::Arc<Vec<pb::PushBatchRequest>>,
    warmup: usize,
    start_timed: std::sync::Arc<tokio::sync::Barrier>,
) -> anyhow::Result<SessionRun> {
    let mut client = SessionServiceClient::new(channel);
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    tx.send(pb::StreamRequest {
        kind: Some(pb::stream_request::Kind::Open(grpc_config())),
    })
    .await?;
    let mut updates = client
        .stream(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await?
        .into_inner();
    let opened = updates.message().await?.context("the stream opens")?;
    let id = opened.session_id;
    let mut latencies = Vec::new();
    let mut timed_from = Instant::now();
    for (k, batch) in batches.iter().enumerate() {
        if k == warmup {
            start_timed.wait().await;
            timed_from = Instant::now();
        }
        let t = Instant::now();
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(batch.clone())),
        })
        .await?;
        let update = updates.message().await?.context("an update per batch")?;
        ensure!(update.sequence == batch.sequence && !update.duplicate);
        if k >= warmup {
            latencies.push(t.elapsed());
        }
    }
    drop(tx);
    let state = client
        .get_session(pb::GetSessionRequest { session_id: id })
        .await?
        .into_inner();
    ensure!(state.batches == batches.len() as u64);
    Ok(SessionRun {
        latencies,
        timed_from,
        encoded_bytes: state.encoded_bytes,
    })
}

struct Row {
    store: String,
    transport: String,
    sessions: usize,
    batches_per_s: f64,
    p50_ms: f64,
    p99_ms: f64,
    encoded_bytes: u64,
    /// Bytes the memory store holds per session (None for Redis).
    store_bytes_per_session: Option<f64>,
}

async fn run_config(
    args: &Args,
    store: &str,
    transport: &str,
    sessions: usize,
    bodies: &std::sync::Arc<Vec<String>>,
    grpc: &std::sync::Arc<Vec<pb::PushBatchRequest>>,
) -> anyhow::Result<Row> {
    let mut settings = Settings::for_tests();
    settings.session_store = store.to_string();
    settings.session_key_prefix = format!("radar-fusion-load:{}", std::process::id());
    settings.max_sessions_per_tenant = sessions.max(100);
    settings.session_memory_bytes = 16 << 30;
    settings.session_memory_bytes_per_tenant = 16 << 30;
    let app = Application::build(settings).await?;
    let (http, grpc_addr, state) = (app.http_addr(), app.grpc_addr(), app.state());
    let (stop, stopped) = oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async move {
        let _ = stopped.await;
    }));
    for _ in 0..400 {
        if state.is_ready() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    ensure!(state.is_ready(), "the application did not become ready");
    let channel = Channel::from_shared(format!("http://{grpc_addr}"))?
        .connect()
        .await?;

    let barrier = std::sync::Arc::new(tokio::sync::Barrier::new(sessions));
    let mut tasks = Vec::new();
    for _ in 0..sessions {
        let barrier = barrier.clone();
        tasks.push(match transport {
            "rest" => tokio::spawn(run_rest(
                format!("http://{http}"),
                bodies.clone(),
                args.warmup,
                barrier,
            )),
            "grpc" => tokio::spawn(run_grpc(
                channel.clone(),
                grpc.clone(),
                args.warmup,
                barrier,
            )),
            other => bail!("unknown transport {other} (rest or grpc)"),
        });
    }
    let mut runs = Vec::new();
    for task in tasks {
        runs.push(task.await??);
    }
    let finished = Instant::now();
    let timed_from = runs
        .iter()
        .map(|r| r.timed_from)
        .min()
        .context("a session")?;
    let mut latencies: Vec<Duration> = runs.iter().flat_map(|r| r.latencies.clone()).collect();
    latencies.sort();
    let pct = |p: f64| {
        let i = ((latencies.len() as f64 * p).ceil() as usize).clamp(1, latencies.len()) - 1;
        latencies[i].as_secs_f64() * 1e3
    };
    let row = Row {
        store: if store == "memory" { "memory" } else { "redis" }.into(),
        transport: transport.into(),
        sessions,
        batches_per_s: latencies.len() as f64 / (finished - timed_from).as_secs_f64(),
        p50_ms: pct(0.5),
        p99_ms: pct(0.99),
        encoded_bytes: runs.iter().map(|r| r.encoded_bytes).max().unwrap_or(0),
        store_bytes_per_session: match state.store() {
            SessionStore::Memory(m) => Some(m.bytes() as f64 / sessions as f64),
            SessionStore::Redis(_) => None,
        },
    };
    // Delete the sessions (Redis keys) and stop the servers.
    let client = reqwest::Client::new();
    let list: Value = client
        .get(format!("http://{http}/v1/sessions"))
        .send()
        .await?
        .json()
        .await?;
    for s in list["sessions"].as_array().into_iter().flatten() {
        let id = s["id"].as_str().unwrap_or_default();
        client
            .delete(format!("http://{http}/v1/sessions/{id}"))
            .send()
            .await?;
    }
    let _ = stop.send(());
    server.await??;
    Ok(row)
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let scans = scans(args.tracks, args.batches);
    let bodies = std::sync::Arc::new(rest_bodies(&scans));
    let grpc = std::sync::Arc::new(grpc_batches(&scans));
    println!(
        "# {} tracks per node, 2 nodes, {} reports per batch, {} batches per session \
         ({} untimed), history 32 instants",
        args.tracks,
        2 * args.tracks,
        args.batches,
        args.warmup
    );
    println!(
        "| store | transport | sessions | batches/s | vs first row | p50 ms | p99 ms | \
         encoded session | memory store per session |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for &sessions in &args.sessions {
        let mut first: Option<f64> = None;
        for store in &args.stores {
            for transport in &args.transports {
                let row = run_config(&args, store, transport, sessions, &bodies, &grpc)
                    .await
                    .with_context(|| format!("{store} {transport} ×{sessions}"))?;
                let base = *first.get_or_insert(row.batches_per_s);
                println!(
                    "| {} | {} | {} | {:.1} | {:.2} | {:.1} | {:.1} | {:.0} kB | {} |",
                    row.store,
                    row.transport,
                    row.sessions,
                    row.batches_per_s,
                    row.batches_per_s / base,
                    row.p50_ms,
                    row.p99_ms,
                    row.encoded_bytes as f64 / 1e3,
                    row.store_bytes_per_session
                        .map_or("(in Redis)".to_string(), |b| format!("{:.0} kB", b / 1e3))
                );
            }
        }
    }
    Ok(())
}
