//! Throughput of the plot-fusion tracker (seed 001), compute and end to end,
//! in one run on the scene of `sim::benchmark::plot_fusion_scene`:
//!
//! ```text
//! cargo run --release --example plot_fusion_load -- \
//!     [--targets 1000] [--radars 4] [--duration 60] [--clutter 20] \
//!     [--batch-s 1] [--doppler] [--skip-compute] [--skip-end-to-end] \
//!     [--motion imm|cv] [--late-plots reprocess|retrodict] [--no-registration] [--no-accuracy] [--timing beam|scan] \
//!     [--late none|held|radars|both] [--store memory|redis://…] \
//!     [--snapshot-batches 32] [--takeover-at 0.5] [--adsb]
//! ```
//!
//! `--adsb`: every target also sends ADS-B (the service's `cooperative`
//! reports) once a second at its own phase, NACp 9 and NACv 2 with GNSS-like
//! noise (σ 5 m, 0.5 m/s), its own address; the radars' plots stay
//! primary, so radar and ADS-B meet by position alone.
//!
//! Plots are timed at the beam by default, as a real radar times them
//! (CAT048 I048/140, 1/128 s: almost every plot has its own time);
//! `--timing scan` stamps every plot of a scan with the scan's start, the
//! convenient feed that hid the cost of beam timing until issue 48. The
//! compute line also scores the answer against the truth: confirmed tracks
//! against targets, and the median and 95th percentile of the horizontal
//! distance from each confirmed track to the nearest target.
//!
//! - compute: `service::plot_fusion::track` on every plot at once, in
//!   process (validation, registration, tracking; no transport);
//! - end to end: a `plot_fusion` session over the gRPC `Stream` of an
//!   in-process server (memory store), one batch per `--batch-s` seconds of
//!   data, each batch sent when the previous one was answered; plots/s
//!   over the whole stream and the per-batch latency p50/p99. Batches are
//!   cut by arrival time: `--late none` (default) every plot arrives at its
//!   time; `held` 3 % of the plots (every 33rd) arrive 5 s late; `radars`
//!   radar k's plots arrive 2k/(R − 1) s late (0 to 2 s), so the radars'
//!   plots interleave out of order; `both` the two at once. `--store`
//!   picks the session store, `--snapshot-batches` the server's
//!   `--session-snapshot-batches` (1: a snapshot every batch, as before
//!   the session log). The line also gives the three slowest batches,
//!   the bytes written to the store per batch (snapshots, written in the
//!   background, and log entries, from the server's counters) and the
//!   session's stored bytes at the end.
//! - takeover (`--takeover-at f`, Redis only): the stream again on a new
//!   session, with a second replica on the same store; after the fraction
//!   f of the batches the serving replica is stopped and the stream
//!   attaches to the other, which reads the session (snapshot and log)
//!   from the store. Reports the time from the stop to the first batch the
//!   other replica accepted, what its read of the session took (fetch,
//!   decode of the snapshot, replay of the log), and whether the final
//!   tracks equal the uninterrupted run's.
//!
//! The allocator is the server binary's (mimalloc, `src/main.rs`), so both
//! figures are what the shipped server does.

use std::time::{Duration, Instant};

use anyhow::{Context, ensure};
use eval::benchmark::{PlotTiming, plot_fusion_scene};
use radar_fusion::{
    app::Application,
    config::Settings,
    proto::{self as pb, session_service_client::SessionServiceClient},
};
use service::plot_fusion as svc;
use tokio::sync::oneshot;
use tonic::transport::Channel;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

