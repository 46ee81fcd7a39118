//! Where a request's time goes: the JPDA update of 500 separated targets
//! (issue 18's request, `seed002_jpda::bench_scene`) over REST and gRPC
//! against a running server, with three times side by side per call:
//! - `compute`: the service's own `timing.compute_us` (the algorithm);
//! - `server`: the server's time for the request from its metrics
//!   (`http_request_duration_seconds` / `grpc_request_duration_seconds`
//!   sum over count for the route, read before and after): parsing,
//!   validation, compute, response encoding, every layer;
//! - `client`: wall time at the client on loopback (request bytes prepared
//!   beforehand; the response read as bytes and decoded after the clock).
//!
//! ```sh
//! cargo run --release --bin radar-fusion &    # or any running server
//! cargo run --release --example request_path -- [--url http://127.0.0.1:8080]
//!     [--grpc http://127.0.0.1:50051] [--targets 500] [--repeat 200] [--dump FILE]
//!     [--dump-proto FILE] [--only rest|grpc]
//! ```

use std::time::{Duration, Instant};

use algo::jpda::{Clutter, SensorModel};
use eval::experiments::seed002_jpda::bench_scene;
use radar_fusion::proto as pb;
use serde_json::{Value, json};

struct Args {
    url: String,
    grpc: String,
    targets: usize,
    repeat: usize,
    /// Write the JSON request to this file and exit (for wrk or perf).
    dump: Option<String>,
    /// Write the protobuf request message to this file and exit.
    dump_proto: Option<String>,
    /// Run only this transport (`rest` or `grpc`), e.g. under a profiler.
    only: Option<String>,
}

fn args() -> anyhow::Result<Args> {
    let mut a = Args {
        url: "http://127.0.0.1:8080".into(),
        grpc: "http://127.0.0.1:50051".into(),
        targets: 500,
        repeat: 200,
        dump: None,
        dump_proto: None,
        only: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{flag} needs a value"))
        };
        match flag.as_str() {
            "--url" => a.url = value()?,
            "--grpc" => a.grpc = value()?,
            "--targets" => a.targets = value()?.parse()?,
            "--repeat" => a.repeat = value()?.parse()?,
            "--dump" => a.dump = Some(value()?),
            "--dump-proto" => a.dump_proto = Some(value()?),
            "--only" => a.only = Some(value()?),
            other => anyhow::bail!("unknown flag {other}"),
        }
    }
    Ok(a)
}

/// The request as JSON and as proto.
fn requests(targets: usize) -> (Vec<u8>, pb::JpdaUpdateRequest) {
    let (tracks, scan) = bench_scene(targets, 3, false, 1);
    let SensorModel::Linear { h, r } = &scan.model else {
        unreachable!("the bench scene is linear")
    };
    let Clutter::Density(lambda) = scan.clutter else {
        unreachable!("the bench scene has a clutter density")
    };
    let rows = |m: &nalgebra::DMatrix<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows())
            .map(|i| (0..m.ncols()).map(|j| m[(i, j)]).collect())
            .collect()
    };
    let matrix = |m: &nalgebra::DMatrix<f64>| pb::Matrix {
        rows: m.nrows() as u32,
        cols: m.ncols() as u32,
        values: rows(m).concat(),
    };
    let body = json!({
        "method": "exact",
        "tracks": tracks.iter().enumerate().map(|(i, t)| json!({
            "id": format!("t{i}"),
            "state": t.x.as_slice(),
            "covariance": rows(&t.p),
        })).collect::<Vec<_>>(),
        "sensors": [{
            "id": "radar",
            "kind": "linear",
            "h": rows(h),
            "r": rows(r),
            "detection_probability": scan.detection_probability,
            "clutter_density": lambda,
            "measurements": scan.measurements.iter().map(|z| json!({"z": z.as_slice()})).collect::<Vec<_>>(),
        }],
    });
    let proto = pb::JpdaUpdateRequest {
        method: Some("exact".into()),
        tracks: tracks
            .iter()
            .enumerate()
            .map(|(i, t)| pb::JpdaTrack {
                id: Some(format!("t{i}")),
                state: t.x.as_slice().to_vec(),
                covariance: Some(matrix(&t.p)),
            })
            .collect(),
        sensors: vec![pb::JpdaSensor {
            id: Some("radar".into()),
            kind: Some("linear".into()),
            h: Some(matrix(h)),
            r: Some(matrix(r)),
            detection_probability: Some(scan.detection_probability),
            clutter_density: Some(lambda),
            measurements: scan
                .measurements
                .iter()
                .map(|z| pb::JpdaMeasurement {
                    z: z.as_slice().to_vec(),
                    ..Default::default()
                })
                .collect(),
            ..Default::default()
        }],
        ..Default::default()
    };
    (serde_json::to_vec(&body).expect("JSON"), proto)
}

