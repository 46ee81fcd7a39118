//! Sessions over the store: create, read, list, delete and push a batch, for
//! every kind. Every write is a compare-and-set on the session's version,
//! retried on conflict from a fresh read, so two replicas pushing to one
//! session never lose or double an update; a batch whose sequence number was
//! applied already is acknowledged without being applied again. A push works
//! on a decoded copy of the session (from the [`SessionCache`] when this
//! replica wrote the version the store holds, else from the stored bytes): a
//! failed request leaves the stored session as it was, and the batch itself
//! is only borrowed, never copied, however many attempts it takes.

use std::{
    collections::{BTreeMap, VecDeque},
    sync::{
        Arc, Mutex,
        atomic::{AtomicUsize, Ordering},
    },
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use tokio::sync::{broadcast, watch};

use super::{
    Admission, Batch, DecodeError, Envelope, Limits, SessionKind, Spec, Update, View,
    cache::SessionCache,
    events::{
        self, EndReason, EventHub, GAP_WAIT, Guard, HubItem, SessionEvent, WatchItem, WatchLimits,
    },
    gauges::RadarGauges,
    registry::{AnyView, EventBody, KindName, KindVisitor, Registered, tag_name},
    stored_kind,
};
use crate::{ServiceError, offload};
use store::{
    CasOutcome, Compacted, Expected, SessionMeta, SessionStore, StoreError, Stored, Write,
};

/// How many times a push re-reads the session after losing a race.
const MAX_ATTEMPTS: usize = 32;

/// The session store and the cache of decoded sessions in front of it.
pub struct Sessions {
    store: Arc<SessionStore>,
    cache: SessionCache,
    events: Arc<EventHub>,
    gauges: RadarGauges,
    snapshots: SnapshotPolicy,
    background: Arc<InFlight>,
    #[cfg(test)]
    faults: Arc<tests::Faults>,
}

/// Background snapshots in flight.
#[derive(Default)]
struct InFlight {
    running: AtomicUsize,
    done: tokio::sync::Notify,
}

/// One background snapshot in flight, until dropped.
struct InFlightGuard(Arc<InFlight>);

impl InFlight {
    fn enter(self: &Arc<Self>) -> InFlightGuard {
        self.running.fetch_add(1, Ordering::SeqCst);
        InFlightGuard(Arc::clone(self))
    }

    async fn settled(&self) {
        loop {
            let done = self.done.notified();
            tokio::pin!(done);
            done.as_mut().enable();
            if self.running.load(Ordering::SeqCst) == 0 {
                return;
            }
            done.await;
        }
    }
}

impl Drop for InFlightGuard {
    fn drop(&mut self) {
        if self.0.running.fetch_sub(1, Ordering::SeqCst) == 1 {
            self.0.done.notify_waiters();
        }
    }
}

/// When a push also stores the whole session (a snapshot): a session is
/// stored as a snapshot and the batches applied since, so a write costs
/// what the batch carries, and a replica that reads the session replays
/// the log. A batch's entry is always written inline; a snapshot that
/// falls due is encoded from a copy of the state and written off the
/// request path, in place of the entries up to its version
/// ([`SessionStore::compact`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SnapshotPolicy {
    /// Most log entries after a snapshot (`--session-snapshot-batches`);
    /// 1: a snapshot after every batch. A snapshot is also due once the
    /// log holds as many bytes as the snapshot.
    pub max_entries: usize,
    /// A snapshot is also due once replaying the log would take this long
    /// (s; the time this replica took to apply its batches)
    /// (`--session-snapshot-replay-s`), so that a replica taking the
    /// session over replays about this much at most; 0: no such bound...
    pub max_replay_s: f64,
    /// ...but a snapshot due by replay time waits until the log holds at
    /// least the snapshot's bytes divided by this, so that snapshots add
    /// at most this many times the log's own bytes to what is written.
    pub max_write_amplification: f64,
}

impl Default for SnapshotPolicy {
    fn default() -> Self {
        Self {
            max_entries: DEFAULT_SNAPSHOT_BATCHES,
            max_replay_s: DEFAULT_SNAPSHOT_REPLAY_S,
            max_write_amplification: DEFAULT_SNAPSHOT_AMPLIFICATION,
        }
    }
}

/// Default [`SnapshotPolicy::max_entries`]: at 4,000 aircraft under four
/// radars in 1-s batches (a 6–12 MB snapshot, 0.25 MB of plots a batch)
/// the bytes bound (the log as large as the snapshot) acts first.
pub const DEFAULT_SNAPSHOT_BATCHES: usize = 32;

/// Default [`SnapshotPolicy::max_replay_s`]: with the fetch and decode of
/// the snapshot, a takeover within about a second.
pub const DEFAULT_SNAPSHOT_REPLAY_S: f64 = 0.5;

/// Default [`SnapshotPolicy::max_write_amplification`]: snapshots due by
/// replay time add at most three times the log's bytes (at 4,000 aircraft,
/// 0.25 MB of plots a batch: at most 1 MB written a batch on average).
pub const DEFAULT_SNAPSHOT_AMPLIFICATION: f64 = 3.0;

/// The shape of a session as stored: its snapshot's bytes and the log after
/// it, with what replaying the log costs, and the snapshot being written
/// off the request path, if any.
#[derive(Debug, Clone, Default)]
struct LogShape {
    snapshot_bytes: usize,
    entries: usize,
    log_bytes: usize,
    /// Seconds this replica took to apply the log's batches.
    replay_s: f64,
    /// A snapshot encoded and written in the background.
    pending: Option<Pending>,
}

/// A snapshot on its way to the store: the log as it was at its version
/// (what it replaces when it lands) and where its outcome arrives.
#[derive(Debug, Clone)]
struct Pending {
    entries: usize,
    log_bytes: usize,
    replay_s: f64,
    landing: Arc<Mutex<Landing>>,
}

/// The outcome of a background snapshot.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Landing {
    Writing,
    /// In the store, `bytes` long, in place of the log up to its version.
    Landed {
        bytes: usize,
    },
    /// Not written (an error, or the log no longer holds its version):
    /// the log still holds every batch; the next batch may try again.
    Failed,
}

impl LogShape {
    fn of(stored: &Stored) -> Self {
        Self {
            snapshot_bytes: stored.data.len(),
            entries: stored.log.len(),
            log_bytes: stored.log_bytes(),
            replay_s: 0.0,
            pending: None,
        }
    }

    fn bytes(&self) -> usize {
        self.snapshot_bytes + self.log_bytes
    }

    /// Takes in the outcome of a background snapshot that has one.
    fn settle(&mut self) {
        let Some(p) = &self.pending else { return };
        let landing = *p.landing.lock().unwrap_or_else(|e| e.into_inner());
        match landing {
            Landing::Writing => {}
            Landing::Landed { bytes } => {
                self.snapshot_bytes = bytes;
                self.entries -= p.entries;
                self.log_bytes -= p.log_bytes;
                self.replay_s = (self.replay_s - p.replay_s).max(0.0);
                self.pending = None;
            }
            Landing::Failed => self.pending = None,
        }
    }

    /// Whether a snapshot is due after the log has grown (none being
    /// written already).
    fn snapshot_due(&self, policy: SnapshotPolicy) -> bool {
        if self.pending.is_some() || self.entries == 0 {
            return false;
        }
        let by_replay = policy.max_replay_s > 0.0
            && self.replay_s >= policy.max_replay_s
            && self.log_bytes as f64 * policy.max_write_amplification.max(0.0)
                >= self.snapshot_bytes as f64;
        self.entries >= policy.max_entries.max(1)
            || self.log_bytes >= self.snapshot_bytes
            || by_replay
    }