struct Args {
    targets: usize,
    radars: usize,
    duration: f64,
    clutter: usize,
    batch_s: f64,
    doppler: bool,
    skip_compute: bool,
    skip_end_to_end: bool,
    /// `tracker.motion`: absent = the service's default.
    motion: Option<String>,
    /// `tracker.late_plots`: absent = the service's default.
    late_plots: Option<String>,
    /// `tracker.registration.enabled = false` (its cost is the difference).
    no_registration: bool,
    /// `tracker.accuracy.enabled = false` (its cost is the difference).
    no_accuracy: bool,
    late: String,
    store: String,
    timing: PlotTiming,
    snapshot_batches: Option<usize>,
    takeover_at: Option<f64>,
    adsb: bool,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = Args {
        targets: 1000,
        radars: 4,
        duration: 60.0,
        clutter: 20,
        batch_s: 1.0,
        doppler: false,
        skip_compute: false,
        skip_end_to_end: false,
        motion: None,
        late_plots: None,
        no_registration: false,
        no_accuracy: false,
        late: "none".into(),
        snapshot_batches: None,
        takeover_at: None,
        store: "memory".into(),
        timing: PlotTiming::Beam,
        adsb: false,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        match flag.as_str() {
            "--doppler" => args.doppler = true,
            "--skip-compute" => args.skip_compute = true,
            "--skip-end-to-end" => args.skip_end_to_end = true,
            "--no-registration" => args.no_registration = true,
            "--no-accuracy" => args.no_accuracy = true,
            "--adsb" => args.adsb = true,
            _ => {
                let value = it.next().context("a flag needs a value")?;
                match flag.as_str() {
                    "--targets" => args.targets = value.parse()?,
                    "--radars" => args.radars = value.parse()?,
                    "--duration" => args.duration = value.parse()?,
                    "--clutter" => args.clutter = value.parse()?,
                    "--batch-s" => args.batch_s = value.parse()?,
                    "--motion" => args.motion = Some(value),
                    "--late-plots" => args.late_plots = Some(value),
                    "--late" => args.late = value,
                    "--store" => args.store = value,
                    "--snapshot-batches" => args.snapshot_batches = Some(value.parse()?),
                    "--takeover-at" => args.takeover_at = Some(value.parse()?),
                    "--timing" => {
                        args.timing = match value.as_str() {
                            "beam" => PlotTiming::Beam,
                            "scan" => PlotTiming::ScanStart,
                            other => anyhow::bail!("--timing: beam or scan, not {other}"),
                        }
                    }
                    other => anyhow::bail!("unknown flag {other}"),
                }
            }
        }
    }
    Ok(args)
}

fn pb_config(spec: &svc::SpecInput) -> pb::PlotFusionConfig {
    pb::PlotFusionConfig {
        cat062: None,
        origin: spec.origin.as_ref().map(|o| pb::GeoPoint {
            lat_deg: o.lat_deg,
            lon_deg: o.lon_deg,
            height_m: o.height_m,
        }),
        radars: spec
            .radars
            .iter()
            .map(|r| pb::PlotRadar {
                id: r.id.clone().unwrap_or_default(),
                kind: r.kind.clone().unwrap_or_default(),
                site: r.site.as_ref().map(|s| pb::PlotRadarSite {
                    position_m: s.position_m.clone().unwrap_or_default(),
                    ..Default::default()
                }),
                sigma_range_m: r.sigma_range_m,
                sigma_azimuth_deg: r.sigma_azimuth_deg,
                sigma_elevation_deg: r.sigma_elevation_deg,
                sigma_radial_velocity_mps: r.sigma_radial_velocity_mps,
                scan_period_s: r.scan_period_s,
                p_detection: r.p_detection,
                clutter_density: r.clutter_density,
                sac: None,
                sic: None,
                bias: None,
            })
            .collect(),
        tracker: Some(pb::TrackerOptions {
            motion: spec.tracker.motion.clone(),
            late_plots: spec.tracker.late_plots.clone(),
            registration: spec
                .tracker
                .registration
                .as_ref()
                .map(|r| pb::RegistrationOptions {
                    enabled: r.enabled,
                    ..Default::default()
                }),
            accuracy: spec.tracker.accuracy.as_ref().map(|a| pb::AccuracyOptions {
                enabled: a.enabled,
                ..Default::default()
            }),
            ..Default::default()
        }),
    }
}

