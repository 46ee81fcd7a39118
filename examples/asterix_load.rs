//! The ASTERIX UDP listener at real rate: CAT048 from the radars of the
//! plot-fusion benchmark scene (`eval::benchmark::plot_fusion_scene`,
//! beam-timed plots, I048/140 in 1/128 s) sent over loopback to the
//! listener of an in-process server, paced in wall-clock time; measures
//! the latency from a datagram to the track update that uses it, and
//! whether any datagram was lost.
//!
//! ```text
//! cargo run --release --example asterix_load -- \
//!     [--targets 4000] [--radars 4] [--duration 60] [--clutter 20] \
//!     [--speed 1.0] [--max-datagram 1400] [--hold-ms 50] \
//!     [--recv-buffer-bytes 4194304] [--store memory|redis://…]
//! ```
//!
//! The feed. Each radar (SAC 25, SIC 1, 2, …) sends its plots as CAT048
//! (`eval::asterix048`: I048/010, /140, /020 single PSR, /040), a datagram
//! of one data block of its own plots of consecutive stamps: a datagram
//! goes when `--hold-ms` of scene time has passed since its oldest plot
//! (`--hold-ms 0`: one per 1/128-s stamp), or at once when the next plot
//! would not fit `--max-datagram` bytes. Datagrams leave at their scene
//! time divided by `--speed` after the start (1.0: real rate) from a
//! thread of their own. Times of day are real: scene time t is sent as the
//! time of day of T0 + t, T0 the Unix time of the start, so the listener's
//! clock (the time of reception for the first batch, then the session's
//! newest plot) maps I048/140 back to T0 + t.
//!
//! The figures.
//! - datagrams and plots sent; datagrams received
//!   (`fusion_asterix_datagrams_total`), records, decode errors, late
//!   plots, push failures and the number of applied batches, from the
//!   process's `/metrics` text;
//! - latency, two ways: the service's own histogram
//!   `fusion_asterix_latency_seconds` (a batch's earliest datagram's
//!   receipt by the listener → its applied update; quantiles interpolated
//!   within its buckets as Prometheus's `histogram_quantile` does, the
//!   maximum as the bucket that holds it), and this program's (each
//!   datagram's send → the first poll of `/metrics`, every 5 ms, whose
//!   `fusion_asterix_records_total` counts its records: datagrams arrive
//!   and are applied in order, so the counter passes a datagram's last
//!   record when its batch is applied);
//! - whether sending kept to schedule (each send's delay past its due
//!   time);
//! - confirmed tracks of the session at the end against the aircraft, and
//!   their horizontal error to the nearest aircraft (median, p95);
//! - CPU seconds of the process while the feed ran, by thread (the
//!   compute lanes run the tracker; the async workers receive, decode
//!   nothing, and write the store).
//!
//! The allocator is the server binary's (mimalloc, `src/main.rs`).