    /// Counts a write made inline.
    fn wrote(&mut self, write: &Write, replay_s: f64) {
        match write {
            Write::Snapshot(d) => {
                *self = Self {
                    snapshot_bytes: d.len(),
                    ..Self::default()
                }
            }
            Write::Append(e) => {
                self.entries += 1;
                self.log_bytes += e.len();
                self.replay_s += replay_s;
            }
        }
    }

    /// Marks a background snapshot of the session as it is now (the log
    /// as it is now is what it replaces).
    fn snapshot_now(&mut self) -> Arc<Mutex<Landing>> {
        let landing = Arc::new(Mutex::new(Landing::Writing));
        self.pending = Some(Pending {
            entries: self.entries,
            log_bytes: self.log_bytes,
            replay_s: self.replay_s,
            landing: Arc::clone(&landing),
        });
        landing
    }
}

/// A decoded session as this replica holds it between batches: the state,
/// the token of the write that made its version, and how it is stored.
struct Hot<K: SessionKind> {
    session: Envelope<K>,
    token: u64,
    shape: LogShape,
}

impl<K: SessionKind> Hot<K> {
    /// The stored session, decoded: its snapshot, then every log entry
    /// applied again (exactly the state of the replica that wrote them).
    fn read(id: &str, stored: &Stored) -> Result<Self, DecodeError> {
        let started = Instant::now();
        let mut session = Envelope::<K>::decode(&stored.data)?;
        let decoded = started.elapsed();
        for (i, entry) in stored.log.iter().enumerate() {
            session.replay(id, entry, i + 1 == stored.log.len())?;
        }
        let replayed = started.elapsed() - decoded;
        metrics::histogram!("fusion_session_read_seconds", "step" => "decode")
            .record(decoded.as_secs_f64());
        if !stored.log.is_empty() {
            metrics::counter!("fusion_session_replayed_batches_total")
                .increment(stored.log.len() as u64);
            metrics::histogram!("fusion_session_read_seconds", "step" => "replay")
                .record(replayed.as_secs_f64());
        }
        tracing::debug!(
            session = id,
            snapshot_bytes = stored.data.len(),
            entries = stored.log.len(),
            decode_ms = decoded.as_secs_f64() * 1e3,
            replay_ms = replayed.as_secs_f64() * 1e3,
            "read a stored session"
        );
        let mut shape = LogShape::of(stored);
        shape.replay_s = replayed.as_secs_f64();
        Ok(Self {
            session,
            token: stored.token,
            shape,
        })
    }
}

/// A fresh write token: random, never 0 (the token of a session no write
/// has touched since its creation).
fn new_token() -> u64 {
    rand::random::<u64>() | 1
}

impl From<StoreError> for ServiceError {
    fn from(e: StoreError) -> Self {
        match e {
            StoreError::Unavailable { reason } => ServiceError::Unavailable(format!(
                "the session store is unreachable ({reason}); retry shortly"
            )),
            StoreError::TooManySessions { limit } => ServiceError::QuotaExceeded(format!(
                "the tenant holds {limit} sessions, the most allowed: delete one or let one expire"
            )),
            StoreError::MemoryFull { limit_bytes } => ServiceError::QuotaExceeded(format!(
                "the session store's memory ({limit_bytes} bytes) is full"
            )),
            StoreError::TenantMemoryFull { limit_bytes } => ServiceError::QuotaExceeded(format!(
                "this write would take the tenant's sessions over {limit_bytes} bytes, the most \
                 one tenant may hold in the session store's memory \
                 (FUSION_SESSION_MEMORY_BYTES_PER_TENANT): delete a session or let one expire"
            )),
            StoreError::AlreadyExists => {
                ServiceError::Internal("a fresh random session id collided".into())
            }
            StoreError::Corrupt { reason } => {
                ServiceError::Internal(format!("stored session: {reason}"))
            }
            // Refused at start; met later only if the server's certificate or
            // credentials change under a running service.
            StoreError::Config { setting, .. } => ServiceError::Unavailable(format!(
                "the session store refuses this service's {setting}; retry shortly"
            )),
        }
    }
}

fn unix_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// A random, unguessable session id: 128 bits from the thread's
/// cryptographically secure generator, in hex.
fn new_id() -> String {
    format!("{:032x}", rand::random::<u128>())
}

fn ttl<K: SessionKind>(s: &Envelope<K>) -> Duration {
    Duration::from_secs_f64(s.idle_expiry_s)
}

/// Ids are 32 hex digits: anything else cannot name a session (404, and
/// nothing odd reaches the store's keys).
fn check_id(id: &str) -> Result<(), ServiceError> {
    if id.len() == 32 && id.bytes().all(|b| b.is_ascii_hexdigit()) {
        Ok(())
    } else {
        Err(not_found(id))
    }
}

fn not_found(id: &str) -> ServiceError {
    ServiceError::NotFound(format!("no session '{}'", crate::validate::quoted(id)))
}

/// Where a push's decoded session comes from.
enum Source<K: SessionKind> {
    /// The cache: trusted only if the compare-and-set on its version and
    /// token succeeds.
    Cache(Hot<K>),
    /// A fresh read of the store, decoded off the async workers.
    Store(Stored),
}

/// A write (or the wait for its replicas) that the store did not confirm:
/// it may still land (a slow Redis applies it later), so it is never
/// reported as "nothing changed".
fn unconfirmed(e: StoreError) -> ServiceError {
    match e {
        StoreError::Unavailable { reason } => ServiceError::Unavailable(format!(
            "the session store did not confirm the write ({reason}): the batch may or may \
             not have been applied; retry it unchanged, with the same sequence number if it \
             had one (a batch applied already is acknowledged as a duplicate)"
        )),
        other => other.into(),
    }
}

impl Sessions {
    /// Sessions over `store`, caching decoded sessions of up to
    /// `cache_bytes` encoded bytes in total (0: no cache).
    pub fn new(store: SessionStore, cache_bytes: usize) -> Self {
        Self::with_watch_limits(store, cache_bytes, WatchLimits::default())
    }

    /// As [`Sessions::new`], with the bounds on watchers. With the Redis
    /// store this starts the event listener: call it inside the runtime.
    pub fn with_watch_limits(store: SessionStore, cache_bytes: usize, limits: WatchLimits) -> Self {
        let events = EventHub::new(&store, limits);
        Self {
            store: Arc::new(store),
            cache: SessionCache::new(cache_bytes),
            events,
            gauges: RadarGauges::default(),
            snapshots: SnapshotPolicy::default(),
            background: Arc::default(),
            #[cfg(test)]
            faults: Arc::default(),
        }
    }

    /// With another [`SnapshotPolicy`] than the default.
    pub fn with_snapshots(mut self, snapshots: SnapshotPolicy) -> Self {
        self.snapshots = snapshots;
        self
    }

    /// This replica's watchers' side of session events.
    pub fn events(&self) -> &EventHub {
        &self.events
    }

    pub fn store(&self) -> &SessionStore {
        &self.store
    }

    /// The per-session gauges `/metrics` shows after the recorder's.
    pub fn gauges(&self) -> &RadarGauges {
        &self.gauges
    }

    pub fn cache(&self) -> &SessionCache {
        &self.cache
    }