fn pb_plot(p: &svc::PlotInput) -> pb::RadarPlot {
    pb::RadarPlot {
        radar_id: p.radar_id.clone().unwrap_or_default(),
        t: p.t,
        range_m: p.range_m,
        azimuth_deg: p.azimuth_deg,
        elevation_deg: p.elevation_deg,
        radial_velocity_mps: p.radial_velocity_mps,
        ..Default::default()
    }
}

/// ADS-B reports of every target of `scene` once a second up to `duration`
/// (see the module header), in time order.
fn adsb_reports(scene: &eval::benchmark::PlotFusionScene, duration: f64) -> Vec<svc::PlotInput> {
    use rand::{RngExt, SeedableRng};
    use rand_distr::StandardNormal;
    let frame = algo::geo::LocalFrame::new(
        algo::geo::Ellipsoid::WGS84,
        52f64.to_radians(),
        4f64.to_radians(),
        0.0,
    )
    .expect("the scene's origin");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(51);
    let mut out = Vec::new();
    for (i, x) in scene.targets.iter().enumerate() {
        let mut t = (i as f64 * 0.137).fract();
        while t <= duration {
            let mut noise = || -> f64 { rng.sample(StandardNormal) };
            let (e, n) = (
                x[0] + x[1] * t + 5.0 * noise(),
                x[2] + x[3] * t + 5.0 * noise(),
            );
            // The scene's targets fly in the tangent plane (the radars'
            // horizontal ranges are in it): the report's height is the
            // plane's there, or its horizontal position would move by up
            // to h · range / R (≈ 80 m at 190 km).
            let (lat, lon, h) = frame.enu_to_geodetic([e, n, 0.0]).expect("a position");
            out.push(svc::PlotInput {
                t: Some(t),
                ssr: svc::SsrInput {
                    mode_s_address: Some(format!("{:06X}", 0x10_0000 + i)),
                    ..Default::default()
                },
                report: Some(svc::report::ReportInput {
                    source: Some("adsb".into()),
                    lat_deg: Some(lat.to_degrees()),
                    lon_deg: Some(lon.to_degrees()),
                    geometric_height_m: Some(h),
                    velocity_east_mps: Some(x[1] + 0.5 * noise()),
                    velocity_north_mps: Some(x[3] + 0.5 * noise()),
                    nacp: Some(9),
                    nacv: Some(2),
                    ..Default::default()
                }),
                ..Default::default()
            });
            t += 1.0;
        }
    }
    out.sort_by(|a, b| a.t.unwrap_or(0.0).total_cmp(&b.t.unwrap_or(0.0)));
    out
}

fn pb_report(p: &svc::PlotInput) -> pb::CooperativeReport {
    let r = p.report.as_ref().expect("a report");
    pb::CooperativeReport {
        source: r.source.clone().unwrap_or_default(),
        t: p.t.unwrap_or(0.0),
        lat_deg: r.lat_deg.unwrap_or(0.0),
        lon_deg: r.lon_deg.unwrap_or(0.0),
        geometric_height_m: r.geometric_height_m,
        velocity_east_mps: r.velocity_east_mps,
        velocity_north_mps: r.velocity_north_mps,
        nacp: r.nacp.map(u32::from),
        nacv: r.nacv.map(u32::from),
        mode_s_address: p.ssr.mode_s_address.clone(),
        ..Default::default()
    }
}

/// The plots with their arrival times (see the module header), sorted by
/// arrival.
fn arrivals(
    plots: &[svc::PlotInput],
    late: &str,
    radars: usize,
) -> anyhow::Result<Vec<(f64, svc::PlotInput)>> {
    let radar_index = |p: &svc::PlotInput| -> usize {
        p.radar_id
            .as_deref()
            .and_then(|id| {
                id.trim_start_matches(|c: char| !c.is_ascii_digit())
                    .parse()
                    .ok()
            })
            .unwrap_or(0)
    };
    let mut out = plots
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let t = p.t.unwrap_or(0.0);
            let held = if i % 33 == 16 { 5.0 } else { 0.0 };
            let by_radar = 2.0 * (radar_index(p) % radars) as f64 / (radars.max(2) - 1) as f64;
            let delay = match late {
                "none" => 0.0,
                "held" => held,
                "radars" => by_radar,
                "both" => held + by_radar,
                other => anyhow::bail!("--late: none, held, radars or both, not {other}"),
            };
            Ok((t + delay, p.clone()))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    out.sort_by(|a, b| a.0.total_cmp(&b.0));
    Ok(out)
}

