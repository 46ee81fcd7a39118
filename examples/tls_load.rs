//! What TLS costs (issue 34), against two running servers, one plaintext
//! and one with `FUSION_TLS_CERT`:
//! - **new connections**: sequential connect + one `GET /healthz` on a new
//!   connection, plaintext, TLS with a full handshake (resumption off) and
//!   TLS resumed (a client session cache);
//! - **throughput**: the rules endpoint (`POST /v1/correlation/rules/evaluate`)
//!   at `--connections` HTTP/1.1 keep-alive connections, closed loop,
//!   plaintext and TLS alternated for `--rounds` rounds of `--seconds`.
//!
//! ```sh
//! openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 30 \
//!   -subj /CN=localhost -addext subjectAltName=DNS:localhost,IP:127.0.0.1 \
//!   -addext basicConstraints=critical,CA:FALSE -keyout key.pem -out cert.pem
//! FUSION_HTTP_ADDR=127.0.0.1:8080 FUSION_GRPC_ADDR=127.0.0.1:50051 target/release/radar-fusion &
//! FUSION_HTTP_ADDR=127.0.0.1:8443 FUSION_GRPC_ADDR=127.0.0.1:50443 \
//!   FUSION_TLS_CERT=cert.pem FUSION_TLS_KEY=key.pem target/release/radar-fusion &
//! cargo run --release --example tls_load -- --plain 127.0.0.1:8080 --tls 127.0.0.1:8443 \
//!   --tls-ca cert.pem [--server-name localhost] [--connections 64] [--seconds 5] [--rounds 3]
//!   [--handshakes 1000] [--plain-pid PID --tls-pid PID]
//! ```
//! With the servers' process ids, each figure also gets the server's CPU
//! time per connection or request (`/proc/PID/stat`, user + system).

use std::{
    net::SocketAddr,
    path::PathBuf,
    sync::{
        Arc,
        atomic::{AtomicBool, AtomicU64, Ordering},
    },
    time::{Duration, Instant},
};

use http_body_util::{BodyExt, Full};
use hyper::body::Bytes;
use hyper_util::rt::TokioIo;
use rustls::{ClientConfig, client::Resumption, pki_types::ServerName};
use tokio::net::TcpStream;
use tokio_rustls::TlsConnector;

struct Args {
    plain: SocketAddr,
    tls: SocketAddr,
    ca: PathBuf,
    server_name: String,
    connections: usize,
    seconds: f64,
    rounds: usize,
    handshakes: usize,
    plain_pid: Option<u32>,
    tls_pid: Option<u32>,
}

fn args() -> anyhow::Result<Args> {
    let mut a = Args {
        plain: "127.0.0.1:8080".parse()?,
        tls: "127.0.0.1:8443".parse()?,
        ca: PathBuf::from("cert.pem"),
        server_name: "localhost".into(),
        connections: 64,
        seconds: 5.0,
        rounds: 3,
        handshakes: 1000,
        plain_pid: None,
        tls_pid: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || {
            it.next()
                .ok_or_else(|| anyhow::anyhow!("{flag} needs a value"))
        };
        match flag.as_str() {
            "--plain" => a.plain = value()?.parse()?,
            "--tls" => a.tls = value()?.parse()?,
            "--tls-ca" => a.ca = value()?.into(),
            "--server-name" => a.server_name = value()?,
            "--connections" => a.connections = value()?.parse()?,
            "--seconds" => a.seconds = value()?.parse()?,
            "--rounds" => a.rounds = value()?.parse()?,
            "--handshakes" => a.handshakes = value()?.parse()?,
            "--plain-pid" => a.plain_pid = Some(value()?.parse()?),
            "--tls-pid" => a.tls_pid = Some(value()?.parse()?),
            other => anyhow::bail!("unknown flag {other}"),
        }
    }
    Ok(a)
}