    /// Creates a session of kind `K`.
    pub async fn create<K: SessionKind>(
        &self,
        tenant: &str,
        spec: Spec<K::Spec>,
    ) -> Result<View<K::View>, ServiceError> {
        self.create_with_id::<K>(tenant, &new_id(), spec).await
    }

    /// A new session under a chosen id (32 hex digits; the ASTERIX UDP
    /// listener's configured session). An id in use is a `Conflict`.
    pub async fn create_with_id<K: SessionKind>(
        &self,
        tenant: &str,
        id: &str,
        spec: Spec<K::Spec>,
    ) -> Result<View<K::View>, ServiceError> {
        check_id(id)?;
        let mut warnings = Vec::new();
        let session = Envelope::<K>::create(spec, unix_ms(), &mut warnings)?;
        let data = session.encode();
        let id = id.to_string();
        let bytes = data.len();
        let version = self
            .store
            .create(tenant, &id, K::NAME, data, ttl(&session))
            .await
            .map_err(|e| match e {
                StoreError::AlreadyExists => {
                    ServiceError::Conflict(format!("session '{id}' exists already"))
                }
                other => other.into(),
            })?;
        let view = session.view(&id, version, bytes).map(|mut v| {
            v.warnings = warnings;
            v
        });
        let hot = Hot {
            session,
            token: 0,
            shape: LogShape {
                snapshot_bytes: bytes,
                ..LogShape::default()
            },
        };
        self.cache.put(tenant, &id, version, bytes, hot);
        view
    }

    /// A session of any kind.
    ///
    /// The decoded session is kept in the cache (as a push keeps it): a
    /// replica that attaches a stream to a session another replica served
    /// reads and replays it once, not again for the first batch.
    ///
    /// The store is read for the version and token; a session this replica
    /// holds decoded at that version, made by the same write, answers
    /// without decoding and replaying the stored bytes (the state is the
    /// same: `a_replica_that_replays_the_log_holds_the_serving_replicas_state`).
    pub async fn get(&self, tenant: &str, id: &str) -> Result<AnyView, ServiceError> {
        let stored = self.read(tenant, id).await?;
        let kind = served_kind(&stored)?;
        kind.visit(ViewKept {
            sessions: self,
            tenant,
            id,
            stored,
        })
        .await
    }

    /// The view of `stored` (a session of kind `K`), from the cached copy
    /// when it holds the same write ([`view_from`]); the copy, or the one
    /// read from the bytes, kept in the cache.
    async fn view_kept<K: SessionKind>(
        &self,
        tenant: &str,
        id: &str,
        stored: Stored,
    ) -> Result<View<K::View>, ServiceError> {
        let (version, bytes) = (stored.version, stored.bytes());
        let cached = self.cache.take_at::<Hot<K>>(tenant, id, version);
        let id2 = id.to_string();
        let (view, hot) = offload(move || view_from::<K>(&id2, &stored, cached)).await?;
        self.cache.put(tenant, id, version, bytes, hot);
        Ok(view)
    }

    /// A session known to be of kind `K`; another kind is an error naming it.
    pub async fn get_as<K: SessionKind>(
        &self,
        tenant: &str,
        id: &str,
    ) -> Result<View<K::View>, ServiceError> {
        let stored = self.read(tenant, id).await?;
        let id = id.to_string();
        offload(move || view_of::<K>(&id, &stored)).await
    }

    /// The kind of session `id` (from the store's bytes; for a batch whose
    /// items do not say it).
    pub async fn kind_of(&self, tenant: &str, id: &str) -> Result<KindName, ServiceError> {
        served_kind(&self.read(tenant, id).await?)
    }

    /// The stored session `id`, or 404.
    async fn read(&self, tenant: &str, id: &str) -> Result<Stored, ServiceError> {
        check_id(id)?;
        let started = Instant::now();
        let stored = self.store.get(tenant, id).await?;
        metrics::histogram!("fusion_session_read_seconds", "step" => "fetch")
            .record(started.elapsed().as_secs_f64());
        stored.ok_or_else(|| not_found(id))
    }

    pub async fn list(&self, tenant: &str) -> Result<Vec<SessionMeta>, ServiceError> {
        Ok(self.store.list(tenant).await?)
    }

    pub async fn delete(&self, tenant: &str, id: &str) -> Result<(), ServiceError> {
        check_id(id)?;
        self.cache.forget(tenant, id);
        self.gauges.forget(tenant, id);
        if self.store.delete(tenant, id).await? {
            if self.announces(tenant, id) {
                self.publish(tenant, id, events::encode_deleted(tenant, id))
                    .await;
            }
            Ok(())
        } else {
            Err(not_found(id))
        }
    }

