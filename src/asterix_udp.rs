//! The ASTERIX UDP listener (off by default; `--asterix-udp ADDR`):
//! datagrams of CAT048/CAT034 data blocks, as radars multicast them, feed
//! one `plot_fusion` session through the same session push as a client's
//! batches (`Sessions::push`, so the store's compare-and-set, limits and
//! exactly-once rules hold).
//!
//! The session is `--asterix-session-id` of `--asterix-tenant`, configured
//! by `--asterix-session-spec` (the JSON of a `plot_fusion` create
//! request); the listener creates it at start when it does not exist, and
//! again if it expires. Datagrams waiting together are pushed as one batch
//! (at most [`MAX_DATAGRAMS_PER_BATCH`]; data blocks are self-delimiting,
//! so their concatenation is valid ASTERIX). Times of day are taken
//! nearest to the session's newest plot, or to the time of reception for a
//! session that has processed none. The session takes plots in any order
//! within its `tracker.max_lag_s`, and each update holds every plot
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
//! `fusion_asterix_push_failures_total`; out: `fusion_cat062_datagrams_total`,
//! `fusion_cat062_records_total`, `fusion_cat062_skipped_total` (values
//! left out of a record, out of their item's range),
//! `fusion_cat062_send_failures_total`.

use std::{
    net::{IpAddr, Ipv4Addr, Ipv6Addr, SocketAddr, UdpSocket as StdUdpSocket},
    time::{SystemTime, UNIX_EPOCH},
};

use anyhow::Context;
use tokio::{net::UdpSocket, task::JoinHandle};

use crate::state::AppState;
use service::{
    ServiceError,
    plot_fusion::{SpecInput, asterix::AsterixInput},
    session::{
        Batch, Spec,
        plot_fusion::{BatchInput, PlotFusionSession},
    },
};

/// Most datagrams pushed as one batch.
pub const MAX_DATAGRAMS_PER_BATCH: usize = 64;
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
    let socket = bind(addr, settings.asterix_interface)
        .with_context(|| format!("binding the ASTERIX UDP address {addr}"))?;
    let listener = Listener {
        state: state.clone(),
        tenant: settings.asterix_tenant.clone(),
        id: settings.asterix_session_id.clone(),
        spec,
        out,
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

fn bind(addr: SocketAddr, interface: Ipv4Addr) -> anyhow::Result<UdpSocket> {
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
    socket.set_nonblocking(true)?;
    Ok(UdpSocket::from_std(socket)?)
}

struct Listener {
    state: AppState,
    tenant: String,
    id: String,
    spec: Spec<SpecInput>,
    out: Option<Out>,
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

    async fn run(self, socket: UdpSocket) {
        let mut buf = vec![0u8; DATAGRAM_BYTES];
        loop {
            let n = match socket.recv(&mut buf).await {
                Ok(n) => n,
                Err(e) => {
                    tracing::warn!(error = %e, "ASTERIX UDP receive failed");
                    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
                    continue;
                }
            };
            let mut data = buf[..n].to_vec();
            let mut datagrams = 1u64;
            while (datagrams as usize) < MAX_DATAGRAMS_PER_BATCH {
                match socket.try_recv(&mut buf) {
                    Ok(n) => {
                        data.extend_from_slice(&buf[..n]);
                        datagrams += 1;
                    }
                    Err(_) => break,
                }
            }
            metrics::counter!("fusion_asterix_datagrams_total").increment(datagrams);
            self.push(data).await;
        }
    }

    async fn push(&self, data: Vec<u8>) {
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
                }),
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
