//! The accept loop of both servers: hyper's HTTP/1 and HTTP/2 (by the
//! connection preface) over one router, with the connection limits that
//! `axum::serve` cannot set.
//!
//! What it bounds, and why (issue 16, "slow clients lock everyone out"):
//! - **Headers.** A connection must begin a request within
//!   `header_read_timeout` of being accepted (or of its previous response,
//!   on a kept-alive HTTP/1 connection), and an HTTP/1 request's headers must
//!   be complete within it (hyper's header-read timer, which needs the timer
//!   `axum::serve` never sets). Otherwise the connection is closed.
//! - **Connections.** At most `max_connections` open at once (beyond it the
//!   loop stops accepting, so new clients wait in the kernel's backlog
//!   instead of being refused), and at most `max_per_client` from one IP
//!   address (beyond it a new connection is closed at once, counted).
//! - **HTTP/2 streams.** At most `h2_max_concurrent_streams` requests at once
//!   on one HTTP/2 connection (the SETTINGS_MAX_CONCURRENT_STREAMS the
//!   server announces; hyper's default is 200), so one connection cannot
//!   open more bodies at once than that.
//! - **Dead HTTP/2 peers.** A keep-alive PING every `h2_keepalive`; a peer
//!   that does not answer within it is closed, so idle gRPC streams of
//!   vanished clients do not hold connections.
//!
//! - **TLS** (`FUSION_TLS_CERT`, [`crate::tls`]). The handshake shares the
//!   header-read deadline: it and the first request's beginning must both
//!   be done within `header_read_timeout` of the accept, so a client that
//!   handshakes slowly is cut like one that sends headers slowly. A first
//!   byte that is not a TLS handshake record (plaintext to a TLS port) closes
//!   the connection at once. Each accept reads the current configuration, so
//!   a reloaded certificate serves new connections while open ones keep
//!   theirs. A verified client certificate that maps to a tenant is put into
//!   every request of its connection (`auth::CertTenant`).
//!
//! Bodies are bounded elsewhere: the REST router reads a body within its own
//! timeout before a request takes an in-flight slot (`http::admit`), and so
//! does the gRPC router for unary calls (`grpc::admit`); the bytes of all
//! bodies being read at once share one budget (`AppState::read_body`).
//!
//! Graceful shutdown: when `shutdown` completes the loop stops accepting,
//! every connection is asked to finish its requests in flight and close
//! (HTTP/2 GOAWAY), and `serve` returns when all have closed.

use std::{
    collections::HashMap,
    future::Future,
    net::{IpAddr, SocketAddr},
    pin::Pin,
    sync::{Arc, Mutex},
    task::{Context, Poll},
    time::Duration,
};

use axum::{Router, body::Body, extract::Request};
use hyper::body::Incoming;
use hyper_util::{
    rt::{TokioExecutor, TokioIo, TokioTimer},
    server::conn::auto::Builder,
    service::TowerToHyperService,
};
use tokio::{
    io::{AsyncRead, AsyncReadExt, AsyncWrite, ReadBuf},
    net::{TcpListener, TcpStream},
    sync::{Semaphore, watch},
    time::Instant,
};
use tokio_rustls::server::TlsStream;
use tower::ServiceExt as _;

use crate::{auth::CertTenant, config::Settings, tls::TlsPort};

/// The first bytes of every HTTP/2 connection (RFC 9113 §3.4).
const H2_PREFACE: &[u8; 24] = b"PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n";

/// The first byte of a TLS connection: a handshake record (RFC 8446 §5.1).
const TLS_HANDSHAKE_RECORD: u8 = 0x16;

/// The limits of one server's connections.
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Longest wait for a request to begin and (HTTP/1) for its headers.
    pub header_read_timeout: Duration,
    /// Most connections open at once.
    pub max_connections: usize,
    /// Most connections open at once from one IP address (0: unbounded).
    pub max_per_client: usize,
    /// HTTP/2 keep-alive PING interval and answer timeout.
    pub h2_keepalive: Duration,
    /// Most concurrent streams on one HTTP/2 connection.
    pub h2_max_concurrent_streams: u32,
    /// Longest a connection stays open before it is closed gracefully
    /// (`None`: no limit); streams still open are cut [`AGE_GRACE`] later.
    pub max_age: Option<Duration>,
}