    /// Applies one batch to a session of kind `K` with compare-and-set,
    /// retrying on a lost race. A session of another kind is a violation of
    /// the kind's batch field.
    pub async fn push<K: SessionKind>(
        &self,
        tenant: &str,
        id: &str,
        batch: Batch<K::Batch>,
        limits: Limits,
    ) -> Result<Update<K::Update>, ServiceError> {
        check_id(id)?;
        K::check_size(&batch.body, &limits)?;
        let batch = Arc::new(batch);
        let policy = self.snapshots;
        let mut attempt = 0;
        while attempt < MAX_ATTEMPTS {
            let (version, source) = match self.cache.take::<Hot<K>>(tenant, id) {
                Some((version, hot)) => {
                    metrics::counter!("fusion_session_cache_total", "outcome" => "hit")
                        .increment(1);
                    (version, Source::Cache(hot))
                }
                None => {
                    metrics::counter!("fusion_session_cache_total", "outcome" => "miss")
                        .increment(1);
                    let stored = self.read(tenant, id).await?;
                    (stored.version, Source::Store(stored))
                }
            };
            let (batch2, id2) = (Arc::clone(&batch), id.to_string());
            let from_cache = matches!(source, Source::Cache(_));
            let worked = offload(move || {
                let mut hot = match source {
                    Source::Cache(hot) => hot,
                    Source::Store(stored) => {
                        Hot::<K>::read(&id2, &stored).map_err(|e| e.for_request::<K>(&id2))?
                    }
                };
                let fingerprint = K::fingerprint(&batch2.body);
                match hot
                    .session
                    .admit(&id2, batch2.sequence, fingerprint, version)?
                {
                    Admission::Duplicate(ack) => Ok(Err((ack, hot))),
                    Admission::Apply => {
                        let started = Instant::now();
                        let update = hot.session.apply(&id2, &batch2, &limits)?;
                        let cost = started.elapsed().as_secs_f64();
                        let marks = hot.session.state.take_marks();
                        hot.shape.settle();
                        // The batch's entry inline; a snapshot that falls
                        // due after it is encoded from a copy and written
                        // in the background, once the entry is stored. A
                        // kind without entries or copies stores snapshots
                        // inline, as before the log.
                        let entry = Envelope::<K>::encode_entry(&batch2, &limits);
                        let (write, copy) = match entry {
                            Some(entry) => {
                                let mut after = hot.shape.clone();
                                after.wrote(&Write::Append(Vec::new()), cost);
                                after.log_bytes += entry.len();
                                if after.snapshot_due(policy) {
                                    match hot.session.stored_copy() {
                                        Some(copy) => (Write::Append(entry), Some(copy)),
                                        None => (Write::Snapshot(hot.session.encode()), None),
                                    }
                                } else {
                                    (Write::Append(entry), None)
                                }
                            }
                            None => (Write::Snapshot(hot.session.encode()), None),
                        };
                        Ok(Ok((update, write, hot, marks, copy, cost)))
                    }
                }
            })
            .await;
            let (mut update, write, mut hot, marks, copy, cost) = match worked {
                // A cached copy may be behind the store: only a successful
                // compare-and-set proves it current, so anything else it
                // says (a duplicate, a gap, an error) is asked again of a
                // fresh read. It was taken out of the cache, so the next
                // attempt reads the store.
                _ if from_cache && !matches!(worked, Ok(Ok(_))) => {
                    metrics::counter!("fusion_session_cache_total", "outcome" => "unconfirmed")
                        .increment(1);
                    attempt += 1;
                    continue;
                }
                Err(e) => return Err(e),
                Ok(Err((duplicate, hot))) => {
                    // The original write may not have reached the replicas
                    // yet (its answer was lost, perhaps in a failover): the
                    // acknowledgement waits for them as a write does.
                    self.store
                        .replicated(tenant, id, ttl(&hot.session))
                        .await
                        .map_err(unconfirmed)?;
                    let bytes = hot.shape.bytes();
                    self.cache.put(tenant, id, version, bytes, hot);
                    return Ok(duplicate);
                }
                Ok(Ok(applied)) => applied,
            };
            attempt += 1;
            let ttl = ttl(&hot.session);
            let kind = match write {
                Write::Snapshot(_) => "snapshot",
                Write::Append(_) => "log",
            };
            let written = write.len();
            hot.shape.wrote(&write, cost);
            let expected = Expected {
                version,
                token: Some(hot.token),
            };
            let token = new_token();
            let outcome = self
                .store
                .write(tenant, id, expected, token, write, ttl)
                .await
                .map_err(unconfirmed)?;
            match outcome {
                CasOutcome::Stored { version } => {
                    metrics::counter!("fusion_session_writes_total", "write" => kind).increment(1);
                    metrics::counter!("fusion_session_written_bytes_total", "write" => kind)
                        .increment(written as u64);
                    update.version = version;
                    hot.token = token;
                    if let Some(copy) = copy {
                        let landing = hot.shape.snapshot_now();
                        self.snapshot_in_background(tenant, id, version, token, copy, landing)
                            .await;
                    }
                    let bytes = hot.shape.bytes();
                    self.cache.put(tenant, id, version, bytes, hot);
                    self.gauges.record(
                        tenant,
                        id,
                        K::radar_biases(&update.body),
                        K::radar_accuracy(&update.body),
                    );
                    if self.announces(tenant, id) {
                        let event = events::encode_update::<K>(tenant, &update, &marks);
                        self.publish(tenant, id, event).await;
                    }
                    return Ok(update);
                }
                CasOutcome::Missing => return Err(not_found(id)),
                CasOutcome::Conflict { .. } => {
                    metrics::counter!("fusion_session_cas_conflicts_total").increment(1);
                    if from_cache {
                        metrics::counter!("fusion_session_cache_total", "outcome" => "stale")
                            .increment(1);
                    }
                    tracing::debug!(
                        session = id,
                        attempt,
                        "lost a compare-and-set race; retrying"
                    );
                }
            }
        }
        Err(ServiceError::Unavailable(format!(
            "session '{id}' is being changed by too many writers at once; retry shortly"
        )))
    }

    /// Encodes `copy` (the session at `version`, made by the write with
    /// `token`) and writes it in place of the log up to that version, off
    /// the request path; the outcome goes to `landing`, where the next
    /// batch finds it. A snapshot that fails loses nothing (the log holds
    /// every batch) and is counted and logged
    /// (`fusion_session_snapshots_total{outcome}`).
    async fn snapshot_in_background<K: SessionKind>(
        &self,
        tenant: &str,
        id: &str,
        version: u64,
        token: u64,
        copy: Envelope<K>,
        landing: Arc<Mutex<Landing>>,
    ) {
        let store = Arc::clone(&self.store);
        let guard = self.background.enter();
        #[cfg(test)]
        let faults = Arc::clone(&self.faults);
        let (tenant, id) = (tenant.to_string(), id.to_string());
        let work = async move {
            let _guard = guard;
            let encoded = match tokio::runtime::Handle::try_current() {
                Ok(h) => h.spawn_blocking(move || copy.encode()).await,
                Err(_) => Ok(copy.encode()),
            };
            let outcome = match encoded {
                Ok(data) => {
                    let bytes = data.len();
                    let at = Expected {
                        version,
                        token: Some(token),
                    };
                    #[cfg(test)]
                    let injected = faults.before_write().await;
                    #[cfg(not(test))]
                    let injected: Result<(), String> = Ok(());
                    match injected {
                        Ok(()) => store
                            .compact(&tenant, &id, at, data)
                            .await
                            .map(|c| (c, bytes))
                            .map_err(|e| e.to_string()),
                        Err(e) => Err(e),
                    }
                }
                Err(e) => Err(format!("the encoding task failed: {e}")),
            };
            let result = match outcome {
                Ok((Compacted::Stored, bytes)) => {
                    metrics::counter!("fusion_session_snapshots_total", "outcome" => "stored")
                        .increment(1);
                    metrics::counter!("fusion_session_writes_total", "write" => "snapshot")
                        .increment(1);
                    metrics::counter!("fusion_session_written_bytes_total", "write" => "snapshot")
                        .increment(bytes as u64);
                    Landing::Landed { bytes }
                }
                Ok((Compacted::Stale | Compacted::Missing, _)) => {
                    metrics::counter!("fusion_session_snapshots_total", "outcome" => "stale")
                        .increment(1);
                    tracing::debug!(
                        session = %id,
                        version,
                        "a background snapshot was not written: the log no longer holds its \
                         version"
                    );
                    Landing::Failed
                }
                Err(e) => {
                    metrics::counter!("fusion_session_snapshots_total", "outcome" => "failed")
                        .increment(1);
                    tracing::warn!(
                        session = %id,
                        version,
                        error = %e,
                        "a background snapshot failed; the session's log still holds every \
                         batch, and a later batch writes another"
                    );
                    Landing::Failed
                }
            };
            *landing.lock().unwrap_or_else(|e| e.into_inner()) = result;
        };
        match tokio::runtime::Handle::try_current() {
            Ok(handle) => {
                handle.spawn(work);
            }
            // Outside tokio (a lane's `block_on`; not a path of the
            // service's sessions): before the reply.
            Err(_) => work.await,
        }
    }

    /// Waits until every snapshot this replica is writing in the
    /// background has landed or failed (the tests, and the load example
    /// before it reads the bytes written).
    pub async fn snapshots_settled(&self) {
        self.background.settled().await;
    }

    /// Whether a committed change of the session is announced: always over
    /// Redis (watchers may be on any replica), with the memory store only
    /// when this process has a watcher of it.
    fn announces(&self, tenant: &str, id: &str) -> bool {
        !matches!(*self.store, SessionStore::Memory(_)) || self.events.watched(tenant, id)
    }

    /// Announces a committed change. A failed publication loses nothing:
    /// the change is stored, and watchers find it at their next heartbeat.
    async fn publish(&self, tenant: &str, id: &str, event: Vec<u8>) {
        match self.store.publish(tenant, id, &event).await {
            Ok(true) => {}
            Ok(false) => match events::decode(&event) {
                Ok(e) => self.events.deliver(e),
                Err(e) => tracing::error!(error = %e, "a session event did not decode"),
            },
            Err(e) => {
                metrics::counter!("fusion_session_events_total", "outcome" => "unpublished")
                    .increment(1);
                tracing::warn!(session = id, error = %e, "a session event was not published");
            }
        }
    }

