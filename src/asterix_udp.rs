//! The ASTERIX UDP listener (off by default; `--asterix-udp ADDR`):
//! datagrams of CAT048/CAT034 data blocks, as radars multicast them, feed
//! one `plot_fusion` session through the same session push as a client's
//! batches (`Sessions::push`, so the store's compare-and-set, limits and
//! exactly-once rules hold).
//!
//! The session is `--asterix-session-id` of `--asterix-tenant`, configured
//! by `--asterix-session-spec` (the JSON of a `plot_fusion` create
//! request); the listener creates it at start when it does not exist, and
//! again if it expires. A reader task takes every datagram off the socket
//! as it arrives (stamped with its time of receipt), and the datagrams
//! waiting together are pushed as one batch (data blocks are
//! self-delimiting, so their concatenation is valid ASTERIX), at most what
//! the session's size check admits under `--max-batch-reports` (one plot
//! counted per 10 bytes). While a push runs, the next batch grows; the
//! socket's buffer only holds what arrives while the reader is not
//! running (`--asterix-recv-buffer-bytes`, SO_RCVBUF). Times of day are
//! taken nearest to the session's newest plot, or to the time of reception
//! for a session that has processed none. The session takes plots in any
//! order within its `tracker.max_lag_s`, and each update holds every plot
//! received (the open scan group included): the tracks do not lag a scan.
//!
//! CAT062 out (`--asterix-out-udp ADDR`, off by default): each update of
//! the session, as its `cat062` field holds it (the spec must carry
//! `cat062`), is sent as datagrams of whole data blocks, each datagram at
//! most `--asterix-out-max-datagram` bytes (the spec's
//! `cat062.max_block_bytes` must not be larger, checked at start). To a
//! multicast group, with `--asterix-out-ttl` and from
//! `--asterix-out-interface`. A batch whose push failed sends nothing.
//!
//! Counters in `/metrics`: `fusion_asterix_datagrams_total`,
//! `fusion_asterix_records_total`, `fusion_asterix_plots_total`,
//! `fusion_asterix_decode_errors_total`, `fusion_asterix_late_plots_total`,
//! `fusion_asterix_push_failures_total`, and the histogram
//! `fusion_asterix_latency_seconds`: per applied batch, from the receipt
//! of its earliest datagram to the applied update. Out:
//! `fusion_cat062_datagrams_total`, `fusion_cat062_records_total`,
//! `fusion_cat062_skipped_total` (values left out of a record, out of
//! their item's range), `fusion_cat062_send_failures_total`.

use std::{
    collections::VecDeque,
    net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket as StdUdpSocket},
    sync::{Arc, Mutex},
    time::{Instant, SystemTime, UNIX_EPOCH},
};

use anyhow::Context;
use tokio::{
    net::UdpSocket,
    sync::Notify,
    task::{JoinHandle, JoinSet},
};

use crate::{allowlist::Sources, state::AppState};
use service::{
    ServiceError,
    plot_fusion::{
        SpecInput,
        asterix::{AsterixInput, MIN_PLOT_RECORD_BYTES, Reception},
    },
    session::{
        Batch, Spec,
        plot_fusion::{BatchInput, PlotFusionSession},
    },
};

/// Bytes of datagrams waiting for a push beyond which the listener stops
/// reading its socket until a push takes them.
pub const MAX_WAITING_BYTES: usize = 16 << 20;
/// Largest datagram read (the UDP maximum).
const DATAGRAM_BYTES: usize = 65_536;

/// Reads the session spec file into a spec: the body of `POST
/// /v1/sessions`, parsed by the REST adapter (`app` passes
/// `http::sessions::plot_fusion_spec_from_json`, so that this listener
/// does not depend on its sibling adapter).
pub type SpecParser = fn(&str) -> Result<Spec<SpecInput>, String>;

