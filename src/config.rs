//! Typed settings: embedded defaults, overridden by `FUSION_*` environment
//! variables, overridden by command-line flags. docs/operations.md documents them in
//! one table; keep the two in step.

use std::{net::SocketAddr, path::PathBuf, time::Duration};

use clap::{Args, Parser, Subcommand, ValueEnum};

use store::StoreSettings;

/// The radar fusion service: track-to-track correlation, JPDA, dimension fusion
/// and AIS–radar bias estimation over REST and gRPC.
#[derive(Debug, Parser)]
#[command(
    name = "radar-fusion",
    version,
    about,
    args_conflicts_with_subcommands = true
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub settings: Settings,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Serve REST and gRPC (the default when no command is given; the
    /// server flags go before or after `serve`, not both).
    Serve(Box<Settings>),
    /// Print the OpenAPI document the server serves at /openapi.json.
    Openapi,
    /// Probe a running server's /healthz and exit 0 when it answers 200
    /// (the container health check; the runtime image has no curl).
    Healthcheck {
        /// Address of the REST server to probe.
        #[arg(long, default_value = "127.0.0.1:8080")]
        addr: SocketAddr,
        #[command(flatten)]
        tls: HealthcheckTls,
    },
    /// Copy every session from the Redis store `--from` (one Redis or
    /// Sentinel) into the session store of the settings
    /// (`FUSION_SESSION_STORE`, such as a Redis Cluster), keeping versions,
    /// kinds and TTLs; sessions the target holds already are left alone.
    CopySessions(Box<CopySessions>),
    /// Moved: the experiments are the `radar-fusion-eval` binary of the
    /// `eval` crate; this prints where and exits with status 2.
    #[command(hide = true)]
    Eval {
        /// Ignored: whatever followed `eval`.
        #[arg(trailing_var_arg = true, allow_hyphen_values = true)]
        args: Vec<String>,
    },
}

/// `copy-sessions`: where from, and the settings of the target store (its
/// TLS files and password serve both).
#[derive(Debug, Args)]
pub struct CopySessions {
    /// The store to copy from: `redis://…`, `rediss://…` or a Sentinel URL,
    /// under the same `--session-key-prefix`.
    #[arg(long, env = "FUSION_COPY_SESSIONS_FROM", hide_env_values = true)]
    pub from: String,
    #[command(flatten)]
    pub settings: Settings,
}

/// TLS of the `healthcheck` probe: with `--tls-ca` it speaks TLS to a
/// server started with `FUSION_TLS_CERT`.
#[derive(Debug, Clone, Args)]
pub struct HealthcheckTls {
    /// Probe over TLS, trusting the CA certificates of this PEM file.
    #[arg(long = "tls-ca", env = "FUSION_HEALTHCHECK_TLS_CA")]
    pub ca: Option<PathBuf>,
    /// The name the server's certificate must hold (a DNS name or an IP
    /// address).
    #[arg(
        long = "tls-server-name",
        env = "FUSION_HEALTHCHECK_TLS_SERVER_NAME",
        default_value = "localhost",
        requires = "ca"
    )]
    pub server_name: String,
    /// A client certificate (PEM) for a server that requires one
    /// (`FUSION_TLS_CLIENT_AUTH=required`); needs `--tls-client-key`.
    #[arg(
        long = "tls-client-cert",
        env = "FUSION_HEALTHCHECK_TLS_CLIENT_CERT",
        requires_all = ["ca", "client_key"]
    )]
    pub client_cert: Option<PathBuf>,
    /// The private key (PEM) of `--tls-client-cert`.
    #[arg(
        long = "tls-client-key",
        env = "FUSION_HEALTHCHECK_TLS_CLIENT_KEY",
        requires = "client_cert"
    )]
    pub client_key: Option<PathBuf>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LogFormat {
    Text,
    Json,
}

/// The level of the one-line-per-request access log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum AccessLog {
    /// No access log.
    Off,
    /// At DEBUG: silent under the default `--log info`.
    Debug,
    /// At INFO.
    Info,
}