    /// Watches the session: first a snapshot of it (or, with `after`, the
    /// events after that version when this replica still holds them all),
    /// then every committed update in version order. `QuotaExceeded` when
    /// a watcher cap is reached, `NotFound` for no such session.
    ///
    /// The session's existence is checked (its version read) before the
    /// watcher joins the hub, so that a watch of an id that names no
    /// session holds no channel and no Redis subscription; a session gone
    /// between that check and the read after joining leaves nothing
    /// behind either (`events::Guard::abandon`).
    pub async fn watch(
        &self,
        tenant: &str,
        id: &str,
        after: Option<u64>,
    ) -> Result<Watch, ServiceError> {
        check_id(id)?;
        if self.store.version(tenant, id).await?.is_none() {
            return Err(not_found(id));
        }
        let joined = self
            .events
            .join(tenant, id, self.store.channel(tenant, id))
            .map_err(ServiceError::QuotaExceeded)?;
        // Read after joining: an update committed in between is in the
        // channel, and one before is in this read.
        let stored = match self.read(tenant, id).await {
            Ok(stored) => stored,
            Err(e) => {
                joined.guard.abandon();
                return Err(e);
            }
        };
        let version = stored.version;
        let resumed = after.filter(|&l| {
            l <= version && (l + 1..=version).all(|v| joined.history.iter().any(|e| e.version == v))
        });
        let mut queue = VecDeque::new();
        match resumed {
            Some(l) => queue.extend(
                joined
                    .history
                    .iter()
                    .filter(|e| e.version > l && e.version <= version)
                    .cloned()
                    .map(WatchItem::Update),
            ),
            None => queue.push_back(WatchItem::Snapshot(Box::new(any_view(id, stored).await?))),
        }
        metrics::counter!("fusion_session_watches_total", "start" => if resumed.is_some() { "resumed" } else { "snapshot" })
            .increment(1);
        Ok(Watch {
            store: Arc::clone(&self.store),
            tenant: tenant.to_string(),
            id: id.to_string(),
            rx: joined.rx,
            shutdown: joined.shutdown,
            _guard: joined.guard,
            heartbeat: self.events.limits().heartbeat,
            last: version,
            queue,
            pending: BTreeMap::new(),
            gap_since: None,
            done: false,
        })
    }
}

/// One watcher of one session (see [`events`]): [`Watch::next`] gives its
/// items in order, an `End` last.
pub struct Watch {
    store: Arc<SessionStore>,
    tenant: String,
    id: String,
    rx: broadcast::Receiver<HubItem>,
    shutdown: watch::Receiver<bool>,
    _guard: Guard,
    heartbeat: Duration,
    /// The version of the last item given.
    last: u64,
    queue: VecDeque<WatchItem>,
    /// Events that skip a version, waiting for the missing one.
    pending: BTreeMap<u64, Arc<SessionEvent>>,
    gap_since: Option<Instant>,
    done: bool,
}

impl Watch {
    pub fn heartbeat(&self) -> Duration {
        self.heartbeat
    }

    /// Sends every item, as `out` makes it (`None`: nothing to send; it
    /// gets the version of the last item given), into `tx` until the `End`
    /// or until the receiver is gone: the adapters spawn this for each
    /// stream, so a client that disconnects frees its watcher at once.
    pub async fn forward<T>(
        mut self,
        tx: tokio::sync::mpsc::Sender<T>,
        mut out: impl FnMut(WatchItem, u64) -> Option<T>,
    ) {
        loop {
            let item = tokio::select! {
                () = tx.closed() => return,
                item = self.next() => item,
            };
            let Some(item) = item else { return };
            let Some(message) = out(item, self.last) else {
                continue;
            };
            if tx.send(message).await.is_err() {
                return;
            }
        }
    }

    /// The next item; `None` after the `End`.
    pub async fn next(&mut self) -> Option<WatchItem> {
        if self.done {
            return None;
        }
        loop {
            if let Some(item) = self.queue.pop_front() {
                if matches!(item, WatchItem::End { .. }) {
                    self.done = true;
                    self.queue.clear();
                }
                return Some(item);
            }
            if *self.shutdown.borrow() {
                self.end(EndReason::Shutdown);
                continue;
            }
            let gap = self
                .gap_since
                .map(|t| tokio::time::Instant::from_std(t + GAP_WAIT));
            tokio::select! {
                biased;
                _ = self.shutdown.changed() => self.end(EndReason::Shutdown),
                item = self.rx.recv() => match item {
                    Ok(HubItem::Event(e)) => self.take(e),
                    Ok(HubItem::Resync) => self.resnapshot().await,
                    Err(broadcast::error::RecvError::Lagged(n)) => {
                        metrics::counter!("fusion_session_watchers_dropped_total").increment(1);
                        self.end(EndReason::Slow(n));
                    }
                    Err(broadcast::error::RecvError::Closed) => self.end(EndReason::Shutdown),
                },
                _ = tokio::time::sleep_until(gap.unwrap_or_else(tokio::time::Instant::now)), if gap.is_some() => {
                    metrics::counter!("fusion_session_event_gaps_total").increment(1);
                    self.resnapshot().await;
                }
                _ = tokio::time::sleep(self.heartbeat) => self.beat().await,
            }
        }
    }

    fn end(&mut self, reason: EndReason) {
        self.queue.push_back(WatchItem::End {
            reason,
            version: self.last,
        });
    }

    fn take(&mut self, e: Arc<SessionEvent>) {
        if matches!(e.body, EventBody::Deleted) {
            self.end(EndReason::Deleted);
        } else if e.version == self.last + 1 {
            self.last = e.version;
            self.queue.push_back(WatchItem::Update(e));
            self.drain();
        } else if e.version > self.last {
            self.pending.insert(e.version, e);
            self.gap_since.get_or_insert_with(Instant::now);
        }
    }

    /// Gives the held events that now follow in order.
    fn drain(&mut self) {
        while let Some(e) = self.pending.remove(&(self.last + 1)) {
            self.last = e.version;
            self.queue.push_back(WatchItem::Update(e));
        }
        self.pending.retain(|&v, _| v > self.last);
        self.gap_since = if self.pending.is_empty() {
            None
        } else {
            Some(Instant::now())
        };
    }

    /// Reads the stored session; a version past the last item is given as a
    /// snapshot (it holds every update in between).
    async fn resnapshot(&mut self) {
        self.gap_since = None;
        match self.store.get(&self.tenant, &self.id).await {
            Ok(None) => self.end(EndReason::Expired),
            Ok(Some(stored)) if stored.version > self.last => {
                let version = stored.version;
                match any_view(&self.id, stored).await {
                    Ok(view) => {
                        self.last = version;
                        self.queue.push_back(WatchItem::Snapshot(Box::new(view)));
                        self.drain();
                    }
                    Err(e) => {
                        tracing::error!(session = %self.id, error = %e, "a watched session did not decode")
                    }
                }
            }
            Ok(Some(_)) => self.drain(),
            // The store is down: the next heartbeat looks again.
            Err(_) => {}
        }
    }

    /// A quiet interval: the session still lives (else the watch ends), and
    /// a version stored past the last item (an event lost) is fetched.
    async fn beat(&mut self) {
        match self.store.version(&self.tenant, &self.id).await {
            Ok(None) => self.end(EndReason::Expired),
            Ok(Some(v)) if v > self.last => self.resnapshot().await,
            _ => self.queue.push_back(WatchItem::Heartbeat),
        }
    }
}