/// Batches of `batch_s` seconds of arrival, the last one flushing.
fn batches(plots: &[(f64, svc::PlotInput)], batch_s: f64) -> Vec<pb::PushBatchRequest> {
    let mut out: Vec<pb::PushBatchRequest> = Vec::new();
    let (mut current, mut reports) = (Vec::new(), Vec::new());
    let mut edge = batch_s;
    for (t, p) in plots {
        let t = *t;
        while t >= edge {
            if !current.is_empty() || !reports.is_empty() {
                out.push(pb::PushBatchRequest {
                    sequence: Some(out.len() as u64 + 1),
                    plots: std::mem::take(&mut current),
                    cooperative: std::mem::take(&mut reports),
                    ..Default::default()
                });
            }
            edge += batch_s;
        }
        if p.report.is_some() {
            reports.push(pb_report(p));
        } else {
            current.push(pb_plot(p));
        }
    }
    out.push(pb::PushBatchRequest {
        sequence: Some(out.len() as u64 + 1),
        plots: current,
        cooperative: reports,
        flush: true,
        ..Default::default()
    });
    out
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let scene = plot_fusion_scene(
        args.targets,
        args.radars,
        args.duration,
        args.clutter,
        args.doppler,
        args.timing,
    );
    let (mut spec, mut plots) = (scene.spec.clone(), scene.plots.clone());
    if args.adsb {
        plots.extend(adsb_reports(&scene, args.duration));
        plots.sort_by(|a, b| a.t.unwrap_or(0.0).total_cmp(&b.t.unwrap_or(0.0)));
    }
    spec.tracker.motion = args.motion.clone();
    spec.tracker.late_plots = args.late_plots.clone();
    if args.no_registration {
        spec.tracker.registration = Some(Box::new(svc::RegistrationInput {
            enabled: Some(false),
            ..Default::default()
        }));
    }
    if args.no_accuracy {
        spec.tracker.accuracy = Some(svc::AccuracyInput {
            enabled: Some(false),
            ..Default::default()
        });
    }
    let n = plots.len();
    println!(
        "scene: {} targets, {} radars, {} s, {} clutter plots per scan, doppler {}, motion {}, \
         timing {}: {n} plots (ADS-B reports among them: {})",
        args.targets,
        args.radars,
        args.duration,
        args.clutter,
        args.doppler,
        args.motion.as_deref().unwrap_or("default"),
        match args.timing {
            PlotTiming::Beam => "beam (1/128 s)",
            PlotTiming::ScanStart => "scan start",
        },
        plots.iter().filter(|p| p.report.is_some()).count()
    );

    if !args.skip_compute {
        let input = svc::TrackInput {
            spec: spec.clone(),
            plots: plots.clone(),
            asterix: None,
            nmea: None,
            history: false,
        };
        let wall = Instant::now();
        let out = svc::track(input).map_err(|e| anyhow::anyhow!("{e}"))?;
        let wall = wall.elapsed().as_secs_f64();
        let mut errors: Vec<f64> = out
            .tracks
            .iter()
            .filter(|t| t.status == "confirmed")
            .map(|t| scene.nearest_error(t.t, t.state[0], t.state[2]))
            .collect();
        errors.sort_by(f64::total_cmp);
        let confirmed = errors.len();
        let pct = |p: f64| {
            errors
                .get(((confirmed as f64 * p) as usize).min(confirmed.saturating_sub(1)))
                .copied()
                .unwrap_or(f64::NAN)
        };
        println!(
            "compute (service::plot_fusion::track, mode {}): {:.0} plots/s (tracking {:.3} s, \
             with validation {:.3} s); {confirmed} confirmed tracks for {} targets, horizontal \
             error to the nearest target median {:.1} m, p95 {:.1} m; counters {:?}",
            out.mode,
            n as f64 / (out.compute_us * 1e-6),
            out.compute_us * 1e-6,
            wall,
            args.targets,
            pct(0.5),
            pct(0.95),
            out.counters
        );
    }
    if args.skip_end_to_end {
        return Ok(());
    }

    let batches = batches(&arrivals(&plots, &args.late, args.radars)?, args.batch_s);
    let run = stream(&args, &spec, &batches, n, None).await?;
    println!(
        "end to end (gRPC stream, {} batches of {} s, late {}, store {}, snapshot every {} \
         batches): {:.0} plots/s, {:.1} batches/s; per-batch latency p50 {:.2} ms, p99 {:.2} \
         ms (slowest: {}); written to the store per batch {:.3} MB ({} snapshots, {} log \
         entries); final counters {:?}; stored session {} bytes; GetSession at the end {:.1} \
         ms (a read of the store, decoded and replayed: {:.1} ms)",
        batches.len(),
        args.batch_s,
        args.late,
        args.store,
        args.snapshot_batches
            .unwrap_or(service::session::persist::DEFAULT_SNAPSHOT_BATCHES),
        n as f64 / run.seconds,
        batches.len() as f64 / run.seconds,
        run.pct(0.5),
        run.pct(0.99),
        run.worst,
        run.written_bytes / batches.len() as f64 / 1e6,
        run.snapshots,
        run.entries,
        run.counters,
        run.stored_bytes,
        run.get_ms,
        run.read_ms
    );
    if let Some(at) = args.takeover_at {
        ensure!(
            args.store != "memory",
            "--takeover-at needs a Redis --store"
        );
        let cut = ((batches.len() as f64 * at) as usize).clamp(1, batches.len() - 1);
        let again = stream(&args, &spec, &batches, n, Some(cut)).await?;
        println!(
            "takeover after batch {cut} of {}: the other replica accepted its first batch {:.0} \
             ms after the serving one stopped (its reads of the session: {}); final tracks {} \
             the uninterrupted run's ({} tracks)",
            batches.len(),
            again.takeover_ms.unwrap_or(f64::NAN),
            again.reads,
            if again.tracks == run.tracks {
                "equal"
            } else {
                "DIFFER from"
            },
            run.tracks.len()
        );
    }
    Ok(())
}

