//! The stateless endpoints of seeds 000, 003 and 004 through a running
//! server (issue 54): per endpoint and scene, the first call and the median
//! of the later calls, each as the client's wall time on loopback (body
//! prepared beforehand, answer read as bytes) and the service's own
//! `timing.compute_us`, with the request's and the answer's size.
//!
//! ```sh
//! cargo run --release --bin radar-fusion &    # or any running server
//! cargo run --release --example stateless_endpoints -- [--url http://127.0.0.1:8080]
//!     [--repeat 11] [--only correlation|dimension|ais] [--big] [--dump DIR]
//!     [--history]
//! ```
//!
//! Scenes (all synthetic, from `eval`, fixed seeds):
//! - correlation: `benchmark::realistic_scene(120, 12)` (two nodes × 120
//!   Kalman tracks × 12 instants, recomputed gains) under the weighted, the
//!   independent double-threshold and the modified method, and the modified
//!   method with the filters' gains reported (`realistic_scene(120, 12,
//!   true)`: K and H, no recomputed I − K H); with `--big` also
//!   `realistic_scene(10_000, 11)` under the weighted method (about 60 MB);
//! - dimension: `seed003_dimension::bench_scene(36, 300 s, seed 1)`: about
//!   2,000 plots of two 3D and two 2D radars, all three methods (`--history`
//!   asks for every sample of every system track and every pair, the whole
//!   answer of the releases before issue 54);
//! - ais: `AisSceneConfig::harbour(72, 500 m, 0.5°)`, seed 0: 72 radar tracks
//!   over 20 minutes, about 35,000 samples and 4,600 AIS reports, the radar
//!   at 50.8° N 1.3° W.
//!
//! `--dump DIR` writes each request body to `DIR/<name>.json` (for `perf`
//! runs with curl or wrk) and exits.

use std::time::Instant;

use algo::bias::projection::LocalPlane;
use algo::geo::Ellipsoid;
use eval::{
    ais::AisSceneConfig, benchmark::realistic_scene, experiments::seed003_dimension::bench_scene,
    montecarlo::run_rng,
};
use serde_json::{Value, json};
use service::correlation::CorrelateInput;

struct Args {
    url: String,
    repeat: usize,
    only: Option<String>,
    big: bool,
    history: bool,
    dump: Option<String>,
}

fn args() -> anyhow::Result<Args> {
    let mut a = Args {
        url: "http://127.0.0.1:8080".into(),
        repeat: 11,
        only: None,
        big: false,
        history: false,
        dump: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{flag} needs a value"))
        };
        match flag.as_str() {
            "--url" => a.url = value()?,
            "--repeat" => a.repeat = value()?.parse::<usize>()?.max(1),
            "--only" => a.only = Some(value()?),
            "--dump" => a.dump = Some(value()?),
            "--big" => a.big = true,
            "--history" => a.history = true,
            other => anyhow::bail!("unknown flag {other}"),
        }
    }
    Ok(a)
}

/// The JSON body of a correlation request under method `kind`.
fn correlation_body(input: &CorrelateInput, kind: &str) -> Value {
    let model = input.motion_model.as_ref().map(|m| {
        json!({"kind": m.kind, "process_noise": m.process_noise, "sigma_a_mps2": m.sigma_a_mps2})
    });
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
                        "covariance": s.covariance.rows().collect::<Vec<_>>(),
                        "gain": s.gain.as_ref().map(|g| g.rows().collect::<Vec<_>>()),
                    })).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let mut body = json!({
        "state_layout": input.state_layout,
        "method": {"kind": kind},
        "motion_model": model,
        "nodes": nodes,
    });
    if let Some(h) = &input.measurement_matrix {
        body["measurement_matrix"] = json!(h);
    }
    body
}

