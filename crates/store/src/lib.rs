//! The session store: where streaming correlation sessions keep their state
//! between requests. The state is an opaque, already encoded byte string; the
//! store versions it (optimistic concurrency by compare-and-set), expires it
//! after an idle time-to-live, bounds the number of sessions per tenant and
//! keeps tenants apart. Two backends behind one enum: `memory` (one process)
//! and `redis` (shared by replicas, survives restarts of the service).

pub mod access;
pub mod cluster;
pub mod copy;
pub mod events;
pub mod memory;
pub mod redis;
pub mod sentinel;

use std::time::Duration;

/// A session store; every method is the same for both backends.
// One store per process, behind an `Arc`: the variants' sizes do not matter.
#[allow(clippy::large_enum_variant)]
pub enum SessionStore {
    Memory(memory::MemoryStore),
    Redis(redis::RedisStore),
}

/// How to build a [`SessionStore`] (from `config::Settings::store_settings`).
#[derive(Debug, Clone)]
pub struct StoreSettings {
    /// `memory`, `redis://host:port/db` (`rediss://` for TLS),
    /// `redis+sentinel://…` (`rediss+sentinel://`) or `redis+cluster://…`
    /// (`rediss+cluster://`).
    pub url: String,
    /// Redis: TLS files and the password (see [`access`]).
    pub redis: access::RedisAccessSettings,
    /// Redis (one server or Sentinel): replicas that must acknowledge each
    /// write (`WAIT`) before it is reported done; 0: none (asynchronous
    /// replication, a write acknowledged just before a failover can be lost).
    pub wait_replicas: usize,
    /// Prefix of every Redis key (`{prefix}:{tenant}:…`).
    pub key_prefix: String,
    /// Most live sessions one tenant may hold.
    pub max_sessions_per_tenant: usize,
    /// Memory backend: bound on the total bytes of session data held.
    pub max_memory_bytes: usize,
    /// Memory backend: bound on the bytes of session data one tenant holds.
    pub max_memory_bytes_per_tenant: usize,
    /// Redis backend: longest time one command may take before `Unavailable`.
    pub timeout: Duration,
}

/// Where a Redis store sends its commands, for health and metrics.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Topology {
    /// The server in use, `host:port` (never credentials); a Cluster's seed
    /// nodes; `None` behind Sentinel while no primary is known (before the
    /// first answer, or after one was dropped and before the sentinels name
    /// the next).
    pub primary: Option<String>,
    /// Sentinel: the primary was dropped after a failed command and no
    /// command has succeeded since.
    pub failing_over: bool,
    /// Sentinel: changes of primary followed.
    pub failovers: u64,
    /// Sentinel: times the primary was dropped after a failure and the
    /// sentinels asked again.
    pub redirections: u64,
}

/// A session's state as stored: a snapshot and the log of the writes
/// appended since it ([`Write::Append`]), so that a write costs what it
/// carries rather than the whole state.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stored {
    pub version: u64,
    /// The token of the write that made `version` (0: created and not
    /// written since, or written by a release before tokens).
    pub token: u64,
    /// The snapshot: the state at version `version - log.len()`.
    pub data: Vec<u8>,
    /// The entries appended since the snapshot, oldest first: entry `i`
    /// made version `version - log.len() + i + 1`.
    pub log: Vec<Vec<u8>>,
}

impl Stored {
    /// Bytes held: the snapshot and the log.
    pub fn bytes(&self) -> usize {
        self.data.len() + self.log_bytes()
    }

    /// Bytes of the log.
    pub fn log_bytes(&self) -> usize {
        self.log.iter().map(Vec::len).sum()
    }
}

/// What a [`SessionStore::write`] stores.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Write {
    /// A new snapshot: the whole state at the new version; the log is
    /// dropped (compaction).
    Snapshot(Vec<u8>),
    /// An entry appended to the log (the change from the expected version
    /// to the new one).
    Append(Vec<u8>),
}

impl Write {
    /// Bytes written.
    pub fn len(&self) -> usize {
        match self {
            Self::Snapshot(d) | Self::Append(d) => d.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// What a [`SessionStore::write`] expects to find: the version and,
/// unless `None`, the token of the write that made it. The token tells
/// apart two different writes that made the same version number (a
/// replica that read version 5 before a failover lost it, and another
/// that wrote a new version 5 after): a log entry appended to the wrong
/// one would corrupt the session.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expected {
    pub version: u64,
    pub token: Option<u64>,
}

/// One live session of a tenant, as listed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SessionMeta {
    pub id: String,
    pub version: u64,
    /// The session's kind, as given at creation (`correlation` for a session
    /// created before kinds existed).
    pub kind: String,
    pub bytes: usize,
    pub ttl_remaining: Duration,
}

/// The result of [`SessionStore::compact`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Compacted {
    /// The snapshot replaced the snapshot and the log entries up to its
    /// version; the entries after it are kept.
    Stored,
    /// Not written: the session's log no longer holds the version the
    /// snapshot is of, made by that write (a newer snapshot landed, or the
    /// version was lost in a failover and made again by another write).
    /// Nothing is lost: the log still holds every write.
    Stale,
    /// Not written: no such live session.
    Missing,
}