/// What one streamed run measured.
struct Run {
    seconds: f64,
    latencies: Vec<Duration>,
    /// The three slowest batches (1-based) and their latencies.
    worst: String,
    written_bytes: f64,
    snapshots: f64,
    entries: f64,
    counters: Option<pb::TrackerCounters>,
    stored_bytes: u64,
    /// The session's tracks at the end (GetSession).
    tracks: Vec<pb::FusedTrack>,
    /// What that GetSession took (ms), and a read of the session from the
    /// store (fetch, decode, replay, view: what a GET cost before it
    /// answered from the replica's decoded copy).
    get_ms: f64,
    read_ms: f64,
    /// With a takeover: from the stop of the serving replica to the first
    /// batch the other accepted.
    takeover_ms: Option<f64>,
    /// With a takeover: what the other replica's reads of the session
    /// took (fetch, decode of the snapshot, replay of the log).
    reads: String,
}

impl Run {
    fn pct(&self, p: f64) -> f64 {
        let l = &self.latencies;
        let i = ((l.len() as f64 * p).ceil() as usize).clamp(1, l.len()) - 1;
        l[i].as_secs_f64() * 1e3
    }
}

/// A replica of the service in this process, on `args.store`.
struct Replica {
    state: radar_fusion::state::AppState,
    client: SessionServiceClient<Channel>,
    stop: oneshot::Sender<()>,
    server: tokio::task::JoinHandle<anyhow::Result<()>>,
}

