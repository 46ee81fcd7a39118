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
use store::{CasOutcome, SessionMeta, SessionStore, StoreError, Stored};

/// How many times a push re-reads the session after losing a race.
const MAX_ATTEMPTS: usize = 32;

/// The session store and the cache of decoded sessions in front of it.
pub struct Sessions {
    store: Arc<SessionStore>,
    cache: SessionCache,
    events: Arc<EventHub>,
    gauges: RadarGauges,
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
    ServiceError::NotFound(format!("no session '{id}'"))
}

/// Where a push's decoded session comes from.
enum Source<K: SessionKind> {
    /// The cache: trusted only if the compare-and-set on its version succeeds.
    Cache(Envelope<K>),
    /// A fresh read of the store: its bytes, decoded off the async workers.
    Store(Vec<u8>),
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
        }
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
        self.cache.put(tenant, &id, version, bytes, session);
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
        offload(move || view_of::<K>(&id, &stored.data, stored.version)).await
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
        let mut attempt = 0;
        while attempt < MAX_ATTEMPTS {
            let (version, source) = match self.cache.take::<Envelope<K>>(tenant, id) {
                Some((version, session)) => {
                    metrics::counter!("fusion_session_cache_total", "outcome" => "hit")
                        .increment(1);
                    (version, Source::Cache(session))
                }
                None => {
                    metrics::counter!("fusion_session_cache_total", "outcome" => "miss")
                        .increment(1);
                    let stored = self.read(tenant, id).await?;
                    (stored.version, Source::Store(stored.data))
                }
            };
            let (batch2, id2) = (Arc::clone(&batch), id.to_string());
            let from_cache = matches!(source, Source::Cache(_));
            let worked = offload(move || {
                let mut session = match source {
                    Source::Cache(s) => s,
                    Source::Store(data) => {
                        Envelope::<K>::decode(&data).map_err(|e| e.for_request::<K>(&id2))?
                    }
                };
                let fingerprint = K::fingerprint(&batch2.body);
                match session.admit(&id2, batch2.sequence, fingerprint, version)? {
                    Admission::Duplicate(ack) => Ok(Err(ack)),
                    Admission::Apply => {
                        let update = session.apply(&id2, &batch2, &limits)?;
                        let marks = session.state.take_marks();
                        let data = session.encode();
                        Ok(Ok((update, data, session, marks)))
                    }
                }
            })
            .await;
            let (mut update, data, session, marks) = match worked {
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
                Ok(Err(duplicate)) => return Ok(duplicate),
                Ok(Ok(applied)) => applied,
            };
            attempt += 1;
            let bytes = data.len();
            let ttl = ttl(&session);
            let outcome = self
                .store
                .compare_and_set(tenant, id, version, data, ttl)
                .await
                .map_err(|e| match e {
                    // The write may still land (a slow Redis applies it
                    // later): never report it as "nothing changed".
                    StoreError::Unavailable { reason } => ServiceError::Unavailable(format!(
                        "the session store did not confirm the write ({reason}): the batch \
                         may or may not have been applied; retry it unchanged, with the same \
                         sequence number if it had one (a batch applied already is \
                         acknowledged as a duplicate)"
                    )),
                    other => other.into(),
                })?;
            match outcome {
                CasOutcome::Stored { version } => {
                    update.version = version;
                    self.cache.put(tenant, id, version, bytes, session);
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
    pub async fn watch(
        &self,
        tenant: &str,
        id: &str,
        after: Option<u64>,
    ) -> Result<Watch, ServiceError> {
        check_id(id)?;
        let joined = self
            .events
            .join(tenant, id, self.store.channel(tenant, id))
            .map_err(ServiceError::QuotaExceeded)?;
        // Read after joining: an update committed in between is in the
        // channel, and one before is in this read.
        let stored = self.read(tenant, id).await?;
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
                &id,
                &stored.data,
                stored.version,
            )?)),
            Some(KindName::PlotFusion) => Ok(AnyView::PlotFusion(view_of::<PlotFusionSession>(
                &id,
                &stored.data,
                stored.version,
            )?)),
            None => Err(ServiceError::Internal(format!(
                "stored session: {} is not served by this release",
                tag_name(tag)
            ))),
        }
    })
    .await
}

fn view_of<K: SessionKind>(
    id: &str,
    data: &[u8],
    version: u64,
) -> Result<View<K::View>, ServiceError> {
    let session = Envelope::<K>::decode(data).map_err(|e| match e {
        DecodeError::WrongKind { stored } => ServiceError::NotFound(format!(
            "session '{id}' is a {} session, not {}",
            tag_name(stored),
            K::NAME
        )),
        DecodeError::Other(e) => e,
    })?;
    session.view(id, version, data.len())
}