/// The result of [`SessionStore::compare_and_set`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CasOutcome {
    /// Written; the session now has this version.
    Stored { version: u64 },
    /// Not written: the session has another version than expected.
    Conflict { current: u64 },
    /// Not written: no such live session.
    Missing,
}

#[derive(thiserror::Error, Debug, Clone, PartialEq, Eq)]
pub enum StoreError {
    /// The backend cannot be reached or did not answer in time.
    #[error("session store unavailable: {reason}")]
    Unavailable { reason: String },
    /// The tenant already holds the most live sessions allowed.
    #[error("too many sessions: at most {limit} per tenant")]
    TooManySessions { limit: usize },
    /// The memory backend holds as many bytes as allowed.
    #[error("session store full: at most {limit_bytes} bytes of session data")]
    MemoryFull { limit_bytes: usize },
    /// The memory backend holds as many bytes of this tenant's sessions as
    /// one tenant may hold.
    #[error("the tenant's session data is at its bound of {limit_bytes} bytes")]
    TenantMemoryFull { limit_bytes: usize },
    /// `create` of an id that is live already.
    #[error("a session with this id exists already")]
    AlreadyExists,
    /// A setting is wrong (refuse to start): named, never with a secret.
    #[error("{setting}: {reason}")]
    Config {
        setting: &'static str,
        reason: String,
    },
    /// The backend holds something that is not a session as this store writes it.
    #[error("corrupt session record: {reason}")]
    Corrupt { reason: String },
}

impl SessionStore {
    /// Builds the store `settings.url` names. Redis is connected lazily, so
    /// this succeeds while Redis is down; calls then fail with `Unavailable`
    /// until it is back, and the connection recovers by itself. A Redis that
    /// answers is checked once: a failed TLS handshake or rejected
    /// credentials are `Config` errors (refuse to start), as are bad URLs
    /// and TLS files.
    pub async fn connect(settings: &StoreSettings) -> Result<Self, StoreError> {
        if settings.url == "memory" {
            Ok(Self::Memory(memory::MemoryStore::new(settings)))
        } else {
            redis::RedisStore::connect(settings).await.map(Self::Redis)
        }
    }