use std::{
    collections::BTreeMap,
    net::{SocketAddr, UdpSocket},
    sync::{
        Arc,
        atomic::{AtomicBool, Ordering},
    },
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::{Context, ensure};
use eval::{
    asterix048::{self, Report},
    benchmark::{PlotFusionScene, PlotTiming, plot_fusion_scene},
};
use radar_fusion::{app::Application, config::Settings, state::AppState};
use serde_json::{Value, json};
use service::session::plot_fusion::PlotFusionSession;
use tokio::sync::oneshot;

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The session the listener feeds (its default id and tenant).
const SESSION: &str = "00000000000000000000000000000048";
const TENANT: &str = "default";
/// The radars' SAC; radar r is SIC r + 1.
const SAC: u8 = 25;
/// How often the progress counter is read.
const POLL: Duration = Duration::from_millis(5);
/// Seconds from the start to the first due send (the server is ready,
/// the datagrams encoded).
const LEAD_S: f64 = 1.0;
/// Seconds of scene time per line of the latency-by-time report.
const WINDOW_S: f64 = 5.0;
/// Gives up waiting for the last records after this long without progress.
const STALL: Duration = Duration::from_secs(30);

struct Args {
    targets: usize,
    radars: usize,
    duration: f64,
    clutter: usize,
    speed: f64,
    max_datagram: usize,
    hold_ms: f64,
    recv_buffer_bytes: usize,
    store: String,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut args = Args {
        targets: 4000,
        radars: 4,
        duration: 60.0,
        clutter: 20,
        speed: 1.0,
        max_datagram: asterix048::DEFAULT_MAX_BLOCK_BYTES,
        hold_ms: 50.0,
        recv_buffer_bytes: 4 << 20,
        store: "memory".into(),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().with_context(|| format!("{flag} needs a value"))?;
        match flag.as_str() {
            "--targets" => args.targets = value.parse()?,
            "--radars" => args.radars = value.parse()?,
            "--duration" => args.duration = value.parse()?,
            "--clutter" => args.clutter = value.parse()?,
            "--speed" => args.speed = value.parse()?,
            "--max-datagram" => args.max_datagram = value.parse()?,
            "--hold-ms" => args.hold_ms = value.parse()?,
            "--recv-buffer-bytes" => args.recv_buffer_bytes = value.parse()?,
            "--store" => args.store = value,
            other => anyhow::bail!("unknown flag {other}"),
        }
    }
    ensure!(
        args.speed > 0.0 && args.speed.is_finite(),
        "--speed must be positive"
    );
    ensure!(args.hold_ms >= 0.0, "--hold-ms must be at least 0");
    ensure!(
        asterix048::records_per_block(args.max_datagram) > 0,
        "--max-datagram must hold a record (14 bytes or more)"
    );
    Ok(args)
}

/// The `--asterix-session-spec` JSON: the scene's network, each radar with
/// its SAC/SIC.
fn session_spec(scene: &PlotFusionScene) -> Value {
    let spec = &scene.spec;
    let radars: Vec<Value> = spec
        .radars
        .iter()
        .enumerate()
        .map(|(r, radar)| {
            json!({
                "id": radar.id,
                "kind": radar.kind,
                "site": {"position_m": radar.site.as_ref().and_then(|s| s.position_m.clone())},
                "sigma_range_m": radar.sigma_range_m,
                "sigma_azimuth_deg": radar.sigma_azimuth_deg,
                "scan_period_s": radar.scan_period_s,
                "p_detection": radar.p_detection,
                "clutter_density": radar.clutter_density,
                "sac": SAC,
                "sic": r + 1,
            })
        })
        .collect();
    let origin = spec
        .origin
        .as_ref()
        .map(|o| json!({"lat_deg": o.lat_deg, "lon_deg": o.lon_deg, "height_m": o.height_m}));
    json!({"kind": "plot_fusion", "origin": origin, "radars": radars})
}

/// One datagram: a data block of one radar's plots.
struct Datagram {
    /// Scene time at which the radar sends it.
    send_t: f64,
    bytes: Vec<u8>,
    records: usize,
}

/// Every radar's plots as datagrams (see the module header), in order of
/// sending; and the plots that I048/040 cannot hold (beyond 256 NM).
fn datagrams(
    scene: &PlotFusionScene,
    args: &Args,
    t0: f64,
) -> anyhow::Result<(Vec<Datagram>, usize)> {
    let cap = asterix048::records_per_block(args.max_datagram);
    let hold = args.hold_ms / 1000.0;
    let mut out = Vec::new();
    let mut unencodable = 0;
    for r in 0..args.radars {
        let id = format!("r{r}");
        let sic = u8::try_from(r + 1).context("at most 255 radars")?;
        let mut group: Vec<Report> = Vec::new();
        let mut first_t = 0.0;
        let mut emit = |group: &mut Vec<Report>, send_t: f64| -> anyhow::Result<()> {
            if group.is_empty() {
                return Ok(());
            }
            out.push(Datagram {
                send_t,
                bytes: asterix048::block(group)?,
                records: group.len(),
            });
            group.clear();
            Ok(())
        };
        for p in scene
            .plots
            .iter()
            .filter(|p| p.radar_id.as_deref() == Some(&id))
        {
            let (Some(t), Some(range_m), Some(azimuth_deg)) = (p.t, p.range_m, p.azimuth_deg)
            else {
                continue;
            };
            if !group.is_empty() && t > first_t + hold {
                emit(&mut group, first_t + hold)?;
            }
            let report = Report {
                sac: SAC,
                sic,
                time_of_day_s: asterix048::time_of_day(t0 + t),
                range_m,
                azimuth_deg,
            };
            if asterix048::record(&report).is_err() {
                unencodable += 1;
                continue;
            }
            if group.is_empty() {
                first_t = t;
            }
            group.push(report);
            if group.len() == cap {
                emit(&mut group, t)?;
            }
        }
        emit(&mut group, first_t + hold)?;
    }
    out.sort_by(|a, b| a.send_t.total_cmp(&b.send_t));
    Ok((out, unencodable))
}

/// What the sender did: per datagram its send instant, and how late each
/// send was past its due time.
struct Sent {
    at: Vec<Instant>,
    slip: Vec<Duration>,
    failures: usize,
}

/// Sends every datagram at `start` + its scene time / `speed`.
fn send(
    datagrams: Arc<Vec<Datagram>>,
    to: SocketAddr,
    start: Instant,
    speed: f64,
) -> anyhow::Result<Sent> {
    let socket = UdpSocket::bind("127.0.0.1:0")?;
    let mut sent = Sent {
        at: Vec::with_capacity(datagrams.len()),
        slip: Vec::with_capacity(datagrams.len()),
        failures: 0,
    };
    for d in datagrams.iter() {
        let due = start + Duration::from_secs_f64(d.send_t.max(0.0) / speed);
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
        if socket.send_to(&d.bytes, to).is_err() {
            sent.failures += 1;
        }
        let at = Instant::now();
        sent.slip.push(at.saturating_duration_since(due));
        sent.at.push(at);
    }
    Ok(sent)
}

/// `(instant, fusion_asterix_records_total)` every [`POLL`] until `stop`,
/// kept when the value changes.
fn poll(state: AppState, stop: Arc<AtomicBool>) -> Vec<(Instant, u64)> {
    let mut out: Vec<(Instant, u64)> = Vec::new();
    while !stop.load(Ordering::Relaxed) {
        let text = state.metrics().render();
        let at = Instant::now();
        let records = metric(&text, "fusion_asterix_records_total") as u64;
        if out.last().is_none_or(|&(_, r)| r != records) {
            out.push((at, records));
        }
        std::thread::sleep(POLL);
    }
    out
}

/// The value of an unlabelled series (or a label set given in `name`) in a
/// Prometheus text; 0 when absent.
fn metric(text: &str, name: &str) -> f64 {
    text.lines()
        .find_map(|l| {
            l.strip_prefix(name)
                .and_then(|rest| rest.strip_prefix(' '))
                .and_then(|v| v.trim().parse().ok())
        })
        .unwrap_or(0.0)
}

/// A histogram's buckets `(le, cumulative count)`, +Inf last.
fn buckets(text: &str, name: &str) -> Vec<(f64, f64)> {
    let prefix = format!("{name}_bucket{{le=\"");
    text.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix(&prefix)?;
            let (le, count) = rest.split_once("\"} ")?;
            let le = if le == "+Inf" {
                f64::INFINITY
            } else {
                le.parse().ok()?
            };
            Some((le, count.trim().parse().ok()?))
        })
        .collect()
}