/// Every runtime setting of the service.
#[derive(Debug, Clone, Args)]
pub struct Settings {
    /// Address of the REST server (it also answers gRPC on the same port).
    #[arg(long, env = "FUSION_HTTP_ADDR", default_value = "0.0.0.0:8080")]
    pub http_addr: SocketAddr,
    /// Address of the dedicated gRPC server.
    #[arg(long, env = "FUSION_GRPC_ADDR", default_value = "0.0.0.0:50051")]
    pub grpc_addr: SocketAddr,
    /// Log filter in `tracing` syntax (for example `info,radar_fusion=debug`).
    #[arg(long, env = "FUSION_LOG", default_value = "info")]
    pub log: String,
    /// Log line format.
    #[arg(long, env = "FUSION_LOG_FORMAT", value_enum, default_value = "text")]
    pub log_format: LogFormat,
    /// Level of the access log (one line per request with status and
    /// latency). Internal errors (500) are logged at ERROR whatever this
    /// says; shed (503) and timed-out (504) requests are counted in
    /// `/metrics` and logged at DEBUG.
    #[arg(long, env = "FUSION_ACCESS_LOG", value_enum, default_value = "debug")]
    pub access_log: AccessLog,
    /// Longest time a request may take before it is answered 504 / DEADLINE_EXCEEDED.
    #[arg(long, env = "FUSION_REQUEST_TIMEOUT_S", default_value_t = 30.0)]
    pub request_timeout_s: f64,
    /// Longest time a REST request's body may take to arrive once its
    /// headers have (408 after it); the request takes an in-flight slot
    /// only when its body is complete, so slow clients cannot hold slots.
    #[arg(long, env = "FUSION_BODY_READ_TIMEOUT_S", default_value_t = 10.0)]
    pub body_read_timeout_s: f64,
    /// Longest time a new connection may take to begin a request, and an
    /// HTTP/1 request to send its headers (also the idle limit of a kept-alive
    /// HTTP/1 connection between requests); the connection is closed after it.
    #[arg(long, env = "FUSION_HEADER_READ_TIMEOUT_S", default_value_t = 10.0)]
    pub header_read_timeout_s: f64,
    /// Most connections open at once per server (REST port, gRPC port);
    /// beyond it new connections wait in the listen backlog.
    #[arg(long, env = "FUSION_MAX_CONNECTIONS", default_value_t = 10_000)]
    pub max_connections: usize,
    /// Most connections open at once from one client IP address per server
    /// (0: unbounded); beyond it a new connection is closed at once. Behind a
    /// load balancer every connection comes from the balancer: raise it or
    /// set 0 there, and bound clients at the balancer.
    #[arg(
        long,
        env = "FUSION_MAX_CONNECTIONS_PER_CLIENT",
        default_value_t = 1024
    )]
    pub max_connections_per_client: usize,
    /// Interval of HTTP/2 keep-alive PINGs, and how long an answer may take
    /// before the connection is closed as dead.
    #[arg(long, env = "FUSION_H2_KEEPALIVE_S", default_value_t = 20.0)]
    pub h2_keepalive_s: f64,
    /// Most concurrent streams (requests) on one HTTP/2 connection, both
    /// ports (the SETTINGS_MAX_CONCURRENT_STREAMS the server announces).
    #[arg(long, env = "FUSION_H2_MAX_CONCURRENT_STREAMS", default_value_t = 100)]
    pub h2_max_concurrent_streams: u32,
    /// Largest request body (REST) or message (gRPC) in bytes, counted
    /// decompressed when it comes compressed; larger ones get 413 /
    /// RESOURCE_EXHAUSTED.
    #[arg(long, env = "FUSION_MAX_BODY_BYTES", default_value_t = 16 * 1024 * 1024)]
    pub max_body_bytes: usize,
    /// Most request-body bytes (decompressed) held at once by all the
    /// requests whose bodies are being read or served, both transports: a
    /// body that would take the total over it is shed as it arrives with
    /// 503 + `Retry-After` / UNAVAILABLE. At least `--max-body-bytes`.
    #[arg(
        long,
        env = "FUSION_MAX_BUFFERED_BODY_BYTES",
        default_value_t = 256 * 1024 * 1024
    )]
    pub max_buffered_body_bytes: usize,
    /// Most API requests in flight at once over both transports; beyond it requests are
    /// shed at once with 503 / UNAVAILABLE instead of queueing.
    #[arg(long, env = "FUSION_MAX_IN_FLIGHT", default_value_t = 512)]
    pub max_in_flight: usize,
    /// Most computations on tokio's blocking pool at once (running or waiting
    /// for a thread): the pool takes work only when every compute lane is
    /// busy with a long request; beyond it a request is shed with 503 /
    /// UNAVAILABLE naming this limit (0: never use the pool).
    #[arg(long, env = "FUSION_MAX_BLOCKING_JOBS", default_value_t = 64)]
    pub max_blocking_jobs: usize,
    /// Memory (MiB) each compute lane touches and gives back to the
    /// allocator at start-up, before the service reports ready, so that the
    /// first requests wait less for the kernel to hand over fresh pages (0:
    /// none; the lanes still run one small dimension fusion each).
    #[arg(long, env = "FUSION_WARM_UP_MIB", default_value_t = 32)]
    pub warm_up_mib: usize,
    /// Longest time a graceful shutdown waits for in-flight requests.
    #[arg(long, env = "FUSION_SHUTDOWN_GRACE_S", default_value_t = 30.0)]
    pub shutdown_grace_s: f64,
    /// Where streaming sessions keep their state: `memory` (this process only)
    /// or a Redis URL such as `redis://127.0.0.1:6379/0` (shared by replicas;
    /// `rediss://` for TLS, `redis+sentinel://` / `rediss+sentinel://` for
    /// Sentinel, `redis+cluster://` / `rediss+cluster://` for Redis Cluster).
    #[arg(
        long,
        env = "FUSION_SESSION_STORE",
        default_value = "memory",
        hide_env_values = true
    )]
    pub session_store: String,
    /// PEM file of the CA that signed Redis's certificate (`rediss://`;
    /// without it, the system's roots).
    #[arg(long, env = "FUSION_REDIS_CA")]
    pub redis_ca: Option<PathBuf>,
    /// PEM client certificate for Redis (`tls-auth-clients yes`); with
    /// `--redis-key`.
    #[arg(long, env = "FUSION_REDIS_CERT")]
    pub redis_cert: Option<PathBuf>,
    /// PEM private key of `--redis-cert`.
    #[arg(long, env = "FUSION_REDIS_KEY")]
    pub redis_key: Option<PathBuf>,
    /// Redis password (overrides the URL's); prefer the environment
    /// variable, since a flag shows in the process list.
    #[arg(long, env = "FUSION_REDIS_PASSWORD", hide_env_values = true)]
    pub redis_password: Option<Secret>,
    /// Replicas that must acknowledge every session write (Redis `WAIT`)
    /// before it is answered; fewer within half the store timeout answers
    /// 503 "retry with the same sequence". 0: asynchronous replication.
    #[arg(long, env = "FUSION_REDIS_WAIT_REPLICAS", default_value_t = 0)]
    pub redis_wait_replicas: usize,
    /// Prefix of every Redis key of the session store.
    #[arg(
        long,
        env = "FUSION_SESSION_KEY_PREFIX",
        default_value = "radar-fusion"
    )]
    pub session_key_prefix: String,
    /// Most live sessions one tenant may hold at once.
    #[arg(long, env = "FUSION_MAX_SESSIONS_PER_TENANT", default_value_t = 100)]
    pub max_sessions_per_tenant: usize,
    /// Memory session store: most bytes of session state held in total.
    #[arg(long, env = "FUSION_SESSION_MEMORY_BYTES", default_value_t = 512 * 1024 * 1024)]
    pub session_memory_bytes: usize,
    /// Memory session store: most bytes of session state one tenant may
    /// hold (429 beyond), so that one tenant cannot fill the store for all.
    /// A service with one tenant may raise it to `--session-memory-bytes`.
    #[arg(long, env = "FUSION_SESSION_MEMORY_BYTES_PER_TENANT", default_value_t = 128 * 1024 * 1024)]
    pub session_memory_bytes_per_tenant: usize,
    /// Decoded sessions kept in process in front of the store, bounded by
    /// their encoded size in bytes (0: none). A push to a session this
    /// replica wrote last then skips the read and the decode; the
    /// compare-and-set on the version still guards every write.
    #[arg(long, env = "FUSION_SESSION_CACHE_BYTES", default_value_t = 256 * 1024 * 1024)]
    pub session_cache_bytes: usize,
    /// A session is stored as a snapshot and the batches applied since (a
    /// log), so a batch writes what it carries, not the whole session:
    /// after this many batches (or once the log is as large as the
    /// snapshot) a new snapshot replaces the log. It is encoded and
    /// written in the background, never on a batch's path. A replica that
    /// takes a session over replays at most this many batches. 1: a
    /// snapshot after every batch.
    #[arg(long, env = "FUSION_SESSION_SNAPSHOT_BATCHES", default_value_t = service::session::persist::DEFAULT_SNAPSHOT_BATCHES)]
    pub session_snapshot_batches: usize,
    /// A snapshot is also due once replaying the log would take this long
    /// (s, as this replica took to apply its batches), so that a replica
    /// taking a session over replays about this much; but not before the
    /// log holds a third of the snapshot's bytes (snapshots then add at
    /// most three times the batches' own bytes to the writes). 0: no bound
    /// by time.
    #[arg(long, env = "FUSION_SESSION_SNAPSHOT_REPLAY_S", default_value_t = service::session::persist::DEFAULT_SNAPSHOT_REPLAY_S)]
    pub session_snapshot_replay_s: f64,
    /// Most watchers (`GET /v1/sessions/{id}/events`, gRPC `Watch`) of one
    /// session on one replica; 429 beyond.
    #[arg(long, env = "FUSION_WATCHERS_PER_SESSION", default_value_t = 32)]
    pub watchers_per_session: usize,
    /// Most watchers of one tenant's sessions on one replica; 429 beyond.
    #[arg(long, env = "FUSION_WATCHERS_PER_TENANT", default_value_t = 128)]
    pub watchers_per_tenant: usize,
    /// Events a watcher may fall behind before it is dropped (an `end` of
    /// reason `slow`).
    #[arg(long, env = "FUSION_WATCH_BUFFER", default_value_t = 256)]
    pub watch_buffer: usize,
    /// Seconds of quiet after which a watcher gets a heartbeat (and the
    /// session is checked to be alive).
    #[arg(long, env = "FUSION_WATCH_HEARTBEAT_S", default_value_t = 15.0)]
    pub watch_heartbeat_s: f64,
    /// Longest time one session-store (Redis) command may take before it fails.
    #[arg(long, env = "FUSION_STORE_TIMEOUT_S", default_value_t = 1.0)]
    pub store_timeout_s: f64,
    /// Most live tracks one streaming session may hold (a plot-fusion
    /// session at the limit starts no new track, with a warning).
    #[arg(long, env = "FUSION_MAX_TRACKS_PER_SESSION", default_value_t = 10_000)]
    pub max_tracks_per_session: usize,
    /// Most track reports in one batch pushed to a session.
    #[arg(long, env = "FUSION_MAX_BATCH_REPORTS", default_value_t = 100_000)]
    pub max_batch_reports: usize,
    /// API keys as comma-separated `key=tenant` pairs (key at least 8 characters,
    /// tenant `[A-Za-z0-9_-]{1,64}`). With no key configured anywhere the service
    /// is open and every request acts as tenant `default`.
    #[arg(long, env = "FUSION_API_KEYS", hide_env_values = true)]
    pub api_keys: Option<Secret>,
    /// A file of API keys, one `key=tenant` per line (`#` starts a comment);
    /// combined with `--api-keys`.
    #[arg(long, env = "FUSION_API_KEYS_FILE")]
    pub api_keys_file: Option<PathBuf>,
    /// The key `/metrics` takes (`Authorization: Bearer <key>`, at least 8
    /// printable characters), and then no other. Without it, `/metrics`
    /// takes any tenant's API key when API keys are configured, and is open
    /// otherwise.
    #[arg(long, env = "FUSION_METRICS_KEY", hide_env_values = true)]
    pub metrics_key: Option<Secret>,
    /// Listen for ASTERIX (CAT048/CAT034) UDP datagrams on this address and
    /// feed them to a plot_fusion session (off by default). A multicast
    /// group address (224.0.0.0/4, ff00::/8) is joined.
    #[arg(long, env = "FUSION_ASTERIX_UDP")]
    pub asterix_udp: Option<SocketAddr>,
    /// The session the datagrams feed: the JSON body of a `plot_fusion`
    /// create request (`POST /v1/sessions`), its radars with `sac`/`sic`.
    /// Required with `--asterix-udp`; the session is created (again) when
    /// it does not exist.
    #[arg(long, env = "FUSION_ASTERIX_SESSION_SPEC")]
    pub asterix_session_spec: Option<PathBuf>,
    /// Id of that session (32 hex digits).
    #[arg(
        long,
        env = "FUSION_ASTERIX_SESSION_ID",
        default_value = "00000000000000000000000000000048"
    )]
    pub asterix_session_id: String,
    /// Tenant of that session.
    #[arg(long, env = "FUSION_ASTERIX_TENANT", default_value = "default")]
    pub asterix_tenant: String,
    /// IPv4 interface address that joins an IPv4 multicast group (0.0.0.0:
    /// the system's choice).
    #[arg(long, env = "FUSION_ASTERIX_INTERFACE", default_value = "0.0.0.0")]
    pub asterix_interface: std::net::Ipv4Addr,
    /// Receive buffer of the ASTERIX socket (SO_RCVBUF, bytes; 0: the
    /// system's default). It holds the datagrams that arrive while the
    /// listener's reader is not running; Linux caps it at
    /// net.core.rmem_max.
    #[arg(
        long,
        env = "FUSION_ASTERIX_RECV_BUFFER_BYTES",
        default_value_t = 4 << 20
    )]
    pub asterix_recv_buffer_bytes: usize,
    /// Largest distance (s) between a target report's time and the
    /// listener's time of reception: a report further off (a radar clock
    /// glitch, a forged datagram) is refused and moves nothing; 0 turns the
    /// check off (a recording replayed into the listener).
    #[arg(
        long,
        env = "FUSION_ASTERIX_MAX_CLOCK_OFFSET_S",
        default_value_t = 60.0
    )]
    pub asterix_max_clock_offset_s: f64,
    /// Sources the ASTERIX listener takes datagrams from: IP addresses or
    /// CIDR prefixes (`192.0.2.7`, `10.1.0.0/16`, `2001:db8::/32`), comma
    /// separated. Empty (the default): every source. UDP is
    /// unauthenticated: this and the host's firewall are what restrict it.
    #[arg(long, env = "FUSION_ASTERIX_ALLOW", value_delimiter = ',')]
    pub asterix_allow: Vec<String>,
    /// Send the ASTERIX session's updates as CAT062 datagrams to this
    /// address (unicast or a multicast group); needs `--asterix-udp` and a
    /// session spec with `cat062`. Off by default.
    #[arg(long, env = "FUSION_ASTERIX_OUT_UDP")]
    pub asterix_out_udp: Option<SocketAddr>,
    /// Largest CAT062 datagram (bytes): whole data blocks are packed into
    /// datagrams up to this size; the spec's `cat062.max_block_bytes` must
    /// not exceed it. 1,472 is the UDP payload of a 1,500-byte Ethernet MTU.
    #[arg(long, env = "FUSION_ASTERIX_OUT_MAX_DATAGRAM", default_value_t = 1472)]
    pub asterix_out_max_datagram: usize,
    /// Multicast TTL (hops) of the CAT062 datagrams.
    #[arg(long, env = "FUSION_ASTERIX_OUT_TTL", default_value_t = 1)]
    pub asterix_out_ttl: u32,
    /// IPv4 interface address that sends to an IPv4 multicast group
    /// (0.0.0.0: the system's choice).
    #[arg(long, env = "FUSION_ASTERIX_OUT_INTERFACE", default_value = "0.0.0.0")]
    pub asterix_out_interface: std::net::Ipv4Addr,
    /// Serve TLS on both ports with this PEM certificate chain (the server's
    /// certificate first); needs `--tls-key`. Without both: plaintext.
    #[arg(long, env = "FUSION_TLS_CERT")]
    pub tls_cert: Option<PathBuf>,
    /// The PEM private key (PKCS#8, PKCS#1 or SEC1) of `--tls-cert`.
    #[arg(long, env = "FUSION_TLS_KEY")]
    pub tls_key: Option<PathBuf>,
    /// A PEM bundle of the CAs whose client certificates are accepted:
    /// turns on client-certificate verification (mutual TLS).
    #[arg(long, env = "FUSION_TLS_CLIENT_CA")]
    pub tls_client_ca: Option<PathBuf>,
    /// With `--tls-client-ca`: `required` (the default: a connection without
    /// a trusted certificate is refused) or `optional` (a client may connect
    /// without one and authenticate with an API key).
    #[arg(long, env = "FUSION_TLS_CLIENT_AUTH", value_enum)]
    pub tls_client_auth: Option<ClientAuth>,
    /// A file mapping client-certificate names to tenants, one
    /// `uri:NAME=tenant`, `dns:NAME=tenant` or `cn:NAME=tenant` per line
    /// (needs `--tls-client-ca`); a certificate that maps stands for its
    /// tenant's API key.
    #[arg(long, env = "FUSION_TLS_CLIENT_TENANTS")]
    pub tls_client_tenants: Option<PathBuf>,
    /// Certificate revocation lists of the client CAs (needs
    /// `--tls-client-ca`): a file of PEM CRLs (one or more) or one DER CRL,
    /// read again with the other TLS files. A client certificate a CRL
    /// revokes is refused at the handshake, and so is one whose revocation
    /// status no CRL gives.
    #[arg(long, env = "FUSION_TLS_CRL")]
    pub tls_crl: Option<PathBuf>,
    /// Longest a connection stays open, in seconds: then it is closed
    /// gracefully (HTTP/2 GOAWAY; requests in progress finish, and streams
    /// still open are cut 30 s later), so that a changed or revoked
    /// certificate, or a changed tenant mapping, takes effect on clients
    /// that keep their connections. 0: no limit.
    #[arg(long, env = "FUSION_MAX_CONNECTION_AGE_S", default_value_t = 3600.0)]
    pub max_connection_age_s: f64,
    /// How often the TLS files are read again, in seconds; a change is
    /// loaded for new connections (SIGHUP reloads at once). 0: on SIGHUP only.
    #[arg(long, env = "FUSION_TLS_RELOAD_S", default_value_t = 10.0)]
    pub tls_reload_s: f64,
}