/// Binds the configured address (joining a multicast group) and spawns the
/// listener; `None` when `--asterix-udp` is not set.
pub async fn spawn(
    state: &AppState,
    parse_spec: SpecParser,
) -> anyhow::Result<Option<JoinHandle<()>>> {
    let settings = state.settings();
    let Some(addr) = settings.asterix_udp else {
        return Ok(None);
    };
    let path = settings
        .asterix_session_spec
        .clone()
        .context("--asterix-udp needs --asterix-session-spec")?;
    let json = std::fs::read_to_string(&path)
        .with_context(|| format!("reading --asterix-session-spec {}", path.display()))?;
    let spec = parse_spec(&json)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("--asterix-session-spec {}", path.display()))?;
    let out = match settings.asterix_out_udp {
        Some(to) => Some(Out::open(settings, &spec, to)?),
        None => None,
    };
    let socket = bind(
        addr,
        settings.asterix_interface,
        settings.asterix_recv_buffer_bytes,
    )
    .with_context(|| format!("binding the ASTERIX UDP address {addr}"))?;
    let listener = Listener {
        state: state.clone(),
        tenant: settings.asterix_tenant.clone(),
        id: settings.asterix_session_id.clone(),
        spec,
        out,
        max_clock_offset_s: settings.asterix_max_clock_offset_s,
        sources: Sources::parse("--asterix-allow", &settings.asterix_allow)
            .map_err(anyhow::Error::msg)?,
    };
    listener.ensure_session().await;
    tracing::info!(
        addr = %socket.local_addr()?,
        session = %listener.id,
        tenant = %listener.tenant,
        "listening for ASTERIX datagrams"
    );
    Ok(Some(tokio::spawn(listener.run(socket))))
}

fn bind(addr: SocketAddr, interface: Ipv4Addr, recv_buffer: usize) -> anyhow::Result<UdpSocket> {
    let socket = match addr.ip() {
        IpAddr::V4(group) if group.is_multicast() => {
            let s = StdUdpSocket::bind(SocketAddr::new(Ipv4Addr::UNSPECIFIED.into(), addr.port()))?;
            s.join_multicast_v4(&group, &interface)
                .with_context(|| format!("joining multicast group {group} on {interface}"))?;
            s
        }
        IpAddr::V6(group) if group.is_multicast() => {
            let s = StdUdpSocket::bind(SocketAddr::new(Ipv6Addr::UNSPECIFIED.into(), addr.port()))?;
            s.join_multicast_v6(&group, 0)
                .with_context(|| format!("joining multicast group {group}"))?;
            s
        }
        _ => StdUdpSocket::bind(addr)?,
    };
    let sock = socket2::SockRef::from(&socket);
    if recv_buffer > 0 {
        sock.set_recv_buffer_size(recv_buffer)
            .context("--asterix-recv-buffer-bytes (SO_RCVBUF)")?;
    }
    // Linux caps the request at net.core.rmem_max and reports twice what
    // it granted (its bookkeeping overhead included).
    tracing::info!(
        requested = recv_buffer,
        granted = sock.recv_buffer_size().unwrap_or(0),
        "ASTERIX UDP receive buffer (bytes)"
    );
    socket.set_nonblocking(true)?;
    Ok(UdpSocket::from_std(socket)?)
}

struct Listener {
    state: AppState,
    tenant: String,
    id: String,
    spec: Spec<SpecInput>,
    out: Option<Out>,
    /// `--asterix-max-clock-offset-s` (0: no check).
    max_clock_offset_s: f64,
    /// `--asterix-allow`.
    sources: Sources,
}

/// Where CAT062 goes.
struct Out {
    socket: UdpSocket,
    to: SocketAddr,
    max_datagram: usize,
}