/// The kind of a stored session; one this release does not serve is an
/// internal error naming it.
fn served_kind(stored: &Stored) -> Result<KindName, ServiceError> {
    let tag = stored_kind(&stored.data)?;
    KindName::from_tag(tag).ok_or_else(|| {
        ServiceError::Internal(format!(
            "stored session: {} is not served by this release",
            tag_name(tag)
        ))
    })
}

/// [`Sessions::get`] for the stored session's kind: its view, kept in the
/// cache ([`Sessions::view_kept`]).
struct ViewKept<'a> {
    sessions: &'a Sessions,
    tenant: &'a str,
    id: &'a str,
    stored: Stored,
}

impl<'a> KindVisitor for ViewKept<'a> {
    type Out = std::pin::Pin<
        Box<dyn std::future::Future<Output = Result<AnyView, ServiceError>> + Send + 'a>,
    >;

    fn visit<K: Registered>(self) -> Self::Out {
        Box::pin(async move {
            let view = self
                .sessions
                .view_kept::<K>(self.tenant, self.id, self.stored)
                .await?;
            Ok(K::any_view(view))
        })
    }
}

/// The view of stored bytes of the kind visited.
struct ViewOf<'a> {
    id: &'a str,
    stored: &'a Stored,
}

impl KindVisitor for ViewOf<'_> {
    type Out = Result<AnyView, ServiceError>;

    fn visit<K: Registered>(self) -> Self::Out {
        view_of::<K>(self.id, self.stored).map(K::any_view)
    }
}

/// The view of stored bytes of any kind, decoded off the async workers.
async fn any_view(id: &str, stored: Stored) -> Result<AnyView, ServiceError> {
    let id = id.to_string();
    offload(move || {
        served_kind(&stored)?.visit(ViewOf {
            id: &id,
            stored: &stored,
        })
    })
    .await
}

/// A decoded session of any kind this release serves (one at a time, on
/// its way into the cache: the variants' sizes do not matter).
fn view_and_hot<K: SessionKind>(
    id: &str,
    stored: &Stored,
) -> Result<(View<K::View>, Hot<K>), ServiceError> {
    let hot = Hot::<K>::read(id, stored).map_err(|e| match e {
        DecodeError::WrongKind { stored } => ServiceError::NotFound(format!(
            "session '{id}' is a {} session, not {}",
            tag_name(stored),
            K::NAME
        )),
        DecodeError::Other(e) => e,
    })?;
    let view = hot.session.view(id, stored.version, stored.bytes())?;
    Ok((view, hot))
}

/// The view of `stored`, from `cached` when it is the state of the same
/// write (version and token), else from the stored bytes; with the decoded
/// session to keep.
fn view_from<K: SessionKind>(
    id: &str,
    stored: &Stored,
    cached: Option<Hot<K>>,
) -> Result<(View<K::View>, Hot<K>), ServiceError> {
    match cached {
        Some(hot) if hot.token == stored.token => {
            metrics::counter!("fusion_session_cache_total", "outcome" => "read_hit").increment(1);
            let view = hot.session.view(id, stored.version, stored.bytes())?;
            Ok((view, hot))
        }
        _ => view_and_hot::<K>(id, stored),
    }
}