/// Sum and count of a duration histogram's series whose labels contain
/// every one of `labels`.
async fn histogram(client: &reqwest::Client, url: &str, name: &str, labels: &[&str]) -> (f64, f64) {
    let text = client
        .get(format!("{url}/metrics"))
        .send()
        .await
        .expect("metrics")
        .text()
        .await
        .expect("metrics text");
    let pick = |suffix: &str| -> f64 {
        text.lines()
            .filter(|l| l.starts_with(&format!("{name}_{suffix}")))
            .filter(|l| labels.iter().all(|want| l.contains(want)))
            .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .sum()
    };
    (pick("sum"), pick("count"))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// One line per transport. The server's time is a mean (the histogram's
/// sum over its count), so it is set against the mean compute; the
/// client's median against the median compute.
fn report(name: &str, compute: Vec<f64>, client: Vec<f64>, server_mean_ms: f64) {
    let mean = compute.iter().sum::<f64>() / compute.len() as f64;
    let (c, w) = (median(compute), median(client));
    println!(
        "{name:<6} compute {c:7.3} ms (median), {mean:7.3} ms (mean) | server {server_mean_ms:7.3} ms (mean) = {:5.2}× compute | client {w:7.3} ms (median) = {:5.2}× compute",
        server_mean_ms / mean,
        w / c
    );
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> anyhow::Result<()> {
    let a = args()?;
    let (json_body, proto) = requests(a.targets);
    if let Some(path) = &a.dump {
        std::fs::write(path, &json_body)?;
    }
    if let Some(path) = &a.dump_proto {
        std::fs::write(path, prost::Message::encode_to_vec(&proto))?;
    }
    if a.dump.is_some() || a.dump_proto.is_some() {
        return Ok(());
    }
    println!(
        "JPDA update, {} separated targets, 3 measurements each: {} kB of JSON, {} kB of proto; {} calls per transport",
        a.targets,
        json_body.len() / 1000,
        prost::Message::encoded_len(&proto) / 1000,
        a.repeat
    );
    let client = reqwest::Client::new();
    if a.only.as_deref() != Some("grpc") {
        rest(&a, &client, axum::body::Bytes::from(json_body)).await?;
    }
    if a.only.as_deref() != Some("rest") {
        grpc(&a, &client, proto).await?;
    }
    Ok(())
}

async fn rest(
    a: &Args,
    client: &reqwest::Client,
    json_body: axum::body::Bytes,
) -> anyhow::Result<()> {
    // Warm-up of both paths.
    for _ in 0..5 {
        client
            .post(format!("{}/v1/jpda/update", a.url))
            .header("content-type", "application/json")
            .body(json_body.clone())
            .send()
            .await?
            .bytes()
            .await?;
    }
    let route = ["route=\"/v1/jpda/update\""];
    let before = histogram(client, &a.url, "http_request_duration_seconds", &route).await;
    let (mut compute, mut wall) = (Vec::new(), Vec::new());
    for _ in 0..a.repeat {
        let start = Instant::now();
        let bytes = client
            .post(format!("{}/v1/jpda/update", a.url))
            .header("content-type", "application/json")
            .body(json_body.clone())
            .send()
            .await?
            .bytes()
            .await?;
        wall.push(start.elapsed().as_secs_f64() * 1e3);
        let v: Value = serde_json::from_slice(&bytes)?;
        compute.push(v["timing"]["compute_us"].as_f64().expect("compute_us") / 1e3);
    }
    let after = histogram(client, &a.url, "http_request_duration_seconds", &route).await;
    let server = (after.0 - before.0) / (after.1 - before.1) * 1e3;
    report("REST", compute, wall, server);
    Ok(())
}

async fn grpc(
    a: &Args,
    client: &reqwest::Client,
    proto: pb::JpdaUpdateRequest,
) -> anyhow::Result<()> {
    let channel = tonic::transport::Channel::from_shared(a.grpc.clone())?
        .connect_timeout(Duration::from_secs(5))
        .connect()
        .await?;
    let mut grpc = pb::jpda_service_client::JpdaServiceClient::new(channel)
        .max_decoding_message_size(usize::MAX);
    for _ in 0..5 {
        grpc.update(proto.clone()).await?;
    }
    let method = ["method=\"/radar.fusion.v1.JpdaService/Update\""];
    let before = histogram(client, &a.url, "grpc_request_duration_seconds", &method).await;
    let (mut compute, mut wall) = (Vec::new(), Vec::new());
    for _ in 0..a.repeat {
        let request = proto.clone();
        let start = Instant::now();
        let response = grpc.update(request).await?.into_inner();
        wall.push(start.elapsed().as_secs_f64() * 1e3);
        compute.push(response.timing.map_or(f64::NAN, |t| t.compute_us) / 1e3);
    }
    let after = histogram(client, &a.url, "grpc_request_duration_seconds", &method).await;
    let server = (after.0 - before.0) / (after.1 - before.1) * 1e3;
    report("gRPC", compute, wall, server);
    Ok(())
}