/// Whether mutual TLS requires a client certificate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ClientAuth {
    /// A connection without a trusted client certificate is refused.
    Required,
    /// A client may connect without a certificate; one it sends must be trusted.
    Optional,
}

/// A setting that must not appear in logs: `Debug` prints `***`.
#[derive(Clone, PartialEq, Eq)]
pub struct Secret(String);

impl Secret {
    pub fn expose(&self) -> &str {
        &self.0
    }
}

impl std::fmt::Debug for Secret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("***")
    }
}

impl std::str::FromStr for Secret {
    type Err = std::convert::Infallible;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(Self(s.to_string()))
    }
}

impl From<&str> for Secret {
    fn from(s: &str) -> Self {
        Self(s.to_string())
    }
}

impl Settings {
    /// Defaults with both servers on port 0 on loopback, for tests.
    pub fn for_tests() -> Self {
        let mut s = Cli::parse_from(["radar-fusion"]).settings;
        s.http_addr = "127.0.0.1:0".parse().expect("literal address");
        s.grpc_addr = "127.0.0.1:0".parse().expect("literal address");
        // Test servers share one process and its lanes: the lanes still run
        // the small fusion at each start, without touching memory for it.
        s.warm_up_mib = 0;
        s
    }

    /// The limits of one streaming session.
    pub fn session_limits(&self) -> service::session::Limits {
        service::session::Limits {
            max_tracks: self.max_tracks_per_session,
            max_batch_reports: self.max_batch_reports,
        }
    }

