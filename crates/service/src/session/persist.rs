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
    sync::Arc,
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

use tokio::sync::{broadcast, watch};

use super::{
    Admission, Batch, DecodeError, Envelope, KindName, Limits, SessionKind, Spec, Update, View,
    cache::SessionCache,
    correlation::CorrelationSession,
    events::{
        self, EndReason, EventBody, EventHub, GAP_WAIT, Guard, HubItem, SessionEvent, WatchItem,
        WatchLimits,
    },
    gauges::RadarGauges,
    plot_fusion::PlotFusionSession,
    stored_kind, tag_name,
};
use crate::{ServiceError, offload};
use store::{CasOutcome, Expected, SessionMeta, SessionStore, StoreError, Stored, Write};

/// How many times a push re-reads the session after losing a race.
const MAX_ATTEMPTS: usize = 32;

/// The session store and the cache of decoded sessions in front of it.
pub struct Sessions {
    store: Arc<SessionStore>,
    cache: SessionCache,
    events: Arc<EventHub>,
    gauges: RadarGauges,
    snapshots: SnapshotPolicy,
}

/// When a push stores the whole session (a snapshot) rather than its batch
/// (a log entry): a session is stored as a snapshot and the batches applied
/// since, so a write costs what the batch carries, and a replica that
/// reads the session replays at most `max_entries` batches.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SnapshotPolicy {
    /// Most log entries after a snapshot (`--session-snapshot-batches`);
    /// 1 stores a snapshot every batch. A snapshot is also written once the
    /// log holds as many bytes as the snapshot.
    pub max_entries: usize,
}

impl Default for SnapshotPolicy {
    fn default() -> Self {
        Self {
            max_entries: DEFAULT_SNAPSHOT_BATCHES,
        }
    }
}

/// Default [`SnapshotPolicy::max_entries`]: at 4,000 aircraft under four
/// radars in 1-s batches (a 11.5 MB snapshot, 0.25 MB of plots a batch)
/// about 0.6 MB written a batch on average, and at most 32 batches (128k
/// plots, about a second) to replay on a takeover.
pub const DEFAULT_SNAPSHOT_BATCHES: usize = 32;

/// The shape of a session as stored: its snapshot's bytes and the log after
/// it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct LogShape {
    snapshot_bytes: usize,
    entries: usize,
    log_bytes: usize,
}

impl LogShape {
    fn of(stored: &Stored) -> Self {
        Self {
            snapshot_bytes: stored.data.len(),
            entries: stored.log.len(),
            log_bytes: stored.log_bytes(),
        }
    }

    fn bytes(&self) -> usize {
        self.snapshot_bytes + self.log_bytes
    }

    /// Whether an entry of `len` bytes goes to the log (else a snapshot).
    fn takes(&self, len: usize, policy: SnapshotPolicy) -> bool {
        self.entries + 1 < policy.max_entries.max(1) && self.log_bytes + len < self.snapshot_bytes
    }

    fn wrote(&mut self, write: &Write) {
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
            }
        }
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
        let mut session = Envelope::<K>::decode(&stored.data)?;
        for entry in &stored.log {
            session.replay(id, entry)?;
        }
        if !stored.log.is_empty() {
            metrics::counter!("fusion_session_replayed_batches_total")
                .increment(stored.log.len() as u64);
        }
        Ok(Self {
            session,
            token: stored.token,
            shape: LogShape::of(stored),
        })
    }
}

/// A fresh write token: random, never 0 (the token of a session no write
/// has touched since its creation).
fn new_token() -> u64 {
    rand::random::<u64>() | 1
}

/// A session of any kind this release serves, as a client reads it.
#[derive(Debug, Clone, PartialEq)]
pub enum AnyView {
    Correlation(View<<CorrelationSession as SessionKind>::View>),
    PlotFusion(View<<PlotFusionSession as SessionKind>::View>),
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
    pub async fn get(&self, tenant: &str, id: &str) -> Result<AnyView, ServiceError> {
        let stored = self.read(tenant, id).await?;
        any_view(id, stored).await
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
        let stored = self.read(tenant, id).await?;
        let tag = stored_kind(&stored.data)?;
        KindName::from_tag(tag).ok_or_else(|| {
            ServiceError::Internal(format!(
                "stored session: {} is not served by this release",
                tag_name(tag)
            ))
        })
    }