    /// `memory` or `redis`.
    pub fn backend(&self) -> &'static str {
        match self {
            Self::Memory(_) => "memory",
            Self::Redis(_) => "redis",
        }
    }

    /// Creates a session of `kind` (a label the store keeps for listing) at
    /// version 1 that expires after `ttl` unless updated.
    /// `AlreadyExists` when the id is live; `TooManySessions` when the tenant
    /// holds `max_sessions_per_tenant` live sessions (checked atomically).
    pub async fn create(
        &self,
        tenant: &str,
        id: &str,
        kind: &str,
        data: Vec<u8>,
        ttl: Duration,
    ) -> Result<u64, StoreError> {
        match self {
            Self::Memory(s) => s.create(tenant, id, kind, data, ttl),
            Self::Redis(s) => s.create(tenant, id, kind, data, ttl).await,
        }
    }

    /// The live session `id` of `tenant`, or `None` (unknown, expired, or
    /// another tenant's).
    pub async fn get(&self, tenant: &str, id: &str) -> Result<Option<Stored>, StoreError> {
        match self {
            Self::Memory(s) => Ok(s.get(tenant, id)),
            Self::Redis(s) => s.get(tenant, id).await,
        }
    }

    /// Atomically replaces the data (a snapshot, the log dropped) when the
    /// session's version is `expected_version`, whatever its token; the new
    /// version is `expected_version + 1` and the time-to-live restarts at
    /// `ttl` (idle expiry). [`SessionStore::write`] with a snapshot.
    pub async fn compare_and_set(
        &self,
        tenant: &str,
        id: &str,
        expected_version: u64,
        data: Vec<u8>,
        ttl: Duration,
    ) -> Result<CasOutcome, StoreError> {
        let expected = Expected {
            version: expected_version,
            token: None,
        };
        let token = rand::random::<u64>() | 1;
        self.write(tenant, id, expected, token, Write::Snapshot(data), ttl)
            .await
    }

    /// Atomically writes when the session is at `expected` (its version,
    /// and its token unless that is `None`): a snapshot or a log entry, the
    /// new version `expected.version + 1` made by `token` (never 0). The
    /// time-to-live restarts at `ttl`. Another version or token is a
    /// `Conflict`.
    pub async fn write(
        &self,
        tenant: &str,
        id: &str,
        expected: Expected,
        token: u64,
        write: Write,
        ttl: Duration,
    ) -> Result<CasOutcome, StoreError> {
        match self {
            Self::Memory(s) => s.write(tenant, id, expected, token, write, ttl),
            Self::Redis(s) => s.write(tenant, id, expected, token, write, ttl).await,
        }
    }

    /// Replaces the snapshot and the log entries up to `at.version` by
    /// `data`, the state at that version, when the log holds that version
    /// as made by the write with token `at.token` (required); the entries
    /// after it stay, so the session's version, token and time-to-live are
    /// unchanged and a reader finds a snapshot and a contiguous log before
    /// and after (the change is atomic). This is how a snapshot encoded off
    /// the request path lands while later batches are appended: a
    /// compaction, never a write of a new version. `Stale` when the log no
    /// longer holds that version made by that token.
    pub async fn compact(
        &self,
        tenant: &str,
        id: &str,
        at: Expected,
        data: Vec<u8>,
    ) -> Result<Compacted, StoreError> {
        let Some(token) = at.token else {
            return Ok(Compacted::Stale);
        };
        match self {
            Self::Memory(s) => s.compact(tenant, id, at.version, token, data),
            Self::Redis(s) => s.compact(tenant, id, at.version, token, data).await,
        }
    }

    /// Waits until the writes the session has had are replicated as every
    /// write is (`wait_replicas`): for an answer given without a write (a
    /// duplicate batch), whose original write may not have reached the
    /// replicas yet. Restarts the idle TTL at `ttl`. `Unavailable` when the
    /// replicas do not acknowledge in time.
    pub async fn replicated(
        &self,
        tenant: &str,
        id: &str,
        ttl: Duration,
    ) -> Result<(), StoreError> {
        match self {
            Self::Memory(_) => Ok(()),
            Self::Redis(s) => s.touch_replicated(tenant, id, ttl).await,
        }
    }

    /// Deletes the session; `false` when there was no live session to delete.
    pub async fn delete(&self, tenant: &str, id: &str) -> Result<bool, StoreError> {
        match self {
            Self::Memory(s) => Ok(s.delete(tenant, id)),
            Self::Redis(s) => s.delete(tenant, id).await,
        }
    }

    /// The tenant's live sessions, sorted by id.
    pub async fn list(&self, tenant: &str) -> Result<Vec<SessionMeta>, StoreError> {
        match self {
            Self::Memory(s) => Ok(s.list(tenant)),
            Self::Redis(s) => s.list(tenant).await,
        }
    }

    /// The version of the live session `id` of `tenant`, without its data
    /// (`None`: unknown, expired, or another tenant's).
    pub async fn version(&self, tenant: &str, id: &str) -> Result<Option<u64>, StoreError> {
        match self {
            Self::Memory(s) => Ok(s.version(tenant, id)),
            Self::Redis(s) => s.version(tenant, id).await,
        }
    }

    /// Publishes a session event to every replica's listener (Redis); the
    /// memory store has one process and no listener: `Ok(false)`, the caller
    /// delivers it itself.
    pub async fn publish(
        &self,
        tenant: &str,
        id: &str,
        payload: &[u8],
    ) -> Result<bool, StoreError> {
        match self {
            Self::Memory(_) => Ok(false),
            Self::Redis(s) => s.publish(tenant, id, payload).await.map(|()| true),
        }
    }

    /// The Redis store's event listener and its feed (`None` for memory).
    pub fn listen(
        &self,
        capacity: usize,
    ) -> Option<(
        events::EventListener,
        tokio::sync::mpsc::Receiver<events::Feed>,
    )> {
        match self {
            Self::Memory(_) => None,
            Self::Redis(s) => s.listen(capacity),
        }
    }

    /// The pub/sub channel of a session's events (Redis; for subscribing).
    pub fn channel(&self, tenant: &str, id: &str) -> Option<String> {
        match self {
            Self::Memory(_) => None,
            Self::Redis(s) => Some(s.channel(tenant, id)),
        }
    }

    /// The Redis store's server and failover state (`None` for memory).
    pub fn topology(&self) -> Option<Topology> {
        match self {
            Self::Memory(_) => None,
            Self::Redis(s) => Some(s.topology()),
        }
    }

    /// Copies every session of this Redis store into `to` (a single Redis or
    /// Sentinel into a Cluster, or back; see [`copy`]).
    pub async fn copy_sessions_to(&self, to: &SessionStore) -> Result<copy::Copied, StoreError> {
        match (self, to) {
            (Self::Redis(from), Self::Redis(to)) => copy::copy(from, to).await,
            _ => Err(access::config(
                access::STORE,
                "a copy of sessions is from one Redis store to another".into(),
            )),
        }
    }

    /// Whether the backend answers (readiness); the memory store always does.
    pub async fn ping(&self) -> Result<(), StoreError> {
        match self {
            Self::Memory(_) => Ok(()),
            Self::Redis(s) => s.ping().await,
        }
    }
}

/// A time-to-live as whole milliseconds, at least 1 (Redis rejects 0).
pub(crate) fn ttl_ms(ttl: Duration) -> u64 {
    u64::try_from(ttl.as_millis()).unwrap_or(u64::MAX).max(1)
}