impl Out {
    fn open(
        settings: &crate::config::Settings,
        spec: &Spec<SpecInput>,
        to: SocketAddr,
    ) -> anyhow::Result<Self> {
        let Some(cat062) = &spec.body.cat062 else {
            anyhow::bail!(
                "--asterix-out-udp needs `cat062` (sac, sic) in --asterix-session-spec: the \
                 fusion centre's SAC/SIC for I062/010"
            );
        };
        let block = cat062
            .max_block_bytes
            .unwrap_or(service::plot_fusion::cat062::DEFAULT_BLOCK_BYTES)
            as usize;
        let max_datagram = settings.asterix_out_max_datagram;
        if block > max_datagram {
            anyhow::bail!(
                "cat062.max_block_bytes ({block}) of --asterix-session-spec is larger than \
                 --asterix-out-max-datagram ({max_datagram}): a block would not fit a datagram"
            );
        }
        let local: SocketAddr = match to {
            SocketAddr::V4(_) => (Ipv4Addr::UNSPECIFIED, 0).into(),
            SocketAddr::V6(_) => (Ipv6Addr::UNSPECIFIED, 0).into(),
        };
        let s = StdUdpSocket::bind(local)
            .with_context(|| format!("binding a socket to send CAT062 to {to}"))?;
        match to.ip() {
            IpAddr::V4(group) if group.is_multicast() => {
                s.set_multicast_ttl_v4(settings.asterix_out_ttl)
                    .context("--asterix-out-ttl")?;
                socket2::SockRef::from(&s)
                    .set_multicast_if_v4(&settings.asterix_out_interface)
                    .context("--asterix-out-interface")?;
            }
            IpAddr::V6(group) if group.is_multicast() => {
                // The hop limit of IPv6 multicast is the system's default.
            }
            _ => {
                s.set_ttl(settings.asterix_out_ttl.max(1))
                    .context("--asterix-out-ttl")?;
            }
        }
        s.set_nonblocking(true)?;
        tracing::info!(%to, max_datagram, "sending CAT062 datagrams");
        Ok(Self {
            socket: UdpSocket::from_std(s)?,
            to,
            max_datagram,
        })
    }

    /// Sends the update's CAT062 blocks, packed into datagrams.
    async fn send(&self, c: &service::plot_fusion::cat062::Cat062Data) {
        metrics::counter!("fusion_cat062_records_total").increment(c.records as u64);
        metrics::counter!("fusion_cat062_skipped_total").increment(c.skipped as u64);
        for datagram in datagrams(&c.data, self.max_datagram) {
            match self.socket.send_to(datagram, self.to).await {
                Ok(_) => metrics::counter!("fusion_cat062_datagrams_total").increment(1),
                Err(e) => {
                    metrics::counter!("fusion_cat062_send_failures_total").increment(1);
                    tracing::warn!(error = %e, to = %self.to, "CAT062 datagram not sent");
                }
            }
        }
    }
}

/// Consecutive whole data blocks (each `CAT | LEN | …`, LEN big-endian
/// and counting the whole block) grouped into slices of at most `max`
/// bytes; a block larger than `max` alone in its slice.
pub fn datagrams(data: &[u8], max: usize) -> Vec<&[u8]> {
    let mut out = Vec::new();
    let (mut start, mut at) = (0, 0);
    while at + 3 <= data.len() {
        let len = usize::from(u16::from_be_bytes([data[at + 1], data[at + 2]])).max(3);
        let end = (at + len).min(data.len());
        if end - start > max && at > start {
            out.push(&data[start..at]);
            start = at;
        }
        at = end;
    }
    if at > start {
        out.push(&data[start..at]);
    }
    out
}

impl Listener {
    /// Creates the session unless it exists.
    async fn ensure_session(&self) {
        let sessions = self.state.sessions();
        if sessions.kind_of(&self.tenant, &self.id).await.is_ok() {
            return;
        }
        match sessions
            .create_with_id::<PlotFusionSession>(&self.tenant, &self.id, self.spec.clone())
            .await
        {
            Ok(_) => tracing::info!(session = %self.id, "ASTERIX session created"),
            Err(ServiceError::Conflict(_)) => {}
            Err(e) => tracing::warn!(error = %e, "ASTERIX session could not be created"),
        }
    }