    /// The stored session `id`, or 404.
    async fn read(&self, tenant: &str, id: &str) -> Result<Stored, ServiceError> {
        check_id(id)?;
        self.store
            .get(tenant, id)
            .await?
            .ok_or_else(|| not_found(id))
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
                        let update = hot.session.apply(&id2, &batch2, &limits)?;
                        let marks = hot.session.state.take_marks();
                        let write = match Envelope::<K>::encode_entry(&batch2, &limits)
                            .filter(|e| hot.shape.takes(e.len(), policy))
                        {
                            Some(entry) => Write::Append(entry),
                            None => Write::Snapshot(hot.session.encode()),
                        };
                        Ok(Ok((update, write, hot, marks)))
                    }
                }
            })
            .await;
            let (mut update, write, mut hot, marks) = match worked {
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
            hot.shape.wrote(&write);
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
                    let bytes = hot.shape.bytes();
                    self.cache.put(tenant, id, version, bytes, hot);
                    self.gauges
                        .record(tenant, id, K::radar_biases(&update.body));
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

/// The view of stored bytes of any kind, decoded off the async workers.
async fn any_view(id: &str, stored: Stored) -> Result<AnyView, ServiceError> {
    let id = id.to_string();
    offload(move || {
        let tag = stored_kind(&stored.data)?;
        match KindName::from_tag(tag) {
            Some(KindName::Correlation) => Ok(AnyView::Correlation(view_of::<CorrelationSession>(
                &id, &stored,
            )?)),
            Some(KindName::PlotFusion) => Ok(AnyView::PlotFusion(view_of::<PlotFusionSession>(
                &id, &stored,
            )?)),
            None => Err(ServiceError::Internal(format!(
                "stored session: {} is not served by this release",
                tag_name(tag)
            ))),
        }
    })
    .await
}

fn view_of<K: SessionKind>(id: &str, stored: &Stored) -> Result<View<K::View>, ServiceError> {
    let hot = Hot::<K>::read(id, stored).map_err(|e| match e {
        DecodeError::WrongKind { stored } => ServiceError::NotFound(format!(
            "session '{id}' is a {} session, not {}",
            tag_name(stored),
            K::NAME
        )),
        DecodeError::Other(e) => e,
    })?;
    hot.session.view(id, stored.version, stored.bytes())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plot_fusion::PlotInput;
    use crate::session::{
        Batch, Spec,
        plot_fusion::{
            BatchInput,
            tests::{plots, spec},
        },
    };
    use store::StoreSettings;

    const TENANT: &str = "t";

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
        Sessions::new(store, 1 << 26).with_snapshots(SnapshotPolicy { max_entries })
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
        let mut body = spec();
        body.tracker.late_plots = late_plots.map(str::to_string);
        body.tracker.max_replay_plots = max_replay_plots;
        let created = sessions
            .create::<PlotFusionSession>(
                TENANT,
                Spec {
                    idle_expiry_s: None,
                    body,
                },
            )
            .await
            .unwrap();
        let id = created.id;
        let limits = Limits {
            max_tracks: 100,
            max_batch_reports: 1000,
        };
        let mut logs = Vec::new();
        for (i, chunk) in chunks.iter().enumerate() {
            let batch = Batch {
                sequence: Some(i as u64 + 1),
                body: BatchInput {
                    plots: chunk.clone(),
                    ..Default::default()
                },
            };
            let update = sessions
                .push::<PlotFusionSession>(TENANT, &id, batch, limits)
                .await
                .unwrap();
            let stored = sessions.store().get(TENANT, &id).await.unwrap().unwrap();
            assert_eq!(stored.version, update.version);
            let (version, serving) = sessions
                .cache
                .take::<Hot<PlotFusionSession>>(TENANT, &id)
                .unwrap();
            assert_eq!(version, stored.version);
            let rebuilt = Hot::<PlotFusionSession>::read(&id, &stored).unwrap();
            // The same picture, tracks, covariances, counters and kept
            // update, bit for bit. The stored bytes may differ in where
            // the lag window's base lies: the serving replica moves it to
            // checkpoints it keeps in memory only, a rebuilt one by
            // processing the plots, which by the tracker's streaming rule
            // gives the same tracker (the window then holds more plots).
            // So may the work a late plot costs: an update's `frames`
            // counts the frames processed again, from the nearest
            // checkpoint.
            let view = |h: &Hot<PlotFusionSession>| h.session.view(&id, 0, 0).unwrap();
            assert_eq!(view(&rebuilt), view(&serving), "batch {i}");
            let kept = |h: &Hot<PlotFusionSession>| {
                h.session.last_update.clone().map(|mut k| {
                    k.body.frames = 0;
                    k
                })
            };
            assert_eq!(kept(&rebuilt), kept(&serving), "batch {i}");
            assert_eq!(
                (rebuilt.token, rebuilt.shape),
                (serving.token, serving.shape)
            );
            logs.push(stored.log.len());
            let bytes = serving.shape.bytes();
            sessions.cache.put(TENANT, &id, version, bytes, serving);
        }
        logs
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
}