impl ConnectionLimits {
    /// The connection limits of both servers, from the settings.
    pub fn from_settings(s: &Settings) -> Self {
        Self {
            header_read_timeout: Duration::from_secs_f64(s.header_read_timeout_s),
            max_connections: s.max_connections,
            max_per_client: s.max_connections_per_client,
            h2_keepalive: Duration::from_secs_f64(s.h2_keepalive_s),
            h2_max_concurrent_streams: s.h2_max_concurrent_streams,
            max_age: (s.max_connection_age_s > 0.0)
                .then(|| Duration::from_secs_f64(s.max_connection_age_s)),
        }
    }
}

/// How long a connection closed for its age may take to finish the
/// requests and streams it has open before it is cut.
pub const AGE_GRACE: Duration = Duration::from_secs(30);

/// Serves `router` on `listener` under `limits` until `shutdown` completes,
/// then drains (see the module documentation). `server` names the server
/// in metrics and logs (`http`, `grpc`). With `tls`, every connection is a
/// TLS one (see the module documentation).
pub async fn serve<F>(
    listener: TcpListener,
    router: Router,
    limits: ConnectionLimits,
    server: &'static str,
    tls: Option<TlsPort>,
    shutdown: F,
) where
    F: Future<Output = ()> + Send,
{
    let slots = Arc::new(Semaphore::new(limits.max_connections.max(1)));
    let clients = ClientCounts::new(limits.max_per_client);
    // `stop_tx` is dropped to ask every connection to close gracefully; each
    // connection task holds a `closed_rx`, so `closed_tx.closed()` completes
    // when the last one has ended.
    let (stop_tx, stop_rx) = watch::channel(());
    let (closed_tx, closed_rx) = watch::channel(());
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let slot = tokio::select! {
            slot = slots.clone().acquire_owned() => slot.expect("the semaphore is never closed"),
            () = &mut shutdown => break,
        };
        let (tcp, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(e) => {
                    accept_error(server, &e).await;
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let Some(client) = clients.try_enter(peer.ip()) else {
            metrics::counter!("connections_refused_total", "server" => server, "reason" => "per_client")
                .increment(1);
            tracing::debug!(%peer, server, "connection refused: too many from this client (FUSION_MAX_CONNECTIONS_PER_CLIENT)");
            drop(tcp);
            continue;
        };
        if let Err(e) = tcp.set_nodelay(true) {
            // Small HTTP/2 frames must not wait for the peer's delayed ACK
            // (Nagle): without it a gRPC stream update took 40 ms more.
            tracing::warn!(error = %e, "TCP_NODELAY could not be set");
        }
        let router = router.clone();
        let tls = tls.clone();
        let mut stop_rx = stop_rx.clone();
        let closed_rx = closed_rx.clone();
        tokio::spawn(async move {
            let _slot = slot;
            let _client = client;
            let _closed = closed_rx;
            metrics::gauge!("connections_open", "server" => server).increment(1.0);
            let _open = OpenGauge(server);
            // The handshake and the first request's beginning share one
            // deadline from the accept.
            let deadline = Instant::now() + limits.header_read_timeout;
            let Some(tls) = tls else {
                tokio::select! {
                    begun = request_begins(&tcp, deadline) => if !begun {
                        first_request_timed_out(server);
                        return;
                    },
                    // Stopping: a connection that has sent nothing is just closed.
                    _ = stop_rx.changed() => return,
                }
                serve_connection(tcp, router, None, limits, server, stop_rx).await;
                return;
            };
            let (stream, cert_tenant) = tokio::select! {
                accepted = handshake(tcp, &tls, deadline, server, peer) => match accepted {
                    Some(accepted) => accepted,
                    None => return,
                },
                _ = stop_rx.changed() => return,
            };
            let stream = tokio::select! {
                begun = tls_request_begins(stream, deadline) => match begun {
                    Some(stream) => stream,
                    None => {
                        first_request_timed_out(server);
                        return;
                    }
                },
                _ = stop_rx.changed() => return,
            };
            serve_connection(stream, router, cert_tenant, limits, server, stop_rx).await;
        });
    }
    drop(listener);
    drop(stop_tx);
    drop(closed_rx);
    closed_tx.closed().await;
}

/// Serves one connection whose request has begun: hyper's HTTP/1 and
/// HTTP/2 over `router`, each request carrying the connection's
/// certificate tenant, until it ends or (after `stop_rx` fires) drains.
async fn serve_connection<I>(
    io: I,
    router: Router,
    cert_tenant: Option<CertTenant>,
    limits: ConnectionLimits,
    server: &'static str,
    mut stop_rx: watch::Receiver<()>,
) where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    let service = router.map_request(move |req: Request<Incoming>| {
        let mut req = req.map(Body::new);
        if let Some(tenant) = &cert_tenant {
            req.extensions_mut().insert(tenant.clone());
        }
        req
    });
    let mut builder = Builder::new(TokioExecutor::new());
    builder
        .http1()
        .timer(TokioTimer::new())
        .header_read_timeout(limits.header_read_timeout);
    builder
        .http2()
        .timer(TokioTimer::new())
        .keep_alive_interval(limits.h2_keepalive)
        .keep_alive_timeout(limits.h2_keepalive)
        .max_concurrent_streams(limits.h2_max_concurrent_streams)
        .enable_connect_protocol();
    let conn =
        builder.serve_connection_with_upgrades(TokioIo::new(io), TowerToHyperService::new(service));
    let mut conn = std::pin::pin!(conn);
    let mut stopping = false;
    // The connection's age limit, then the grace after it.
    let mut aged = false;
    let age = tokio::time::sleep(limits.max_age.unwrap_or(Duration::MAX / 4));
    let mut age = std::pin::pin!(age);
    loop {
        tokio::select! {
            result = conn.as_mut() => {
                if let Err(e) = result {
                    tracing::trace!(error = %e, server, "connection ended with an error");
                }
                break;
            }
            _ = stop_rx.changed(), if !stopping => {
                stopping = true;
                conn.as_mut().graceful_shutdown();
            }
            () = &mut age, if limits.max_age.is_some() => {
                if aged {
                    metrics::counter!("connections_aged_out_total", "server" => server, "how" => "cut")
                        .increment(1);
                    break;
                }
                aged = true;
                metrics::counter!("connections_aged_out_total", "server" => server, "how" => "graceful")
                    .increment(1);
                if !stopping {
                    stopping = true;
                    conn.as_mut().graceful_shutdown();
                }
                age.as_mut().reset(Instant::now() + AGE_GRACE);
            }
        }
    }
}