async fn replica(args: &Args, n: usize) -> anyhow::Result<Replica> {
    let mut settings = Settings::for_tests();
    settings.session_store = args.store.clone();
    settings.max_batch_reports = n.max(1);
    settings.max_tracks_per_session = 1_000_000;
    settings.max_body_bytes = 1 << 30;
    settings.max_buffered_body_bytes = 2 << 30;
    settings.session_memory_bytes = 16 << 30;
    settings.session_memory_bytes_per_tenant = 16 << 30;
    settings.request_timeout_s = 600.0;
    if let Some(b) = args.snapshot_batches {
        settings.session_snapshot_batches = b;
    }
    let app = Application::build(settings).await?;
    let (grpc_addr, state) = (app.grpc_addr(), app.state());
    let (stop, stopped) = oneshot::channel::<()>();
    let server = tokio::spawn(async move {
        app.run_until(async move {
            let _ = stopped.await;
        })
        .await
    });
    for _ in 0..400 {
        if state.is_ready() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    let channel = Channel::from_shared(format!("http://{grpc_addr}"))?
        .connect()
        .await?;
    let client = SessionServiceClient::new(channel)
        .max_decoding_message_size(usize::MAX)
        .max_encoding_message_size(usize::MAX);
    Ok(Replica {
        state,
        client,
        stop,
        server,
    })
}

/// A counter of the replica's metrics, summed over its labels.
fn counter(state: &radar_fusion::state::AppState, name: &str, label: Option<&str>) -> f64 {
    state
        .metrics()
        .render()
        .lines()
        .filter(|l| l.starts_with(name) && label.is_none_or(|x| l.contains(x)))
        .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
        .sum()
}

type Updates = tonic::Streaming<pb::BatchUpdate>;

/// Opens (or attaches to) a session stream on `r`.
async fn open(
    r: &mut Replica,
    first: pb::stream_request::Kind,
) -> anyhow::Result<(
    tokio::sync::mpsc::Sender<pb::StreamRequest>,
    Updates,
    String,
)> {
    let (tx, rx) = tokio::sync::mpsc::channel(4);
    tx.send(pb::StreamRequest { kind: Some(first) }).await?;
    let mut updates = r
        .client
        .stream(tokio_stream::wrappers::ReceiverStream::new(rx))
        .await?
        .into_inner();
    let opened = updates.message().await?.context("the stream opens")?;
    Ok((tx, updates, opened.session_id))
}

/// Streams every batch to a session on one replica or, with
/// `takeover = Some(k)`, the first k on one replica and the rest on
/// another after the first is stopped.
async fn stream(
    args: &Args,
    spec: &svc::SpecInput,
    batches: &[pb::PushBatchRequest],
    n: usize,
    takeover: Option<usize>,
) -> anyhow::Result<Run> {
    let mut r = replica(args, n).await?;
    let mut other = match takeover {
        Some(_) => Some(replica(args, n).await?),
        None => None,
    };
    let open_kind = pb::stream_request::Kind::Open(pb::CreateSessionRequest {
        kind: "plot_fusion".into(),
        plot_fusion: Some(pb_config(spec)),
        ..Default::default()
    });
    let (mut tx, mut updates, id) = open(&mut r, open_kind).await?;
    let mut latencies = Vec::with_capacity(batches.len());
    let started = Instant::now();
    let mut last = None;
    let mut takeover_ms = None;
    let mut reads = String::new();
    let mut reads_before = [0.0; 4];
    let mut stopped_at = None;
    let (mut written, mut snapshots, mut entries) = (0.0, 0.0, 0.0);
    for (k, batch) in batches.iter().enumerate() {
        if takeover == Some(k) {
            // Stop the serving replica (its counters first), then attach
            // to the session on the other.
            reads_before = read_sums(&r.state);
            written += counter(&r.state, "fusion_session_written_bytes_total", None);
            snapshots += counter(&r.state, "fusion_session_writes_total", Some("snapshot"));
            entries += counter(&r.state, "fusion_session_writes_total", Some("\"log\""));
            drop(tx);
            drop(updates);
            let next = other.take().context("a second replica")?;
            let old = std::mem::replace(&mut r, next);
            let _ = old.stop.send(());
            old.server.await??;
            stopped_at = Some(Instant::now());
            (tx, updates, _) = open(&mut r, pb::stream_request::Kind::Attach(id.clone())).await?;
        }
        let t = Instant::now();
        tx.send(pb::StreamRequest {
            kind: Some(pb::stream_request::Kind::Batch(batch.clone())),
        })
        .await?;
        let update = updates.message().await?.context("an update per batch")?;
        ensure!(update.error.is_none(), "batch failed: {:?}", update.error);
        latencies.push(t.elapsed());
        if let Some(s) = stopped_at.take() {
            takeover_ms = Some(s.elapsed().as_secs_f64() * 1e3);
            reads = reads_of(&r.state, reads_before);
        }
        last = update.plot_fusion;
    }
    let seconds = started.elapsed().as_secs_f64();
    drop(tx);
    let mut worst: Vec<(Duration, usize)> = latencies
        .iter()
        .enumerate()
        .map(|(k, &l)| (l, k + 1))
        .collect();
    worst.sort();
    let worst = worst
        .iter()
        .rev()
        .take(3)
        .map(|(l, k)| format!("batch {k}: {:.0} ms", l.as_secs_f64() * 1e3))
        .collect::<Vec<_>>()
        .join(", ");
    latencies.sort();
    // Snapshots written in the background after the last batch count too.
    r.state.sessions().snapshots_settled().await;
    written += counter(&r.state, "fusion_session_written_bytes_total", None);
    snapshots += counter(&r.state, "fusion_session_writes_total", Some("snapshot"));
    entries += counter(&r.state, "fusion_session_writes_total", Some("\"log\""));
    let started = Instant::now();
    let state_now = r
        .client
        .get_session(pb::GetSessionRequest {
            session_id: id.clone(),
        })
        .await?
        .into_inner();
    let get_ms = started.elapsed().as_secs_f64() * 1e3;
    let started = Instant::now();
    r.state
        .sessions()
        .get_as::<service::session::plot_fusion::PlotFusionSession>(
            radar_fusion::auth::DEFAULT_TENANT,
            &id,
        )
        .await?;
    let read_ms = started.elapsed().as_secs_f64() * 1e3;
    let tracks = state_now
        .plot_fusion
        .as_ref()
        .map(|p| p.tracks.clone())
        .unwrap_or_default();
    r.client
        .delete_session(pb::DeleteSessionRequest { session_id: id })
        .await?;
    let _ = r.stop.send(());
    r.server.await??;
    Ok(Run {
        seconds,
        latencies,
        worst,
        written_bytes: written,
        snapshots,
        entries,
        counters: last.and_then(|l| l.counters),
        stored_bytes: state_now.encoded_bytes,
        tracks,
        get_ms,
        read_ms,
        takeover_ms,
        reads,
    })
}

/// The replica's reads of stored sessions so far (the metrics may be one
/// recorder for both replicas): the seconds of each step
/// (`fusion_session_read_seconds`: fetch, decode of the snapshot, replay of
/// the log) and the log entries replayed.
fn read_sums(state: &radar_fusion::state::AppState) -> [f64; 4] {
    let text = state.metrics().render();
    let sum = |step: &str| -> f64 {
        text.lines()
            .filter(|l| l.starts_with("fusion_session_read_seconds_sum") && l.contains(step))
            .filter_map(|l| l.rsplit(' ').next()?.parse::<f64>().ok())
            .sum()
    };
    [
        sum("\"fetch\""),
        sum("\"decode\""),
        sum("\"replay\""),
        counter(state, "fusion_session_replayed_batches_total", None),
    ]
}

/// What the reads since `before` ([`read_sums`]) took.
fn reads_of(state: &radar_fusion::state::AppState, before: [f64; 4]) -> String {
    let now = read_sums(state);
    let d = |i: usize| now[i] - before[i];
    format!(
        "fetch {:.0} ms, decode {:.0} ms, replay {:.0} ms of {} entries",
        d(0) * 1e3,
        d(1) * 1e3,
        d(2) * 1e3,
        d(3)
    )
}