/// The q-quantile of a histogram, linear within its bucket (Prometheus's
/// `histogram_quantile`); the last finite bound when it falls in +Inf.
fn bucket_quantile(b: &[(f64, f64)], q: f64) -> f64 {
    let Some(&(_, total)) = b.last() else {
        return f64::NAN;
    };
    let rank = q * total;
    let mut lower = (0.0, 0.0);
    for &(le, count) in b {
        if count >= rank && count > 0.0 {
            if le.is_infinite() {
                return lower.0;
            }
            return lower.0 + (le - lower.0) * (rank - lower.1) / (count - lower.1).max(1.0);
        }
        lower = (le, count);
    }
    lower.0
}

/// The smallest bucket bound holding every observation.
fn bucket_max(b: &[(f64, f64)]) -> f64 {
    let total = b.last().map_or(0.0, |&(_, c)| c);
    b.iter()
        .find(|&&(_, c)| c >= total)
        .map_or(f64::NAN, |&(le, _)| le)
}

/// The p-quantile of sorted values (nearest rank).
fn quantile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() as f64 * p).ceil() as usize).clamp(1, sorted.len()) - 1;
    sorted[i]
}

/// CPU seconds (user + system) of the process and of each of its live
/// threads by name, from /proc (USER_HZ = 100 ticks a second).
fn cpu_seconds() -> (f64, BTreeMap<String, f64>) {
    let ticks = |stat: &str| -> Option<(String, f64)> {
        let open = stat.find('(')?;
        let close = stat.rfind(')')?;
        let name = stat[open + 1..close].to_string();
        let fields: Vec<&str> = stat[close + 1..].split_whitespace().collect();
        let utime: f64 = fields.get(11)?.parse().ok()?;
        let stime: f64 = fields.get(12)?.parse().ok()?;
        Some((name, (utime + stime) / 100.0))
    };
    let total = std::fs::read_to_string("/proc/self/stat")
        .ok()
        .and_then(|s| ticks(&s))
        .map_or(f64::NAN, |(_, t)| t);
    let mut threads = BTreeMap::new();
    if let Ok(dir) = std::fs::read_dir("/proc/self/task") {
        for entry in dir.flatten() {
            let stat = std::fs::read_to_string(entry.path().join("stat")).unwrap_or_default();
            if let Some((name, t)) = ticks(&stat) {
                // compute-0, compute-1 → compute-*.
                let group = match name.split_once('-') {
                    Some(("compute", _)) => "compute-*".to_string(),
                    _ => name,
                };
                *threads.entry(group).or_insert(0.0) += t;
            }
        }
    }
    (total, threads)
}