    /// Reads datagrams and pushes them: a reader task takes every datagram
    /// off the socket as it arrives, stamped with its time of receipt, into
    /// a [`Queue`], while this task pushes what waits as one batch at a
    /// time. A push that takes long makes the next batch larger; it does
    /// not leave datagrams in the socket's buffer to overflow it.
    async fn run(self, socket: UdpSocket) {
        let queue = Arc::new(Queue::default());
        // Aborted with this task (the listener is aborted at shutdown).
        let mut reader = JoinSet::new();
        reader.spawn(read(socket, Arc::clone(&queue), self.sources.clone()));
        let max_bytes = batch_bytes(self.state.settings().max_batch_reports);
        loop {
            let Some(batch) = queue.take(max_bytes) else {
                queue.arrived.notified().await;
                continue;
            };
            queue.room.notify_one();
            self.push(batch.data, batch.first_received).await;
        }
    }

    async fn push(&self, data: Vec<u8>, first_received: Instant) {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0.0, |d| d.as_secs_f64());
        let batch = || Batch {
            sequence: None,
            body: BatchInput {
                plots: Vec::new(),
                asterix: Some(AsterixInput {
                    data: data.clone(),
                    date: None,
                    day_start_t: None,
                    reference_t: Some(now),
                    reception: (self.max_clock_offset_s > 0.0).then_some(Reception {
                        t: now,
                        max_offset_s: self.max_clock_offset_s,
                    }),
                }),
                nmea: None,
                flush: false,
            },
        };
        let limits = self.state.settings().session_limits();
        let sessions = self.state.sessions();
        let mut result = sessions
            .push::<PlotFusionSession>(&self.tenant, &self.id, batch(), limits)
            .await;
        if matches!(result, Err(ServiceError::NotFound(_))) {
            self.ensure_session().await;
            result = sessions
                .push::<PlotFusionSession>(&self.tenant, &self.id, batch(), limits)
                .await;
        }
        match result {
            Ok(update) => {
                metrics::histogram!("fusion_asterix_latency_seconds")
                    .record(first_received.elapsed().as_secs_f64());
                if let (Some(out), Some(c)) = (&self.out, &update.body.cat062) {
                    out.send(c).await;
                }
                if let Some(a) = update.body.asterix {
                    metrics::counter!("fusion_asterix_records_total").increment(a.records as u64);
                    metrics::counter!("fusion_asterix_plots_total").increment(a.plots as u64);
                    metrics::counter!("fusion_asterix_decode_errors_total")
                        .increment((a.errors.len() + a.errors_not_listed) as u64);
                    metrics::counter!("fusion_asterix_late_plots_total").increment(a.late as u64);
                }
            }
            Err(e) => {
                metrics::counter!("fusion_asterix_push_failures_total").increment(1);
                tracing::warn!(error = %e, "ASTERIX batch not applied");
            }
        }
    }
}

/// Bytes of ASTERIX in one batch: what the session's size check admits
/// (one plot counted per [`MIN_PLOT_RECORD_BYTES`]) under
/// `--max-batch-reports`.
fn batch_bytes(max_batch_reports: usize) -> usize {
    max_batch_reports
        .saturating_mul(MIN_PLOT_RECORD_BYTES)
        .max(1)
}

/// Datagrams received and not yet pushed, shared by the reader and the
/// pusher of [`Listener::run`].
#[derive(Default)]
struct Queue {
    waiting: Mutex<Waiting>,
    /// A datagram was queued (the reader wakes the pusher).
    arrived: Notify,
    /// Datagrams were taken (the pusher wakes a reader that waits for room).
    room: Notify,
}

#[derive(Default)]
struct Waiting {
    /// Each datagram with its time of receipt, in order of receipt.
    datagrams: VecDeque<(Instant, Vec<u8>)>,
    bytes: usize,
}