fn view_of<K: SessionKind>(id: &str, stored: &Stored) -> Result<View<K::View>, ServiceError> {
    view_and_hot::<K>(id, stored).map(|(view, _)| view)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot_fusion::PlotInput;
    use crate::session::{
        Batch, Spec,
        plot_fusion::{
            BatchInput, PlotFusionSession,
            tests::{plots, spec},
        },
    };
    use store::StoreSettings;

    const TENANT: &str = "t";

    /// Faults a test puts in the way of background snapshots: a gate they
    /// wait at before writing (open unless a test closes it), and a
    /// failure in place of the write.
    pub(super) struct Faults {
        gate: tokio::sync::Semaphore,
        fail: std::sync::atomic::AtomicBool,
    }

    impl Default for Faults {
        fn default() -> Self {
            Self {
                gate: tokio::sync::Semaphore::new(tokio::sync::Semaphore::MAX_PERMITS),
                fail: Default::default(),
            }
        }
    }

    impl Faults {
        pub(super) async fn before_write(&self) -> Result<(), String> {
            let _pass = self.gate.acquire().await.map_err(|e| e.to_string())?;
            if self.fail.load(Ordering::SeqCst) {
                Err("a write failure put in by the test".into())
            } else {
                Ok(())
            }
        }
    }

    /// Sessions whose background snapshots wait at a closed gate until
    /// [`open`] (and fail there when `fail`).
    async fn gated(max_entries: usize, fail: bool) -> Sessions {
        let mut sessions = memory(max_entries).await;
        sessions.faults = Arc::new(Faults {
            gate: tokio::sync::Semaphore::new(0),
            fail: fail.into(),
        });
        sessions
    }

    fn open(sessions: &Sessions) {
        sessions
            .faults
            .gate
            .add_permits(tokio::sync::Semaphore::MAX_PERMITS >> 4);
    }

    async fn memory(max_entries: usize) -> Sessions {
        let store = SessionStore::connect(&StoreSettings {
            url: "memory".into(),
            redis: Default::default(),
            wait_replicas: 0,
            key_prefix: String::new(),
            max_sessions_per_tenant: 10,
            max_memory_bytes: 1 << 26,
            max_memory_bytes_per_tenant: 1 << 26,
            timeout: Duration::from_secs(1),
        })
        .await
        .unwrap();
        // No bound by replay time: the cadence is by entries and bytes
        // only, so the tests' logs are known in advance.
        Sessions::new(store, 1 << 26).with_snapshots(SnapshotPolicy {
            max_entries,
            max_replay_s: 0.0,
            ..SnapshotPolicy::default()
        })
    }

    /// Pushes `chunks` of plots in turn; after each, a replica that reads
    /// the store (the snapshot, then the log replayed) must hold the state
    /// of the replica that served the batch, byte for byte. Returns the
    /// log's length after each push.
    async fn serve_and_rebuild(sessions: &Sessions, chunks: &[Vec<PlotInput>]) -> Vec<usize> {
        serve_and_rebuild_with(sessions, chunks, None, None).await
    }

    /// [`serve_and_rebuild`] with `tracker.late_plots` and
    /// `tracker.max_replay_plots`.
    async fn serve_and_rebuild_with(
        sessions: &Sessions,
        chunks: &[Vec<PlotInput>],
        late_plots: Option<&str>,
        max_replay_plots: Option<u32>,
    ) -> Vec<usize> {
        let id = new_session(sessions, late_plots, max_replay_plots).await;
        let mut logs = Vec::new();
        for (i, chunk) in chunks.iter().enumerate() {
            push_chunk(sessions, &id, i, chunk).await;
            sessions.snapshots_settled().await;
            logs.push(check_replica(sessions, &id, i).await);
        }
        logs
    }

    async fn new_session(
        sessions: &Sessions,
        late_plots: Option<&str>,
        max_replay_plots: Option<u32>,
    ) -> String {
        let mut body = spec();
        body.tracker.late_plots = late_plots.map(str::to_string);
        body.tracker.max_replay_plots = max_replay_plots;
        sessions
            .create::<PlotFusionSession>(
                TENANT,
                Spec {
                    idle_expiry_s: None,
                    body,
                },
            )
            .await
            .unwrap()
            .id
    }

    /// Pushes `chunk` as batch `i + 1`; its version.
    async fn push_chunk(sessions: &Sessions, id: &str, i: usize, chunk: &[PlotInput]) -> u64 {
        push_chunk_limited(sessions, id, i, chunk, 100).await
    }

    /// [`push_chunk`] at a limit of `max_tracks` tracks.
    async fn push_chunk_limited(
        sessions: &Sessions,
        id: &str,
        i: usize,
        chunk: &[PlotInput],
        max_tracks: usize,
    ) -> u64 {
        let limits = Limits {
            max_tracks,
            max_batch_reports: 1000,
        };
        let batch = Batch {
            sequence: Some(i as u64 + 1),
            body: BatchInput {
                plots: chunk.to_vec(),
                ..Default::default()
            },
        };
        sessions
            .push::<PlotFusionSession>(TENANT, id, batch, limits)
            .await
            .unwrap()
            .version
    }

    /// A replica that reads the store now (the snapshot, then the log
    /// replayed) must hold the state of the replica that served the
    /// batches, byte for byte, and know the store's shape as it does
    /// (once it has taken in a snapshot that landed). The log's length.
    async fn check_replica(sessions: &Sessions, id: &str, i: usize) -> usize {
        let stored = sessions.store().get(TENANT, id).await.unwrap().unwrap();
        let (version, mut serving) = sessions
            .cache
            .take::<Hot<PlotFusionSession>>(TENANT, id)
            .unwrap();
        assert_eq!(version, stored.version);
        let rebuilt = Hot::<PlotFusionSession>::read(id, &stored).unwrap();
        // The same picture, tracks, covariances, counters and kept
        // update, bit for bit. The stored bytes may differ in where
        // the lag window's base lies: the serving replica moves it to
        // checkpoints it keeps in memory only, a rebuilt one by
        // processing the plots, which by the tracker's streaming rule
        // gives the same tracker (the window then holds more plots).
        // So may the work a late plot costs: an update's `frames`
        // counts the frames processed again, from the nearest
        // checkpoint.
        let view = |h: &Hot<PlotFusionSession>| h.session.view(id, 0, 0).unwrap();
        assert_eq!(view(&rebuilt), view(&serving), "batch {i}");
        let kept = |h: &Hot<PlotFusionSession>| {
            h.session.last_update.clone().map(|mut k| {
                k.body.frames = 0;
                k
            })
        };
        assert_eq!(kept(&rebuilt), kept(&serving), "batch {i}");
        let settled = serving
            .shape
            .pending
            .as_ref()
            .is_none_or(|p| *p.landing.lock().unwrap() != Landing::Writing);
        serving.shape.settle();
        if settled {
            let shape = |h: &Hot<PlotFusionSession>| {
                (
                    h.token,
                    h.shape.snapshot_bytes,
                    h.shape.entries,
                    h.shape.log_bytes,
                )
            };
            assert_eq!(shape(&rebuilt), shape(&serving), "batch {i}");
        }
        let bytes = serving.shape.bytes();
        sessions.cache.put(TENANT, id, version, bytes, serving);
        stored.log.len()
    }

    #[tokio::test]
    async fn a_watch_that_does_not_start_leaves_no_channel_and_one_that_ends_keeps_it() {
        let sessions = memory(32).await;
        let hub = &sessions.events;
        let id = "0123456789abcdef0123456789abcdef";
        // No such session: refused before joining.
        assert!(matches!(
            sessions.watch(TENANT, id, None).await,
            Err(ServiceError::NotFound(_))
        ));
        assert!(!hub.watched(TENANT, id));
        // A watch abandoned as it starts (its session gone between the
        // check and the read) removes the channel it made at once.
        let joined = hub.join(TENANT, id, None).unwrap();
        assert!(hub.watched(TENANT, id));
        joined.guard.abandon();
        assert!(!hub.watched(TENANT, id));
        // A watch that ran and ended keeps the channel for resuming.
        let joined = hub.join(TENANT, id, None).unwrap();
        drop(joined);
        assert!(hub.watched(TENANT, id));
    }

    #[tokio::test]
    async fn a_replica_that_replays_the_log_holds_the_serving_replicas_state() {
        let chunks: Vec<Vec<PlotInput>> = plots().chunks(4).map(<[_]>::to_vec).collect();
        assert!(chunks.len() > 8);
        // At most 4 entries: a snapshot every 4th batch.
        let logs = serve_and_rebuild(&memory(4).await, &chunks).await;
        let cycle: Vec<usize> = (0..chunks.len()).map(|i| [1, 2, 3, 0][i % 4]).collect();
        assert_eq!(logs, cycle);
        // 1: a snapshot every batch, as before the log.
        let logs = serve_and_rebuild(&memory(1).await, &chunks).await;
        assert!(logs.iter().all(|&n| n == 0));
        // Late plots within the lag (every other pair of batches swapped):
        // the replay recomputes the same corrections.
        let mut swapped = chunks.clone();
        for pair in swapped.chunks_mut(2) {
            pair.reverse();
        }
        serve_and_rebuild(&memory(32).await, &swapped).await;
        // The same under retrodiction: the late plots update the tracks
        // where they stand, identically on both replicas.
        serve_and_rebuild_with(&memory(4).await, &swapped, Some("retrodict"), None).await;
        // Auto with a bound of 2 replayed plots: some batches retrodict,
        // others replay; the decisions are the stored state's, so the
        // replicas agree.
        serve_and_rebuild_with(&memory(4).await, &swapped, None, Some(2)).await;
    }

    /// A session at its limit of tracks: the serving replica holds at most
    /// the limit, and so does every read of the store (a `GET`, a replica
    /// taking the next batch), bit for bit the serving state, whatever
    /// the store holds at the time (a snapshot alone, or a snapshot and a
    /// log). Before the limit was stored with the session, a decoded
    /// window flushed its open frame without it: the extra tentative
    /// tracks a read saw were confirmed by the log's replay (6 confirmed
    /// tracks at a limit of 3 in `checks/hostile_probes.py`).
    #[tokio::test]
    async fn every_read_of_a_session_at_its_track_limit_holds_the_limit() {
        // Two crossing targets, one track allowed; 4 plots a batch (one
        // radar's scan of both targets, and the next scan's start).
        let chunks: Vec<Vec<PlotInput>> = plots().chunks(3).map(<[_]>::to_vec).collect();
        for max_entries in [1, 3, 32] {
            let sessions = memory(max_entries).await;
            let id = new_session(&sessions, None, None).await;
            for (i, chunk) in chunks.iter().enumerate() {
                push_chunk_limited(&sessions, &id, i, chunk, 1).await;
                sessions.snapshots_settled().await;
                check_replica(&sessions, &id, i).await;
                let AnyView::PlotFusion(view) = sessions.get(TENANT, &id).await.unwrap() else {
                    panic!("a plot-fusion session");
                };
                assert!(
                    view.body.tracks.len() <= 1,
                    "entries {max_entries}, batch {i}: {} tracks",
                    view.body.tracks.len()
                );
            }
        }
    }

    /// While a snapshot is being written a reader finds the snapshot
    /// before it and the whole log, and after it lands the new snapshot
    /// and the entries after its version: the serving replica's state
    /// either way. A snapshot every 4 batches (4 entries): version k + 1
    /// is batch k's.
    #[tokio::test]
    async fn a_reader_during_a_background_snapshot_finds_the_state_whole() {
        let chunks: Vec<Vec<PlotInput>> = plots().chunks(4).map(<[_]>::to_vec).collect();
        assert!(chunks.len() >= 7);
        let sessions = gated(4, false).await;
        let id = new_session(&sessions, None, None).await;
        // Batches 1–4: the fourth entry makes a snapshot due; it waits at
        // the gate, so the store holds the creation's snapshot and 4
        // entries.
        for (i, chunk) in chunks[..4].iter().enumerate() {
            push_chunk(&sessions, &id, i, chunk).await;
            assert_eq!(check_replica(&sessions, &id, i).await, i + 1);
        }
        // Batch 5 while it waits: one snapshot at a time, the log grows.
        push_chunk(&sessions, &id, 4, &chunks[4]).await;
        assert_eq!(check_replica(&sessions, &id, 4).await, 5);
        // It lands: the state at version 5 (batch 4), entry 6 (batch 5)
        // kept.
        open(&sessions);
        sessions.snapshots_settled().await;
        assert_eq!(check_replica(&sessions, &id, 4).await, 1);
        // Batches 6 and 7 follow it: 2 and 3 entries, no snapshot due.
        for (i, chunk) in chunks.iter().enumerate().skip(5).take(2) {
            push_chunk(&sessions, &id, i, chunk).await;
            sessions.snapshots_settled().await;
            assert_eq!(check_replica(&sessions, &id, i).await, i - 3);
        }
    }

    /// A GET of a session this replica holds decoded at the stored version
    /// answers from it, as a replica that reads the store would: the same
    /// view, and the serving replica's own copy kept (its background
    /// snapshot still pending: a copy read from the store would know of
    /// none). After another writer's batch (a version the copy does not
    /// hold) the GET reads the store.
    #[tokio::test]
    async fn a_get_of_a_hot_session_answers_from_its_decoded_copy() {
        let chunks: Vec<Vec<PlotInput>> = plots().chunks(4).map(<[_]>::to_vec).collect();
        let sessions = gated(4, false).await;
        let id = new_session(&sessions, None, None).await;
        let mut version = 0;
        for (i, chunk) in chunks[..4].iter().enumerate() {
            version = push_chunk(&sessions, &id, i, chunk).await;
        }
        let fresh = sessions
            .get_as::<PlotFusionSession>(TENANT, &id)
            .await
            .unwrap();
        let AnyView::PlotFusion(view) = sessions.get(TENANT, &id).await.unwrap() else {
            panic!("a plot-fusion session");
        };
        assert_eq!(view, fresh);
        let hot = sessions
            .cache
            .take_at::<Hot<PlotFusionSession>>(TENANT, &id, version)
            .expect("kept in the cache");
        assert!(hot.shape.pending.is_some(), "the copy was read again");
        // A batch the copy has not seen (as another replica's would be):
        // the store moves on, and only the stale copy is cached.
        push_chunk(&sessions, &id, 4, &chunks[4]).await;
        let newer = sessions
            .cache
            .take_at::<Hot<PlotFusionSession>>(TENANT, &id, version + 1);
        assert!(newer.is_some());
        sessions.cache.put(TENANT, &id, version, 1, hot);
        let AnyView::PlotFusion(after) = sessions.get(TENANT, &id).await.unwrap() else {
            panic!("a plot-fusion session");
        };
        assert_eq!(after.version, version + 1);
        assert_eq!(
            after,
            sessions
                .get_as::<PlotFusionSession>(TENANT, &id)
                .await
                .unwrap()
        );
        open(&sessions);
        sessions.snapshots_settled().await;
    }

    /// A background snapshot that fails loses nothing: the log still
    /// holds every batch, a replica reads the whole state from it, and the
    /// next batch writes another snapshot.
    #[tokio::test]
    async fn a_failed_background_snapshot_leaves_the_session_whole() {
        let chunks: Vec<Vec<PlotInput>> = plots().chunks(4).map(<[_]>::to_vec).collect();
        assert!(chunks.len() >= 5);
        let sessions = gated(4, true).await;
        let id = new_session(&sessions, None, None).await;
        for (i, chunk) in chunks[..4].iter().enumerate() {
            push_chunk(&sessions, &id, i, chunk).await;
        }
        open(&sessions);
        sessions.snapshots_settled().await;
        // Failed: the creation's snapshot and the 4 entries.
        assert_eq!(check_replica(&sessions, &id, 3).await, 4);
        // Batch 5: 5 entries, a snapshot due again, and this one lands
        // (at batch 5's version: no entry after it).
        sessions.faults.fail.store(false, Ordering::SeqCst);
        push_chunk(&sessions, &id, 4, &chunks[4]).await;
        sessions.snapshots_settled().await;
        assert_eq!(check_replica(&sessions, &id, 4).await, 0);
    }

    /// The cadence: a snapshot is due at `max_entries` entries, or once the
    /// log holds the snapshot's bytes, or once its replay takes
    /// `max_replay_s` provided the log holds a share (1 /
    /// `max_write_amplification`) of the snapshot's bytes; never while one
    /// is being written, nor with an empty log.
    #[test]
    fn a_snapshot_falls_due_by_entries_bytes_or_replay_time() {
        let policy = SnapshotPolicy {
            max_entries: 32,
            max_replay_s: 0.5,
            max_write_amplification: 3.0,
        };
        let shape = |entries: usize, log_bytes: usize, replay_s: f64| LogShape {
            snapshot_bytes: 6_000,
            entries,
            log_bytes,
            replay_s,
            pending: None,
        };
        assert!(!shape(0, 0, 0.0).snapshot_due(policy));
        assert!(!shape(31, 1_000, 0.1).snapshot_due(policy));
        assert!(shape(32, 1_000, 0.1).snapshot_due(policy));
        assert!(!shape(10, 5_999, 0.1).snapshot_due(policy));
        assert!(shape(10, 6_000, 0.1).snapshot_due(policy));
        // Replay time with a third of the snapshot's bytes: due; with
        // less: not yet (snapshots would add more than 3× the log).
        assert!(shape(4, 2_000, 0.5).snapshot_due(policy));
        assert!(!shape(4, 1_999, 0.5).snapshot_due(policy));
        assert!(!shape(4, 2_000, 0.49).snapshot_due(policy));
        // No bound by time.
        let untimed = SnapshotPolicy {
            max_replay_s: 0.0,
            ..policy
        };
        assert!(!shape(4, 2_000, 100.0).snapshot_due(untimed));
        // One being written: none more.
        let mut writing = shape(32, 6_000, 1.0);
        let landing = writing.snapshot_now();
        assert!(!writing.snapshot_due(policy));
        // It lands at 4,000 bytes while 2 more entries (1,000 bytes,
        // 0.2 s) were appended: they are the log now.
        writing.wrote(&Write::Append(vec![0; 1_000]), 0.2);
        writing.wrote(&Write::Append(Vec::new()), 0.0);
        *landing.lock().unwrap() = Landing::Landed { bytes: 4_000 };
        writing.settle();
        assert!(writing.pending.is_none());
        assert_eq!(
            (writing.snapshot_bytes, writing.entries, writing.log_bytes),
            (4_000, 2, 1_000)
        );
        assert!((writing.replay_s - 0.2).abs() < 1e-12);
        // A failed one leaves the log as it is, and may be tried again.
        let landing = writing.snapshot_now();
        *landing.lock().unwrap() = Landing::Failed;
        writing.settle();
        assert!(writing.pending.is_none());
        assert_eq!((writing.entries, writing.log_bytes), (2, 1_000));
    }
}