    pub fn watch_limits(&self) -> service::session::events::WatchLimits {
        service::session::events::WatchLimits {
            per_session: self.watchers_per_session,
            per_tenant: self.watchers_per_tenant,
            buffer: self.watch_buffer,
            history: 64,
            heartbeat: Duration::from_secs_f64(self.watch_heartbeat_s),
        }
    }

    pub fn request_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.request_timeout_s)
    }

    pub fn body_read_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.body_read_timeout_s)
    }

    pub fn shutdown_grace(&self) -> Duration {
        Duration::from_secs_f64(self.shutdown_grace_s)
    }

    /// The session store's settings.
    pub fn store_settings(&self) -> StoreSettings {
        StoreSettings {
            url: self.session_store.clone(),
            redis: store::access::RedisAccessSettings {
                ca: self.redis_ca.clone(),
                cert: self.redis_cert.clone(),
                key: self.redis_key.clone(),
                password: self.redis_password.as_ref().map(|p| p.expose().to_string()),
            },
            wait_replicas: self.redis_wait_replicas,
            key_prefix: self.session_key_prefix.clone(),
            max_sessions_per_tenant: self.max_sessions_per_tenant,
            max_memory_bytes: self.session_memory_bytes,
            max_memory_bytes_per_tenant: self.session_memory_bytes_per_tenant,
            timeout: Duration::from_secs_f64(self.store_timeout_s),
        }
    }

    /// Rejects settings that cannot work, naming the flag.
    pub fn validate(&self) -> Result<(), String> {
        let positive = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 && v < 1e9 {
                Ok(())
            } else {
                Err(format!("--{name} must be a positive number of seconds"))
            }
        };
        positive("request-timeout-s", self.request_timeout_s)?;
        positive("body-read-timeout-s", self.body_read_timeout_s)?;
        positive("shutdown-grace-s", self.shutdown_grace_s)?;
        positive("header-read-timeout-s", self.header_read_timeout_s)?;
        positive("h2-keepalive-s", self.h2_keepalive_s)?;
        if self.max_connections == 0 {
            return Err("--max-connections must be at least 1".into());
        }
        if self.max_body_bytes < 1024 {
            return Err("--max-body-bytes must be at least 1024".into());
        }
        if self.max_buffered_body_bytes < self.max_body_bytes {
            return Err(format!(
                "--max-buffered-body-bytes (FUSION_MAX_BUFFERED_BODY_BYTES, {}) must be at least \
                 --max-body-bytes (FUSION_MAX_BODY_BYTES, {}), or a body at the limit could \
                 never be read",
                self.max_buffered_body_bytes, self.max_body_bytes
            ));
        }
        if self.h2_max_concurrent_streams == 0 {
            return Err("--h2-max-concurrent-streams must be at least 1".into());
        }
        if self.max_in_flight == 0 {
            return Err("--max-in-flight must be at least 1".into());
        }
        positive("store-timeout-s", self.store_timeout_s)?;
        if self.session_snapshot_batches == 0 {
            return Err(
                "--session-snapshot-batches must be at least 1 (1: a snapshot every batch)".into(),
            );
        }
        if !(self.session_snapshot_replay_s.is_finite() && self.session_snapshot_replay_s >= 0.0) {
            return Err(
                "--session-snapshot-replay-s must be a number of seconds, at least 0 (0: no bound \
                 by time)"
                    .into(),
            );
        }
        if self.max_tracks_per_session == 0 {
            return Err("--max-tracks-per-session must be at least 1".into());
        }
        if self.max_batch_reports == 0 {
            return Err("--max-batch-reports must be at least 1".into());
        }
        let store = self.session_store.as_str();
        if store != "memory"
            && ![
                "redis://",
                "rediss://",
                "redis+sentinel://",
                "rediss+sentinel://",
                "redis+cluster://",
                "rediss+cluster://",
            ]
            .iter()
            .any(|scheme| store.starts_with(scheme))
        {
            // Only the scheme: the URL may hold a password.
            let scheme = store.split_once("://").map_or("", |(s, _)| s);
            return Err(format!(
                "--session-store (FUSION_SESSION_STORE) must be `memory` or a Redis URL \
                 starting with redis://, rediss://, redis+sentinel://, rediss+sentinel://, \
                 redis+cluster:// or rediss+cluster://, not one of scheme {scheme:?}"
            ));
        }
        if self.session_key_prefix.is_empty() {
            return Err("--session-key-prefix must not be empty".into());
        }
        if self.max_sessions_per_tenant == 0 {
            return Err("--max-sessions-per-tenant must be at least 1".into());
        }
        if self.watchers_per_session == 0 || self.watchers_per_tenant == 0 || self.watch_buffer == 0
        {
            return Err(
                "--watchers-per-session, --watchers-per-tenant and --watch-buffer (FUSION_WATCHERS_PER_SESSION, FUSION_WATCHERS_PER_TENANT, FUSION_WATCH_BUFFER) must be at least 1"
                    .into(),
            );
        }
        if !(self.watch_heartbeat_s.is_finite()
            && (0.05..=3600.0).contains(&self.watch_heartbeat_s))
        {
            return Err(format!(
                "--watch-heartbeat-s (FUSION_WATCH_HEARTBEAT_S) must be in [0.05, 3600], not {}",
                self.watch_heartbeat_s
            ));
        }
        if self.asterix_udp.is_some() && self.asterix_session_spec.is_none() {
            return Err(
                "--asterix-udp needs --asterix-session-spec (the plot_fusion session to feed)"
                    .into(),
            );
        }
        if self.asterix_out_udp.is_some() && self.asterix_udp.is_none() {
            return Err(
                "--asterix-out-udp needs --asterix-udp (it sends that listener's session's \
                 tracks)"
                    .into(),
            );
        }
        if !(64..=65_507).contains(&self.asterix_out_max_datagram) {
            return Err(format!(
                "--asterix-out-max-datagram must be 64 to 65507 bytes (a UDP payload), not {}",
                self.asterix_out_max_datagram
            ));
        }
        crate::allowlist::Sources::parse("--asterix-allow", &self.asterix_allow)?;
        if !(self.asterix_max_clock_offset_s.is_finite() && self.asterix_max_clock_offset_s >= 0.0)
        {
            return Err(format!(
                "--asterix-max-clock-offset-s must be finite and ≥ 0 (0: no check), not {}",
                self.asterix_max_clock_offset_s
            ));
        }
        if self.asterix_recv_buffer_bytes > i32::MAX as usize {
            return Err(format!(
                "--asterix-recv-buffer-bytes must be at most {} (SO_RCVBUF is an int), not {}",
                i32::MAX,
                self.asterix_recv_buffer_bytes
            ));
        }
        if self.asterix_out_ttl > 255 {
            return Err(format!(
                "--asterix-out-ttl must be 0 to 255, not {}",
                self.asterix_out_ttl
            ));
        }
        self.validate_tls()?;
        let id = &self.asterix_session_id;
        if !(id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit())) {
            return Err(format!(
                "--asterix-session-id must be 32 hex digits, not {id:?}"
            ));
        }
        Ok(())
    }
}