/// What one push takes off the queue.
struct Taken {
    data: Vec<u8>,
    /// When its earliest datagram was received.
    first_received: Instant,
}

impl Queue {
    fn waiting(&self) -> std::sync::MutexGuard<'_, Waiting> {
        // The lock guards plain data whose every update is complete: a
        // panic elsewhere cannot leave it half changed.
        self.waiting
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn put(&self, received: Instant, datagram: Vec<u8>) {
        let mut w = self.waiting();
        w.bytes += datagram.len();
        w.datagrams.push_back((received, datagram));
    }

    fn bytes(&self) -> usize {
        self.waiting().bytes
    }

    /// The datagrams waiting, oldest first, concatenated up to `max_bytes`
    /// (at least one); `None` when none waits.
    fn take(&self, max_bytes: usize) -> Option<Taken> {
        let mut w = self.waiting();
        let first_received = w.datagrams.front()?.0;
        let mut data = Vec::with_capacity(w.bytes.min(max_bytes));
        while let Some((_, d)) = w.datagrams.front() {
            if !data.is_empty() && data.len() + d.len() > max_bytes {
                break;
            }
            data.extend_from_slice(d);
            w.datagrams.pop_front();
        }
        w.bytes -= data.len();
        Some(Taken {
            data,
            first_received,
        })
    }
}

/// The reader of [`Listener::run`]: every datagram into `queue` as it
/// arrives, counted in `fusion_asterix_datagrams_total`. While more than
/// [`MAX_WAITING_BYTES`] wait, it stops reading until a push takes them
/// (the socket's receive buffer, `--asterix-recv-buffer-bytes`, holds what
/// arrives meanwhile).
async fn read(socket: UdpSocket, queue: Arc<Queue>, sources: Sources) {
    let mut buf = vec![0u8; DATAGRAM_BYTES];
    loop {
        while queue.bytes() >= MAX_WAITING_BYTES {
            queue.room.notified().await;
        }
        match socket.recv_from(&mut buf).await {
            Ok((n, from)) => {
                let received = Instant::now();
                metrics::counter!("fusion_asterix_datagrams_total").increment(1);
                if !sources.allows(from.ip()) {
                    metrics::counter!("fusion_asterix_refused_datagrams_total").increment(1);
                    continue;
                }
                queue.put(received, buf[..n].to_vec());
                queue.arrived.notify_one();
            }
            Err(e) => {
                tracing::warn!(error = %e, "ASTERIX UDP receive failed");
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_push_takes_the_oldest_datagrams_up_to_its_bytes_and_at_least_one() {
        let q = Queue::default();
        assert!(q.take(100).is_none());
        let t0 = Instant::now();
        let t1 = t0 + std::time::Duration::from_millis(1);
        q.put(t0, vec![1; 40]);
        q.put(t1, vec![2; 40]);
        q.put(t1, vec![3; 40]);
        q.put(t1, vec![4; 200]);
        // 40 + 40 = 80 ≤ 100; a third would make 120.
        let a = q.take(100).unwrap();
        assert_eq!(a.data, [vec![1; 40], vec![2; 40]].concat());
        assert_eq!(a.first_received, t0);
        assert_eq!(q.bytes(), 240);
        let b = q.take(100).unwrap();
        assert_eq!((b.data, b.first_received), (vec![3; 40], t1));
        // A datagram larger than the limit goes alone.
        assert_eq!(q.take(100).unwrap().data, vec![4; 200]);
        assert_eq!(q.bytes(), 0);
        assert!(q.take(100).is_none());
    }

    #[test]
    fn a_batch_holds_what_the_session_size_check_admits() {
        // 100,000 reports of at least 10 bytes: 1,000,000 bytes, whose
        // count 1,000,000 / 10 = 100,000 is within the limit.
        assert_eq!(batch_bytes(100_000), 1_000_000);
        assert_eq!(batch_bytes(0), 1);
        assert_eq!(batch_bytes(usize::MAX), usize::MAX);
    }
}