/// The dimension-fusion body of the issue-15 bench scene.
fn dimension_body(history: bool) -> anyhow::Result<Value> {
    let mut rng = run_rng(1, 0);
    let scene = bench_scene(36, 300.0, &mut rng)?;
    let radars: Vec<Value> = scene
        .radars
        .iter()
        .enumerate()
        .map(|(r, radar)| {
            let (lat, lon, h) = radar.frame.origin_geodetic();
            let tracks: Vec<Value> = scene
                .tracks
                .iter()
                .enumerate()
                .filter(|(_, t)| t.radar == r)
                .map(|(i, t)| {
                    json!({
                        "id": format!("t{i}"),
                        "plots": t.plots.iter().map(|p| {
                            let mut v = json!({"t": p.t, "range_m": p.range,
                                "azimuth_deg": p.azimuth.to_degrees().rem_euclid(360.0)});
                            if let Some(e) = p.elevation {
                                v["elevation_deg"] = json!(e.to_degrees());
                            }
                            v
                        }).collect::<Vec<_>>(),
                    })
                })
                .collect();
            let mut v = json!({
                "id": format!("r{r}"),
                "kind": if radar.three_d { "3d" } else { "2d" },
                "site": {"lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees(), "height_m": h},
                "sigma_range_m": radar.sigma_range,
                "sigma_azimuth_deg": radar.sigma_azimuth.to_degrees(),
                "scan_period_s": radar.scan_period,
                "tracks": tracks,
            });
            if radar.three_d {
                v["sigma_elevation_deg"] = json!(radar.sigma_elevation.to_degrees());
            }
            v
        })
        .collect();
    let (lat, lon, h) = scene.centre.origin_geodetic();
    let mut body = json!({
        "origin": {"lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees(), "height_m": h},
        "radars": radars,
    });
    if history {
        body["history"] = json!(true);
        body["all_pairs"] = json!(true);
    }
    Ok(body)
}

/// The AIS–radar body of the harbour scene.
fn ais_body() -> anyhow::Result<Value> {
    let (lat0, lon0) = (50.8f64, -1.3f64);
    let plane = LocalPlane::new(Ellipsoid::WGS84, lat0.to_radians(), lon0.to_radians())?;
    let mut rng = run_rng(17, 500);
    let scene = AisSceneConfig::harbour(72, 500.0, 0.5f64.to_radians()).generate(&mut rng)?;
    let tracks: Vec<Value> = scene
        .radar
        .iter()
        .enumerate()
        .map(|(i, samples)| {
            json!({
                "id": format!("r{i}"),
                "samples": samples.iter().map(|s| json!({
                    "t": s.t, "range_m": s.range, "azimuth_deg": s.azimuth.to_degrees(),
                })).collect::<Vec<_>>(),
            })
        })
        .collect();
    let mut reports = Vec::new();
    for (k, ship) in scene.ais.iter().enumerate() {
        for p in ship {
            let (lat, lon) = plane.inverse(p.position);
            reports.push(json!({"mmsi": 235_000_000 + k as u32, "t": p.t,
                "lat_deg": lat.to_degrees(), "lon_deg": lon.to_degrees()}));
        }
    }
    Ok(json!({
        "site": {"lat_deg": lat0, "lon_deg": lon0},
        "radar_tracks": tracks,
        "ais_reports": reports,
    }))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Posts `body` `repeat + 1` times and prints the first call and the median
/// of the others.
async fn run(
    client: &reqwest::Client,
    url: &str,
    name: &str,
    body: Vec<u8>,
    repeat: usize,
) -> anyhow::Result<()> {
    let body = axum::body::Bytes::from(body);
    let (mut wall, mut compute) = (Vec::new(), Vec::new());
    let mut answer_len = 0;
    for _ in 0..=repeat {
        let start = Instant::now();
        let resp = client
            .post(url)
            .header("content-type", "application/json")
            .body(body.clone())
            .send()
            .await?;
        let status = resp.status();
        let bytes = resp.bytes().await?;
        wall.push(start.elapsed().as_secs_f64() * 1e3);
        if !status.is_success() {
            anyhow::bail!("{name}: {status}: {}", String::from_utf8_lossy(&bytes));
        }
        let v: Value = serde_json::from_slice(&bytes)?;
        compute.push(v["timing"]["compute_us"].as_f64().unwrap_or(f64::NAN) / 1e3);
        answer_len = bytes.len();
    }
    println!(
        "| {name} | {:.2} / {:.2} | {:.2} / {:.2} | {:.2} ({:.2}) | {:.1} | {:.1} |",
        wall[0],
        compute[0],
        median(wall[1..].to_vec()),
        median(compute[1..].to_vec()),
        wall[1..].iter().copied().fold(f64::INFINITY, f64::min),
        compute[1..].iter().copied().fold(f64::INFINITY, f64::min),
        body.len() as f64 / 1e3,
        answer_len as f64 / 1e3,
    );
    Ok(())
}

#[tokio::main(flavor = "current_thread")]
async fn main() -> anyhow::Result<()> {
    let a = args()?;
    let wanted = |k: &str| a.only.as_deref().is_none_or(|o| o == k);
    let mut bodies: Vec<(String, &str, Vec<u8>)> = Vec::new();
    if wanted("correlation") {
        let s = realistic_scene(120, 12, false);
        for kind in ["weighted", "independent_double_threshold", "modified"] {
            bodies.push((
                format!("correlation-120-{kind}"),
                "/v1/correlation/tracks",
                serde_json::to_vec(&correlation_body(&s.request, kind))?,
            ));
        }
        // The modified test with the filters' gains reported (K and H).
        let g = realistic_scene(120, 12, true);
        bodies.push((
            "correlation-120-modified-gains".into(),
            "/v1/correlation/tracks",
            serde_json::to_vec(&correlation_body(&g.request, "modified"))?,
        ));
        if a.big {
            let s = realistic_scene(10_000, 11, false);
            bodies.push((
                "correlation-10000-weighted".into(),
                "/v1/correlation/tracks",
                serde_json::to_vec(&correlation_body(&s.request, "weighted"))?,
            ));
        }
    }
    if wanted("dimension") {
        bodies.push((
            "dimension-bench36".into(),
            "/v1/dimension/fuse",
            serde_json::to_vec(&dimension_body(a.history)?)?,
        ));
    }
    if wanted("ais") {
        bodies.push((
            "ais-harbour72".into(),
            "/v1/ais-radar/associate",
            serde_json::to_vec(&ais_body()?)?,
        ));
    }
    if let Some(dir) = &a.dump {
        std::fs::create_dir_all(dir)?;
        for (name, _, body) in &bodies {
            std::fs::write(format!("{dir}/{name}.json"), body)?;
        }
        return Ok(());
    }
    println!(
        "| request | first call: client / compute ms | later calls (median of {}): client / compute ms | min client (compute) ms | request kB | answer kB |",
        a.repeat
    );
    println!("|---|---|---|---|---|---|");
    let client = reqwest::Client::new();
    for (name, path, body) in bodies {
        run(&client, &format!("{}{path}", a.url), &name, body, a.repeat).await?;
    }
    Ok(())
}