impl Settings {
    /// The TLS options go together: a certificate and its key, or neither;
    /// client verification and its options only with TLS.
    fn validate_tls(&self) -> Result<(), String> {
        match (&self.tls_cert, &self.tls_key) {
            (Some(_), None) => {
                return Err("--tls-cert (FUSION_TLS_CERT) needs --tls-key (FUSION_TLS_KEY)".into());
            }
            (None, Some(_)) => {
                return Err("--tls-key (FUSION_TLS_KEY) needs --tls-cert (FUSION_TLS_CERT)".into());
            }
            _ => {}
        }
        let tls = self.tls_cert.is_some();
        if self.tls_client_ca.is_some() && !tls {
            return Err(
                "--tls-client-ca (FUSION_TLS_CLIENT_CA) needs --tls-cert and --tls-key".into(),
            );
        }
        if self.tls_client_auth.is_some() && self.tls_client_ca.is_none() {
            return Err(
                "--tls-client-auth (FUSION_TLS_CLIENT_AUTH) needs --tls-client-ca (FUSION_TLS_CLIENT_CA)"
                    .into(),
            );
        }
        if self.tls_client_tenants.is_some() && self.tls_client_ca.is_none() {
            return Err(
                "--tls-client-tenants (FUSION_TLS_CLIENT_TENANTS) needs --tls-client-ca (FUSION_TLS_CLIENT_CA)"
                    .into(),
            );
        }
        if self.tls_crl.is_some() && self.tls_client_ca.is_none() {
            return Err(
                "--tls-crl (FUSION_TLS_CRL) needs --tls-client-ca (FUSION_TLS_CLIENT_CA)".into(),
            );
        }
        if !(self.max_connection_age_s.is_finite()
            && (0.0..1e9).contains(&self.max_connection_age_s))
        {
            return Err(
                "--max-connection-age-s (FUSION_MAX_CONNECTION_AGE_S) must be a number of \
                 seconds, 0 (no limit) or more"
                    .into(),
            );
        }
        if !(self.tls_reload_s.is_finite() && (0.0..1e9).contains(&self.tls_reload_s)) {
            return Err("--tls-reload-s must be a number of seconds, 0 or more".into());
        }
        Ok(())
    }