fn unix_now() -> f64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let scene = plot_fusion_scene(
        args.targets,
        args.radars,
        args.duration,
        args.clutter,
        false,
        PlotTiming::Beam,
    );
    println!(
        "scene: {} targets, {} radars, {} s, {} clutter plots per scan, beam-timed (1/128 s): \
         {} plots",
        args.targets,
        args.radars,
        args.duration,
        args.clutter,
        scene.plots.len()
    );

    // The server, its listener on a free loopback port.
    let port = UdpSocket::bind("127.0.0.1:0")?.local_addr()?.port();
    let to: SocketAddr = format!("127.0.0.1:{port}").parse()?;
    let dir = std::env::temp_dir().join(format!("asterix-load-{}-{port}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let spec_path = dir.join("session.json");
    std::fs::write(&spec_path, session_spec(&scene).to_string())?;
    let mut settings = Settings::for_tests();
    settings.session_store = args.store.clone();
    settings.asterix_udp = Some(to);
    settings.asterix_session_spec = Some(spec_path);
    settings.asterix_recv_buffer_bytes = args.recv_buffer_bytes;
    settings.max_batch_reports = scene.plots.len().max(100_000);
    settings.max_tracks_per_session = 1_000_000;
    settings.session_memory_bytes = 16 << 30;
    settings.session_memory_bytes_per_tenant = 16 << 30;
    settings.request_timeout_s = 600.0;
    let app = Application::build(settings).await?;
    let state = app.state();
    let (stop_server, stopped) = oneshot::channel::<()>();
    let server = tokio::spawn(app.run_until(async move {
        let _ = stopped.await;
    }));
    for _ in 0..400 {
        if state.is_ready() {
            break;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    ensure!(state.is_ready(), "the server did not become ready");
    std::fs::remove_dir_all(&dir).ok();

    // T0 on a 1/128-s stamp, so that every sent time of day is exact.
    let now = unix_now();
    let t0 = ((now + LEAD_S) * 128.0).ceil() / 128.0;
    let (datagrams, unencodable) = datagrams(&scene, &args, t0)?;
    let datagrams = Arc::new(datagrams);
    let start = Instant::now() + Duration::from_secs_f64((t0 - unix_now()).max(0.0));
    let records_sent: usize = datagrams.iter().map(|d| d.records).sum();
    let bytes_sent: usize = datagrams.iter().map(|d| d.bytes.len()).sum();
    let largest = datagrams.iter().map(|d| d.bytes.len()).max().unwrap_or(0);
    let before = state.metrics().render();
    let cpu_before = cpu_seconds();

    let stop = Arc::new(AtomicBool::new(false));
    let poller = {
        let (state, stop) = (state.clone(), Arc::clone(&stop));
        std::thread::Builder::new()
            .name("poller".into())
            .spawn(move || poll(state, stop))?
    };
    let sender = {
        let datagrams = Arc::clone(&datagrams);
        let speed = args.speed;
        std::thread::Builder::new()
            .name("sender".into())
            .spawn(move || send(datagrams, to, start, speed))?
    };
    let sent = tokio::task::spawn_blocking(move || sender.join())
        .await?
        .map_err(|_| anyhow::anyhow!("the sender panicked"))??;
    let send_s = sent
        .at
        .last()
        .map_or(0.0, |last| last.duration_since(start).as_secs_f64());

    // Wait for the last records (bounded: until no progress for STALL).
    let counted = |text: &str, name: &str| metric(text, name) - metric(&before, name);
    let mut last_progress = (Instant::now(), -1.0);
    loop {
        let text = state.metrics().render();
        let records = counted(&text, "fusion_asterix_records_total");
        if records >= records_sent as f64 {
            break;
        }
        if records > last_progress.1 {
            last_progress = (Instant::now(), records);
        } else if last_progress.0.elapsed() > STALL {
            println!(
                "stopped waiting: {records} of {records_sent} records applied, none for {} s",
                STALL.as_secs()
            );
            break;
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let drained = Instant::now();
    stop.store(true, Ordering::Relaxed);
    let progress = tokio::task::spawn_blocking(move || poller.join())
        .await?
        .map_err(|_| anyhow::anyhow!("the poller panicked"))?;
    let cpu_after = cpu_seconds();
    let text = state.metrics().render();

    // The service's figures.
    let received = counted(&text, "fusion_asterix_datagrams_total");
    let records = counted(&text, "fusion_asterix_records_total");
    let plots = counted(&text, "fusion_asterix_plots_total");
    let decode_errors = counted(&text, "fusion_asterix_decode_errors_total");
    let late = counted(&text, "fusion_asterix_late_plots_total");
    let push_failures = counted(&text, "fusion_asterix_push_failures_total");
    let b = buckets(&text, "fusion_asterix_latency_seconds");
    let batches = b.last().map_or(0.0, |&(_, c)| c);
    let latency_sum = metric(&text, "fusion_asterix_latency_seconds_sum");

    // This program's: each datagram's send → the first poll counting its
    // last record.
    let mut own: Vec<f64> = Vec::with_capacity(datagrams.len());
    let mut cumulative = 0u64;
    let mut k = 0;
    let base = metric(&before, "fusion_asterix_records_total") as u64;
    for (d, at) in datagrams.iter().zip(&sent.at) {
        cumulative += d.records as u64;
        while k < progress.len() && progress[k].1 < base + cumulative {
            k += 1;
        }
        match progress.get(k) {
            Some(&(seen, _)) => own.push(seen.saturating_duration_since(*at).as_secs_f64()),
            None => break,
        }
    }
    // The worst latency of the datagrams sent in each WINDOW_S of scene
    // time: where in the feed the delays come.
    let mut windows: BTreeMap<u64, f64> = BTreeMap::new();
    for (d, l) in datagrams.iter().zip(&own) {
        let w = windows
            .entry((d.send_t / WINDOW_S).floor().max(0.0) as u64)
            .or_insert(0.0);
        *w = w.max(*l);
    }
    own.sort_by(f64::total_cmp);
    let mut slip: Vec<f64> = sent.slip.iter().map(Duration::as_secs_f64).collect();
    slip.sort_by(f64::total_cmp);

    // The session at the end, scored against the truth at T0 + t.
    let view = state
        .sessions()
        .get_as::<PlotFusionSession>(TENANT, SESSION)
        .await
        .map_err(|e| anyhow::anyhow!("the session: {e}"))?;
    let mut errors: Vec<f64> = view
        .body
        .tracks
        .iter()
        .filter(|t| t.status == "confirmed")
        .map(|t| scene.nearest_error(t.t - t0, t.state[0], t.state[2]))
        .collect();
    errors.sort_by(f64::total_cmp);
    let confirmed = errors.len();

    let cpu_total = cpu_after.0 - cpu_before.0;
    let wall = drained.duration_since(start).as_secs_f64();
    let threads: Vec<String> = cpu_after
        .1
        .iter()
        .map(|(name, t)| {
            format!(
                "{name} {:.1}",
                t - cpu_before.1.get(name).copied().unwrap_or(0.0)
            )
        })
        .collect();
    let ms = |s: f64| s * 1e3;
    println!(
        "sent: {} datagrams ({} bytes, largest {largest}), {records_sent} plots ({:.0} plots/s \
         over {send_s:.1} s at speed {}, hold {} ms, {unencodable} beyond I048/040); send delay \
         past due p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms, {} over 10 ms, {} send failures",
        datagrams.len(),
        bytes_sent,
        records_sent as f64 / send_s.max(1e-9),
        args.speed,
        args.hold_ms,
        ms(quantile(&slip, 0.5)),
        ms(quantile(&slip, 0.99)),
        ms(slip.last().copied().unwrap_or(f64::NAN)),
        slip.iter().filter(|&&s| s > 0.010).count(),
        sent.failures,
    );
    println!(
        "service: {received} datagrams received ({} not), {records} records, {plots} plots, \
         {decode_errors} decode errors, {late} late plots, {push_failures} push failures; \
         {batches} batches ({:.0} plots each)",
        datagrams.len() as f64 - received,
        records / batches.max(1.0)
    );
    println!(
        "latency, service histogram (earliest datagram's receipt → applied update, per batch): \
         p50 {:.0} ms, p99 {:.0} ms, max ≤ {:.0} ms, mean {:.0} ms",
        ms(bucket_quantile(&b, 0.5)),
        ms(bucket_quantile(&b, 0.99)),
        ms(bucket_max(&b)),
        ms(latency_sum / batches.max(1.0)),
    );
    println!(
        "latency, this program (datagram sent → its records counted applied, per datagram, \
         poll {} ms): p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms ({} of {} datagrams seen applied)",
        POLL.as_millis(),
        ms(quantile(&own, 0.5)),
        ms(quantile(&own, 0.99)),
        ms(own.last().copied().unwrap_or(f64::NAN)),
        own.len(),
        datagrams.len()
    );
    let by_window: Vec<String> = windows
        .iter()
        .map(|(w, l)| format!("{}: {:.0}", *w as f64 * WINDOW_S, ms(*l)))
        .collect();
    println!(
        "worst latency (ms) of the datagrams sent in each {WINDOW_S} s from scene time: {}",
        by_window.join(", ")
    );
    println!(
        "session: {confirmed} confirmed tracks for {} aircraft ({} tracks in all), horizontal \
         error to the nearest aircraft median {:.1} m, p95 {:.1} m; counters {:?}; stored \
         session {} bytes",
        args.targets,
        view.body.tracks.len(),
        quantile(&errors, 0.5),
        quantile(&errors, 0.95),
        view.body.counters,
        view.encoded_bytes,
    );
    println!(
        "cpu: {cpu_total:.1} s over {wall:.1} s of wall ({:.0} % of {} cores); by live thread: {}",
        100.0 * cpu_total
            / wall
            / std::thread::available_parallelism().map_or(1, |n| n.get()) as f64,
        std::thread::available_parallelism().map_or(1, |n| n.get()),
        threads.join(", ")
    );
    let goal = records == records_sent as f64
        && received == datagrams.len() as f64
        && push_failures == 0.0
        && quantile(&own, 0.99) < 1.0;
    println!(
        "asterix_load: {} aircraft × {} radars at speed {}: {:.0} plots/s; datagrams {} sent, \
         {received} received; latency p50 {:.0} ms, p99 {:.0} ms, max {:.0} ms (service \
         histogram p99 {:.0} ms); {confirmed} confirmed for {} aircraft; cpu {:.0} %; goal \
         (nothing lost, p99 < 1 s) {}",
        args.targets,
        args.radars,
        args.speed,
        records_sent as f64 / send_s.max(1e-9),
        datagrams.len(),
        ms(quantile(&own, 0.5)),
        ms(quantile(&own, 0.99)),
        ms(own.last().copied().unwrap_or(f64::NAN)),
        ms(bucket_quantile(&b, 0.99)),
        args.targets,
        100.0 * cpu_total
            / wall
            / std::thread::available_parallelism().map_or(1, |n| n.get()) as f64,
        if goal { "met" } else { "NOT met" },
    );
    let _ = stop_server.send(());
    server.await??;
    Ok(())
}