/// How a connection is made: plaintext, or TLS with a client configuration.
#[derive(Clone)]
enum Dial {
    Plain(SocketAddr),
    Tls(SocketAddr, TlsConnector, ServerName<'static>),
}

type Sender = hyper::client::conn::http1::SendRequest<Full<Bytes>>;

impl Dial {
    /// A new HTTP/1.1 connection; for TLS, whether the handshake resumed.
    async fn connect(&self) -> anyhow::Result<(Sender, bool)> {
        match self {
            Self::Plain(addr) => {
                let tcp = TcpStream::connect(addr).await?;
                tcp.set_nodelay(true)?;
                Ok((handshake(tcp).await?, false))
            }
            Self::Tls(addr, connector, name) => {
                let tcp = TcpStream::connect(addr).await?;
                tcp.set_nodelay(true)?;
                let tls = connector.connect(name.clone(), tcp).await?;
                let resumed =
                    tls.get_ref().1.handshake_kind() == Some(rustls::HandshakeKind::Resumed);
                Ok((handshake(tls).await?, resumed))
            }
        }
    }
}

async fn handshake<S>(io: S) -> anyhow::Result<Sender>
where
    S: tokio::io::AsyncRead + tokio::io::AsyncWrite + Unpin + Send + 'static,
{
    let (sender, conn) = hyper::client::conn::http1::handshake(TokioIo::new(io)).await?;
    tokio::spawn(conn);
    Ok(sender)
}

/// One request; fails unless the answer is 200.
async fn send(sender: &mut Sender, req: hyper::Request<Full<Bytes>>) -> anyhow::Result<()> {
    sender.ready().await?;
    let response = sender.send_request(req).await?;
    anyhow::ensure!(response.status() == 200, "status {}", response.status());
    response.into_body().collect().await?;
    Ok(())
}

fn healthz() -> hyper::Request<Full<Bytes>> {
    hyper::Request::get("/healthz")
        .header("host", "localhost")
        .body(Full::new(Bytes::new()))
        .expect("a valid request")
}

fn evaluate(body: &Bytes) -> hyper::Request<Full<Bytes>> {
    hyper::Request::post("/v1/correlation/rules/evaluate")
        .header("host", "localhost")
        .header("content-type", "application/json")
        .body(Full::new(body.clone()))
        .expect("a valid request")
}

/// `n` sequential new connections with one `GET /healthz` each: mean ms
/// per connection and how many handshakes resumed.
async fn new_connections(dial: &Dial, n: usize) -> anyhow::Result<(f64, usize)> {
    let mut resumed = 0;
    let start = Instant::now();
    for _ in 0..n {
        let (mut sender, r) = dial.connect().await?;
        resumed += usize::from(r);
        send(&mut sender, healthz()).await?;
    }
    Ok((start.elapsed().as_secs_f64() * 1e3 / n as f64, resumed))
}

/// Requests per second of the rules endpoint at `connections` keep-alive
/// connections for `seconds`.
async fn throughput(dial: &Dial, connections: usize, seconds: f64) -> anyhow::Result<f64> {
    let body =
        Bytes::from_static(br#"{"alpha": 0.05, "rules": [{"l": 3, "r": 4}, {"l": 6, "r": 8}]}"#);
    let mut senders = Vec::with_capacity(connections);
    for _ in 0..connections {
        senders.push(dial.connect().await?.0);
    }
    let done = Arc::new(AtomicU64::new(0));
    let stop = Arc::new(AtomicBool::new(false));
    let start = Instant::now();
    let mut tasks = Vec::new();
    for mut sender in senders {
        let (done, stop, body) = (done.clone(), stop.clone(), body.clone());
        tasks.push(tokio::spawn(async move {
            while !stop.load(Ordering::Relaxed) {
                send(&mut sender, evaluate(&body)).await?;
                done.fetch_add(1, Ordering::Relaxed);
            }
            anyhow::Ok(())
        }));
    }
    tokio::time::sleep(Duration::from_secs_f64(seconds)).await;
    stop.store(true, Ordering::Relaxed);
    let elapsed = start.elapsed().as_secs_f64();
    for task in tasks {
        task.await??;
    }
    Ok(done.load(Ordering::Relaxed) as f64 / elapsed)
}

/// A process's CPU time (user + system) in seconds, from `/proc/PID/stat`.
fn cpu_seconds(pid: Option<u32>) -> Option<f64> {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", pid?)).ok()?;
    // Fields after the command name (which may hold spaces, in parentheses).
    let fields: Vec<&str> = stat.rsplit_once(')')?.1.split_whitespace().collect();
    let ticks: f64 = fields.get(11)?.parse::<f64>().ok()? + fields.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0) // USER_HZ
}

/// " (server CPU x µs each)" for `n` operations between two readings.
fn cpu_each(before: Option<f64>, after: Option<f64>, n: f64) -> String {
    match (before, after) {
        (Some(b), Some(a)) => format!(", server CPU {:.0} µs each", (a - b) * 1e6 / n),
        _ => String::new(),
    }
}

#[tokio::main]
async fn main() -> anyhow::Result<()> {
    let a = args()?;
    let config = radar_fusion::tls::client_config(&a.ca, None, &[b"http/1.1"])
        .map_err(anyhow::Error::msg)?;
    let name = radar_fusion::tls::server_name(&a.server_name).map_err(anyhow::Error::msg)?;
    let mut full: ClientConfig = config.clone();
    full.resumption = Resumption::disabled();
    let plain = Dial::Plain(a.plain);
    let tls_full = Dial::Tls(a.tls, TlsConnector::from(Arc::new(full)), name.clone());
    let tls_resumed = Dial::Tls(a.tls, TlsConnector::from(Arc::new(config)), name);

    println!(
        "new connection + GET /healthz, {} sequential, mean ms per connection:",
        a.handshakes
    );
    // Warm both servers and the session cache first.
    new_connections(&plain, 20).await?;
    new_connections(&tls_resumed, 20).await?;
    for (label, dial, pid) in [
        ("plaintext", &plain, a.plain_pid),
        ("TLS full handshake", &tls_full, a.tls_pid),
        ("TLS resumed", &tls_resumed, a.tls_pid),
    ] {
        let before = cpu_seconds(pid);
        let (ms, resumed) = new_connections(dial, a.handshakes).await?;
        let cpu = cpu_each(before, cpu_seconds(pid), a.handshakes as f64);
        println!(
            "  {label:<20} {ms:.3} ms ({:.0} connections/s; {resumed} resumed{cpu})",
            1e3 / ms
        );
    }

    println!(
        "rules endpoint, {} keep-alive HTTP/1.1 connections, {} s per round, alternated:",
        a.connections, a.seconds
    );
    let (mut plain_sum, mut tls_sum) = (0.0, 0.0);
    for round in 1..=a.rounds {
        let before = cpu_seconds(a.plain_pid);
        let p = throughput(&plain, a.connections, a.seconds).await?;
        let p_cpu = cpu_each(before, cpu_seconds(a.plain_pid), p * a.seconds);
        let before = cpu_seconds(a.tls_pid);
        let t = throughput(&tls_resumed, a.connections, a.seconds).await?;
        let t_cpu = cpu_each(before, cpu_seconds(a.tls_pid), t * a.seconds);
        println!(
            "  round {round}: plaintext {p:.0} req/s{p_cpu}; TLS {t:.0} req/s{t_cpu} ({:.1} %)",
            100.0 * t / p
        );
        plain_sum += p;
        tls_sum += t;
    }
    let rounds = a.rounds as f64;
    println!(
        "  mean: plaintext {:.0} req/s, TLS {:.0} req/s ({:.1} %)",
        plain_sum / rounds,
        tls_sum / rounds,
        100.0 * tls_sum / plain_sum
    );
    Ok(())
}