    /// Whether both ports serve TLS.
    pub fn tls_enabled(&self) -> bool {
        self.tls_cert.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(args: &[&str]) -> Settings {
        let mut argv = vec!["radar-fusion"];
        argv.extend_from_slice(args);
        Cli::parse_from(argv).settings
    }

    #[test]
    fn session_store_defaults_and_settings() {
        let s = with(&[]);
        assert_eq!(s.validate(), Ok(()));
        let store = s.store_settings();
        assert_eq!(store.url, "memory");
        assert_eq!(store.key_prefix, "radar-fusion");
        assert_eq!(store.max_sessions_per_tenant, 100);
        assert_eq!(store.max_memory_bytes, 512 * 1024 * 1024);
        assert_eq!(store.max_memory_bytes_per_tenant, 128 * 1024 * 1024);
        assert_eq!(store.timeout, Duration::from_secs(1));
        let s = with(&[
            "--session-store",
            "redis://127.0.0.1:6379/0",
            "--store-timeout-s",
            "0.25",
        ]);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.store_settings().timeout, Duration::from_millis(250));
    }

    #[test]
    fn the_body_budget_is_256_mib_and_holds_a_body_at_the_limit() {
        let s = with(&[]);
        assert_eq!(s.max_buffered_body_bytes, 256 << 20);
        assert_eq!(s.h2_max_concurrent_streams, 100);
        let err = with(&[
            "--max-body-bytes",
            "4096",
            "--max-buffered-body-bytes",
            "4095",
        ])
        .validate()
        .unwrap_err();
        assert!(err.starts_with("--max-buffered-body-bytes"), "{err}");
        let err = with(&["--h2-max-concurrent-streams", "0"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--h2-max-concurrent-streams"), "{err}");
    }

    #[test]
    fn the_access_log_is_quiet_by_default() {
        assert_eq!(with(&[]).access_log, AccessLog::Debug);
        assert_eq!(with(&["--access-log", "info"]).access_log, AccessLog::Info);
        assert_eq!(with(&["--access-log", "off"]).access_log, AccessLog::Off);
    }

    #[test]
    fn tls_options_go_together() {
        assert_eq!(with(&[]).validate(), Ok(()));
        assert!(!with(&[]).tls_enabled());
        let ok = with(&[
            "--tls-cert",
            "c.pem",
            "--tls-key",
            "k.pem",
            "--tls-client-ca",
            "ca.pem",
        ]);
        assert_eq!(ok.validate(), Ok(()));
        assert!(ok.tls_enabled());
        assert_eq!(
            ok.tls_client_auth, None,
            "required is the default, decided by tls"
        );
        for (args, named) in [
            (
                &["--tls-cert", "c.pem"][..],
                "--tls-cert (FUSION_TLS_CERT) needs --tls-key",
            ),
            (
                &["--tls-key", "k.pem"],
                "--tls-key (FUSION_TLS_KEY) needs --tls-cert",
            ),
            (
                &["--tls-client-ca", "ca.pem"],
                "--tls-client-ca (FUSION_TLS_CLIENT_CA) needs",
            ),
            (
                &[
                    "--tls-cert",
                    "c",
                    "--tls-key",
                    "k",
                    "--tls-client-auth",
                    "optional",
                ],
                "--tls-client-auth (FUSION_TLS_CLIENT_AUTH) needs --tls-client-ca",
            ),
            (
                &[
                    "--tls-cert",
                    "c",
                    "--tls-key",
                    "k",
                    "--tls-client-tenants",
                    "t",
                ],
                "--tls-client-tenants (FUSION_TLS_CLIENT_TENANTS) needs --tls-client-ca",
            ),
            (&["--tls-reload-s=-1"], "--tls-reload-s"),
        ] {
            let err = with(args).validate().unwrap_err();
            assert!(err.starts_with(named), "{args:?}: {err}");
        }
    }

    #[test]
    fn a_bad_session_store_names_the_flag() {
        let err = with(&["--session-store", "postgres://x"])
            .validate()
            .unwrap_err();
        assert!(err.contains("--session-store"), "{err}");
        let err = with(&["--session-store", "redi://app:hunter2@h:1/0"])
            .validate()
            .unwrap_err();
        assert!(err.contains("--session-store"), "{err}");
        assert!(
            !err.contains("hunter2"),
            "the error shows the password: {err}"
        );
        let s = with(&[
            "--session-store",
            "rediss+sentinel://h:1/m",
            "--redis-ca",
            "/etc/redis/ca.pem",
            "--redis-password",
            "hunter2",
        ]);
        s.validate().unwrap();
        let store = s.store_settings();
        assert_eq!(store.redis.password.as_deref(), Some("hunter2"));
        assert!(!format!("{store:?}").contains("hunter2"));
        assert!(!format!("{s:?}").contains("hunter2"));
        let err = with(&["--store-timeout-s", "0"]).validate().unwrap_err();
        assert!(err.contains("--store-timeout-s"), "{err}");
        let err = with(&["--max-sessions-per-tenant", "0"])
            .validate()
            .unwrap_err();
        assert!(err.contains("--max-sessions-per-tenant"), "{err}");
    }

    #[test]
    fn the_asterix_allowlist_takes_addresses_and_prefixes_and_names_a_bad_one() {
        assert!(with(&[]).asterix_allow.is_empty());
        let s = with(&["--asterix-allow", "192.0.2.7,10.1.0.0/16"]);
        assert_eq!(s.asterix_allow, ["192.0.2.7", "10.1.0.0/16"]);
        assert!(s.validate().is_ok());
        let err = with(&["--asterix-allow", "10.1.0.0/33"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--asterix-allow"), "{err}");
    }

    #[test]
    fn the_asterix_clock_check_is_60_s_unless_set() {
        assert_eq!(with(&[]).asterix_max_clock_offset_s, 60.0);
        assert_eq!(
            with(&["--asterix-max-clock-offset-s", "0"]).asterix_max_clock_offset_s,
            0.0
        );
        let err = with(&["--asterix-max-clock-offset-s=-1"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--asterix-max-clock-offset-s"), "{err}");
    }

    #[test]
    fn a_snapshot_every_32_batches_unless_set() {
        assert_eq!(with(&[]).session_snapshot_batches, 32);
        with(&["--session-snapshot-batches", "1"])
            .validate()
            .unwrap();
        let err = with(&["--session-snapshot-batches", "0"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--session-snapshot-batches"), "{err}");
        assert_eq!(with(&[]).session_snapshot_replay_s, 0.5);
        with(&["--session-snapshot-replay-s", "0"])
            .validate()
            .unwrap();
        let err = with(&["--session-snapshot-replay-s=-1"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--session-snapshot-replay-s"), "{err}");
    }

    #[test]
    fn the_asterix_receive_buffer_is_4_mib_unless_set() {
        assert_eq!(with(&[]).asterix_recv_buffer_bytes, 4_194_304);
        let s = with(&["--asterix-recv-buffer-bytes", "0"]);
        assert_eq!(s.asterix_recv_buffer_bytes, 0);
        s.validate().unwrap();
        // 2³¹ does not fit SO_RCVBUF's int.
        let err = with(&["--asterix-recv-buffer-bytes", "2147483648"])
            .validate()
            .unwrap_err();
        assert!(err.starts_with("--asterix-recv-buffer-bytes"), "{err}");
    }
}