fn first_request_timed_out(server: &'static str) {
    metrics::counter!("connections_timed_out_total", "server" => server, "phase" => "first_request")
        .increment(1);
}

/// Waits until the connection has sent enough to tell HTTP/1 from HTTP/2
/// (hyper then starts at once): a byte that differs from the HTTP/2
/// preface, or the whole preface. False when the peer closes first or the
/// deadline passes; the connection is then dropped.
async fn request_begins(tcp: &TcpStream, deadline: Instant) -> bool {
    let mut buf = [0u8; H2_PREFACE.len()];
    loop {
        let Ok(Ok(n)) = tokio::time::timeout_at(deadline, tcp.peek(&mut buf)).await else {
            return false;
        };
        if n == 0 {
            return false;
        }
        if begins(&buf[..n]) {
            return true;
        }
        // A part of the preface: `peek` would return the same bytes at
        // once (so its timeout never fires), so wait a little before looking
        // again, until the deadline.
        if Instant::now() >= deadline {
            return false;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
}

/// Whether `start` tells HTTP/1 from HTTP/2: it differs from the preface
/// or is all of it.
fn begins(start: &[u8]) -> bool {
    start.len() >= H2_PREFACE.len() || start != &H2_PREFACE[..start.len()]
}

/// The TLS handshake of one connection, within `deadline`: a first byte that
/// is not a TLS handshake record (plaintext sent to a TLS port) closes the
/// connection at once. Counts the outcome; `None` when it failed. The
/// certificate tenant is that of a verified client certificate mapped by
/// `FUSION_TLS_CLIENT_TENANTS`.
async fn handshake(
    tcp: TcpStream,
    tls: &TlsPort,
    deadline: Instant,
    server: &'static str,
    peer: SocketAddr,
) -> Option<(TlsStream<TcpStream>, Option<CertTenant>)> {
    let failed = |reason: &'static str| {
        metrics::counter!("tls_handshake_failures_total", "server" => server, "reason" => reason)
            .increment(1);
        tracing::debug!(%peer, server, reason, "TLS handshake failed");
    };
    let mut first = [0u8; 1];
    match tokio::time::timeout_at(deadline, tcp.peek(&mut first)).await {
        Err(_) => {
            failed("timeout");
            return None;
        }
        Ok(Ok(0) | Err(_)) => {
            failed("closed");
            return None;
        }
        Ok(Ok(_)) if first[0] != TLS_HANDSHAKE_RECORD => {
            failed("not_tls");
            return None;
        }
        Ok(Ok(_)) => {}
    }
    let acceptor = tls.acceptor();
    let stream = match tokio::time::timeout_at(deadline, acceptor.tls.accept(tcp)).await {
        Err(_) => {
            failed("timeout");
            return None;
        }
        Ok(Err(e)) => {
            let reason = crate::tls::failure_reason(&e);
            failed(reason);
            tracing::trace!(%peer, server, error = %e, "TLS handshake error");
            return None;
        }
        Ok(Ok(stream)) => stream,
    };
    let conn = stream.get_ref().1;
    let kind = match conn.handshake_kind() {
        Some(rustls::HandshakeKind::Resumed) => "resumed",
        _ => "full",
    };
    metrics::counter!("tls_handshakes_total", "server" => server, "kind" => kind).increment(1);
    let tenant = crate::tls::cert_tenant(&acceptor.tenants, conn);
    Some((stream, tenant))
}

/// [`request_begins`] for a TLS stream, which cannot be peeked: reads the
/// first bytes of the request (within `deadline`) and hands them back in
/// front of the stream.
async fn tls_request_begins<S>(mut stream: S, deadline: Instant) -> Option<Prefixed<S>>
where
    S: AsyncRead + Unpin,
{
    let mut start = [0u8; H2_PREFACE.len()];
    let mut n = 0;
    while !begins(&start[..n]) {
        match tokio::time::timeout_at(deadline, stream.read(&mut start[n..])).await {
            Ok(Ok(0) | Err(_)) | Err(_) => return None,
            Ok(Ok(read)) => n += read,
        }
    }
    Some(Prefixed {
        prefix: start[..n].to_vec(),
        at: 0,
        inner: stream,
    })
}

/// A stream whose first bytes were read already: they are read again first.
struct Prefixed<S> {
    prefix: Vec<u8>,
    at: usize,
    inner: S,
}

impl<S: AsyncRead + Unpin> AsyncRead for Prefixed<S> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<std::io::Result<()>> {
        if self.at < self.prefix.len() {
            let n = (self.prefix.len() - self.at).min(buf.remaining());
            let at = self.at;
            buf.put_slice(&self.prefix[at..at + n]);
            self.at += n;
            return Poll::Ready(Ok(()));
        }
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<S: AsyncWrite + Unpin> AsyncWrite for Prefixed<S> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<std::io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[std::io::IoSlice<'_>],
    ) -> Poll<std::io::Result<usize>> {
        Pin::new(&mut self.inner).poll_write_vectored(cx, bufs)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }
}

/// Accept errors: per-connection ones (the peer reset before we took it) are
/// skipped; others (out of file descriptors) are logged and the loop waits
/// a moment so that it does not spin.
async fn accept_error(server: &'static str, e: &std::io::Error) {
    use std::io::ErrorKind::*;
    if matches!(
        e.kind(),
        ConnectionAborted | ConnectionReset | ConnectionRefused | Interrupted
    ) {
        return;
    }
    metrics::counter!("accept_errors_total", "server" => server).increment(1);
    tracing::error!(error = %e, server, "accept failed; retrying in 100 ms");
    tokio::time::sleep(Duration::from_millis(100)).await;
}

/// Decrements the open-connections gauge when a connection task ends.
struct OpenGauge(&'static str);

impl Drop for OpenGauge {
    fn drop(&mut self) {
        metrics::gauge!("connections_open", "server" => self.0).decrement(1.0);
    }
}

/// Open connections per client IP address, bounded.
#[derive(Clone)]
struct ClientCounts {
    max: usize,
    counts: Arc<Mutex<HashMap<IpAddr, usize>>>,
}

impl ClientCounts {
    fn new(max: usize) -> Self {
        Self {
            max,
            counts: Arc::default(),
        }
    }

    /// Counts a new connection from `ip`, or None when it already holds
    /// `max` (never None when `max` is 0).
    fn try_enter(&self, ip: IpAddr) -> Option<ClientGuard> {
        let ip = ip.to_canonical();
        let mut counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        let count = counts.entry(ip).or_insert(0);
        if self.max > 0 && *count >= self.max {
            return None;
        }
        *count += 1;
        Some(ClientGuard {
            ip,
            counts: self.clone(),
        })
    }
}

/// One counted connection; uncounted when dropped.
struct ClientGuard {
    ip: IpAddr,
    counts: ClientCounts,
}

impl Drop for ClientGuard {
    fn drop(&mut self) {
        let mut counts = self.counts.counts.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(count) = counts.get_mut(&self.ip) {
            *count -= 1;
            if *count == 0 {
                counts.remove(&self.ip);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_connection_limits_come_from_the_settings() {
        let mut s = Settings::for_tests();
        s.h2_max_concurrent_streams = 100;
        s.max_connection_age_s = 0.0;
        let limits = ConnectionLimits::from_settings(&s);
        assert_eq!(limits.h2_max_concurrent_streams, 100);
        assert_eq!(limits.max_age, None, "0 s: no limit");
        s.max_connection_age_s = 2.5;
        let limits = ConnectionLimits::from_settings(&s);
        assert_eq!(limits.max_age, Some(Duration::from_millis(2500)));
    }

    #[test]
    fn per_client_counts_are_bounded_and_released() {
        let counts = ClientCounts::new(2);
        let a: IpAddr = "10.0.0.1".parse().unwrap();
        let b: IpAddr = "10.0.0.2".parse().unwrap();
        let first = counts.try_enter(a).expect("first of a");
        let _second = counts.try_enter(a).expect("second of a");
        assert!(counts.try_enter(a).is_none(), "a third from a is refused");
        let _other = counts
            .try_enter(b)
            .expect("another client is counted apart");
        drop(first);
        assert!(counts.try_enter(a).is_some(), "a slot of a is free again");
    }

    #[test]
    fn ipv4_mapped_addresses_count_as_their_ipv4_client() {
        let counts = ClientCounts::new(1);
        let _v4 = counts.try_enter("10.0.0.1".parse().unwrap()).unwrap();
        assert!(
            counts
                .try_enter("::ffff:10.0.0.1".parse().unwrap())
                .is_none(),
            "the same client over an IPv6 socket"
        );
    }

    #[test]
    fn zero_means_unbounded() {
        let counts = ClientCounts::new(0);
        let ip: IpAddr = "10.0.0.1".parse().unwrap();
        let guards: Vec<_> = (0..100).map(|_| counts.try_enter(ip).unwrap()).collect();
        assert_eq!(guards.len(), 100);
    }
}
