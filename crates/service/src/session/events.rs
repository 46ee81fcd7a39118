//! Watching a session: every committed batch update, in version order, to
//! any number of watchers on any replica.
//!
//! - A push publishes its update after the store confirmed the write (so a
//!   watcher never sees an update that was not committed), a delete a
//!   `deleted` event. With the Redis store the event goes through Redis
//!   pub/sub ([`store::events`]) and reaches every replica whose watchers
//!   follow the session; with the memory store it is handed to this
//!   process's watchers directly.
//! - Each replica keeps, per watched session, a broadcast channel (bounded:
//!   a watcher that falls [`WatchLimits::buffer`] events behind is dropped
//!   with an `end` of reason `slow`, so memory never grows with a slow
//!   reader) and the last [`WatchLimits::history`] events, from which a
//!   watcher resumes after a reconnect (`Last-Event-ID`).
//! - A watcher delivers versions in order. Pub/sub delivers at most once and
//!   two replicas' publications of consecutive versions may cross, so a
//!   watcher holds an event that skips ahead for up to [`GAP_WAIT`]; a gap
//!   still open then, a lost subscription (a Redis reconnect) or a stored
//!   version ahead of the last event seen at a heartbeat is filled with a
//!   fresh `snapshot` of the stored session: the store is the truth, the
//!   events say when to look.
//! - Expiry is found at the heartbeat: the stored session is gone, an `end`
//!   of reason `expired` (or `deleted`, when the delete event arrived).

use std::{
    collections::{BTreeMap, HashMap, VecDeque},
    sync::{Arc, Mutex, MutexGuard},
    time::{Duration, Instant},
};

use tokio::sync::{broadcast, watch};
use wire_formats::wire::{FormatError, Reader, Writer};

use super::{
    PlotMark, SessionKind, Update,
    registry::{AnyView, EventBody, KindName, KindVisitor, Registered},
};

/// First byte of an event's encoding.
const EVENT_FORMAT: u8 = 1;
/// Kind tag of a delete event (no kind uses 0).
const DELETED_TAG: u8 = 0;
/// How long a watcher holds an event that skips a version, waiting for the
/// missing one, before it reads a snapshot instead.
pub const GAP_WAIT: Duration = Duration::from_millis(500);
/// How long a replica keeps a session's channel and history after its last
/// watcher left, so that a reconnecting watcher can resume from it.
pub const HISTORY_GRACE: Duration = Duration::from_secs(60);

/// Bounds on watching, from the service settings.
#[derive(Debug, Clone, Copy)]
pub struct WatchLimits {
    /// Most watchers of one session on one replica.
    pub per_session: usize,
    /// Most watchers of one tenant on one replica.
    pub per_tenant: usize,
    /// Events a watcher may fall behind before it is dropped.
    pub buffer: usize,
    /// Events kept per watched session for resuming.
    pub history: usize,
    /// Interval of heartbeats (and of the check that the session lives).
    pub heartbeat: Duration,
}

impl Default for WatchLimits {
    fn default() -> Self {
        Self {
            per_session: 32,
            per_tenant: 128,
            buffer: 256,
            history: 64,
            heartbeat: Duration::from_secs(15),
        }
    }
}

/// One event of one session.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionEvent {
    pub tenant: String,
    pub id: String,
    /// The session's version after the update (0 for `Deleted`).
    pub version: u64,
    pub body: EventBody,
}

/// Encodes the event of an update of kind `K` (its version set).
pub fn encode_update<K: SessionKind>(
    tenant: &str,
    update: &Update<K::Update>,
    plots: &[PlotMark],
) -> Vec<u8> {
    let mut w = head(tenant, &update.session_id, update.version, K::TAG);
    w.opt(update.sequence, Writer::u64);
    w.usize(update.warnings.len());
    update.warnings.iter().for_each(|s| w.str(s));
    K::encode_update(&update.body, &mut w);
    w.usize(plots.len());
    for p in plots {
        w.u32(p.radar);
        w.f64(p.t);
        p.position.iter().for_each(|&x| w.f64(x));
    }
    w.buf
}

/// Encodes the delete event of a session.
pub fn encode_deleted(tenant: &str, id: &str) -> Vec<u8> {
    head(tenant, id, 0, DELETED_TAG).buf
}

fn head(tenant: &str, id: &str, version: u64, tag: u8) -> Writer {
    let mut w = Writer::default();
    w.u8(EVENT_FORMAT);
    w.str(tenant);
    w.str(id);
    w.u64(version);
    w.u8(tag);
    w
}

/// Reads what [`encode_update`] or [`encode_deleted`] wrote.
pub fn decode(buf: &[u8]) -> Result<SessionEvent, FormatError> {
    let mut r = Reader::new(buf);
    let format = r.u8()?;
    if format != EVENT_FORMAT {
        return Err(wire_formats::wire::corrupt(&format!(
            "session event format {format}"
        )));
    }
    let tenant = r.str()?;
    let id = r.str()?;
    let version = r.u64()?;
    let tag = r.u8()?;
    let body = if tag == DELETED_TAG {
        EventBody::Deleted
    } else {
        let sequence = r.opt(Reader::u64)?;
        let n = r.len(8)?;
        let warnings = (0..n).map(|_| r.str()).collect::<Result<Vec<_>, _>>()?;
        let kind = KindName::from_tag(tag).ok_or_else(|| {
            wire_formats::wire::corrupt(&format!("session event of unknown kind {tag}"))
        })?;
        kind.visit(DecodeBody {
            r: &mut r,
            id: &id,
            sequence,
            version,
            warnings,
        })?
    };
    if !r.is_empty() {
        return Err(wire_formats::wire::corrupt(
            "trailing bytes in a session event",
        ));
    }
    Ok(SessionEvent {
        tenant,
        id,
        version,
        body,
    })
}

/// Reads the rest of an update event of a kind (its update, the plot
/// marks), the envelope's fields read before.
struct DecodeBody<'a, 'b> {
    r: &'a mut Reader<'b>,
    id: &'a str,
    sequence: Option<u64>,
    version: u64,
    warnings: Vec<String>,
}

impl KindVisitor for DecodeBody<'_, '_> {
    type Out = Result<EventBody, FormatError>;

    fn visit<K: Registered>(self) -> Self::Out {
        let r = self.r;
        let body = K::decode_update(r)?;
        let n = r.len(36)?;
        let plots = (0..n)
            .map(|_| {
                Ok(PlotMark {
                    radar: r.u32()?,
                    t: r.f64()?,
                    position: [r.f64()?, r.f64()?, r.f64()?],
                })
            })
            .collect::<Result<Vec<_>, FormatError>>()?;
        let update = Update {
            session_id: self.id.to_string(),
            sequence: self.sequence,
            version: self.version,
            duplicate: false,
            body,
            warnings: self.warnings,
        };
        K::event_body(update, plots)
    }
}

/// What a replica's channel of one session carries.
#[derive(Debug, Clone)]
pub(super) enum HubItem {
    Event(Arc<SessionEvent>),
    /// Events may have been lost (the Redis subscription was re-made).
    Resync,
}

struct Channel {
    tx: broadcast::Sender<HubItem>,
    /// The last events, by version (updates only).
    history: BTreeMap<u64, Arc<SessionEvent>>,
    watchers: usize,
    /// When the last watcher left (for [`HISTORY_GRACE`]).
    idle_since: Option<Instant>,
    /// Its Redis channel, when subscribed.
    subscribed: Option<String>,
}

type Key = (String, String);

struct HubState {
    channels: HashMap<Key, Channel>,
    tenants: HashMap<String, usize>,
    /// Channels whose last watcher left, oldest first, with the time it
    /// left: the purge of channels idle past [`HISTORY_GRACE`] pops them
    /// from the front, so it costs what it removes, not the number of
    /// channels (it scanned every channel at every join). An entry whose
    /// channel has gone or has watchers again, or went idle again later
    /// (its `idle_since` differs), is dropped as it comes out.
    idle: VecDeque<(Instant, Key)>,
}

impl HubState {
    /// Removes the channels idle past [`HISTORY_GRACE`] at `now`, and
    /// hands back their Redis channels to unsubscribe from; returns the
    /// number of idle entries it looked at.
    fn purge_idle(&mut self, now: Instant, unsubscribe: &mut Vec<String>) -> usize {
        let mut examined = 0;
        while let Some((since, _)) = self.idle.front() {
            if now.saturating_duration_since(*since) <= HISTORY_GRACE {
                break;
            }
            examined += 1;
            let Some((since, key)) = self.idle.pop_front() else {
                break;
            };
            let idle_then = self
                .channels
                .get(&key)
                .is_some_and(|c| c.watchers == 0 && c.idle_since == Some(since));
            if idle_then
                && let Some(c) = self.channels.remove(&key)
                && let Some(name) = c.subscribed
            {
                unsubscribe.push(name);
            }
        }
        examined
    }
}

/// This replica's side of session events: channels per watched session and
/// the Redis listener (for the Redis store).
pub struct EventHub {
    state: Mutex<HubState>,
    limits: WatchLimits,
    listener: Option<store::events::EventListener>,
    /// Ends every watch (the service is shutting down).
    shutdown: watch::Sender<bool>,
}

/// Why a watch ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EndReason {
    Deleted,
    Expired,
    /// The watcher fell this many events behind.
    Slow(u64),
    Shutdown,
}

impl EndReason {
    pub fn name(self) -> &'static str {
        match self {
            Self::Deleted => "deleted",
            Self::Expired => "expired",
            Self::Slow(_) => "slow",
            Self::Shutdown => "shutdown",
        }
    }

    pub fn message(self, heartbeat: Duration) -> String {
        match self {
            Self::Deleted => "the session was deleted".into(),
            Self::Expired => "the session expired (or was deleted) and is gone".into(),
            Self::Slow(n) => format!(
                "this watcher fell {n} events behind and was dropped; reconnect with \
                 Last-Event-ID to resume (or read a fresh snapshot)"
            ),
            Self::Shutdown => format!(
                "this replica is shutting down; reconnect (another replica serves the same \
                 session; heartbeats every {} s)",
                heartbeat.as_secs_f64()
            ),
        }
    }
}

/// What a watcher is shown next.
#[derive(Debug, Clone)]
pub enum WatchItem {
    /// The whole session at its version (first, or to fill a gap).
    Snapshot(Box<AnyView>),
    /// One batch update, the next version after the last item.
    Update(Arc<SessionEvent>),
    /// Nothing happened for a heartbeat interval; the session lives.
    Heartbeat,
    /// The last item: the watch is over.
    End { reason: EndReason, version: u64 },
}

impl EventHub {
    /// A hub over `store`: with Redis, starts its listener task (so this is
    /// called inside the runtime) and the task that hands the feed on.
    pub fn new(store: &store::SessionStore, limits: WatchLimits) -> Arc<Self> {
        let (shutdown, _) = watch::channel(false);
        let listened = if tokio::runtime::Handle::try_current().is_ok() {
            store.listen(limits.buffer.max(64) * 4)
        } else {
            // Built outside a runtime (a unit test): no listener, so only
            // this process's events reach its watchers.
            None
        };
        let (listener, feed) = match listened {
            Some((l, f)) => (Some(l), Some(f)),
            None => (None, None),
        };
        let hub = Arc::new(Self {
            state: Mutex::new(HubState {
                channels: HashMap::new(),
                tenants: HashMap::new(),
                idle: VecDeque::new(),
            }),
            limits,
            listener,
            shutdown,
        });
        if let Some(mut feed) = feed {
            let weak = Arc::downgrade(&hub);
            tokio::spawn(async move {
                while let Some(item) = feed.recv().await {
                    let Some(hub) = weak.upgrade() else { return };
                    match item {
                        store::events::Feed::Message(bytes) => match decode(&bytes) {
                            Ok(event) => hub.deliver(event),
                            Err(e) => {
                                metrics::counter!("fusion_session_events_total", "outcome" => "undecodable")
                                    .increment(1);
                                tracing::warn!(error = %e, "a session event did not decode");
                            }
                        },
                        store::events::Feed::Resync => {
                            metrics::counter!("fusion_session_event_resyncs_total").increment(1);
                            hub.resync();
                        }
                    }
                }
            });
        }
        hub
    }

    pub fn limits(&self) -> WatchLimits {
        self.limits
    }

    fn lock(&self) -> MutexGuard<'_, HubState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Whether this replica has a channel of the session (a watcher now or
    /// within [`HISTORY_GRACE`]).
    pub fn watched(&self, tenant: &str, id: &str) -> bool {
        self.lock()
            .channels
            .contains_key(&(tenant.to_string(), id.to_string()))
    }

    /// Hands an event to the session's channel on this replica (if any).
    pub fn deliver(&self, event: SessionEvent) {
        let event = Arc::new(event);
        let mut state = self.lock();
        let key = (event.tenant.clone(), event.id.clone());
        let Some(channel) = state.channels.get_mut(&key) else {
            return;
        };
        metrics::counter!("fusion_session_events_total", "outcome" => "delivered").increment(1);
        if !matches!(event.body, EventBody::Deleted) {
            channel.history.insert(event.version, Arc::clone(&event));
            while channel.history.len() > self.limits.history {
                channel.history.pop_first();
            }
        }
        let _ = channel.tx.send(HubItem::Event(event));
    }

    fn resync(&self) {
        for channel in self.lock().channels.values_mut() {
            channel.history.clear();
            let _ = channel.tx.send(HubItem::Resync);
        }
    }

    /// Ends every watch on this replica (shutdown).
    pub fn close(&self) {
        let _ = self.shutdown.send(true);
    }

    /// Registers a watcher of the session: `Err` names the cap reached.
    /// `channel`: the session's Redis channel (the Redis store).
    pub(super) fn join(
        self: &Arc<Self>,
        tenant: &str,
        id: &str,
        channel: Option<String>,
    ) -> Result<Joined, String> {
        let mut state = self.lock();
        // Channels idle past the grace period go, with their subscription.
        let mut stale = Vec::new();
        state.purge_idle(Instant::now(), &mut stale);
        if let Some(l) = &self.listener {
            for name in stale {
                l.unsubscribe(name);
            }
        }
        let of_tenant = state.tenants.get(tenant).copied().unwrap_or(0);
        if of_tenant >= self.limits.per_tenant {
            return Err(format!(
                "the tenant has {of_tenant} watchers on this replica, the most allowed \
                 (watch.max_per_tenant): close one"
            ));
        }
        let key = (tenant.to_string(), id.to_string());
        let subscribe = match (&self.listener, channel) {
            (Some(_), Some(c)) if !state.channels.contains_key(&key) => Some(c),
            _ => None,
        };
        let channel = state
            .channels
            .entry(key.clone())
            .or_insert_with(|| Channel {
                tx: broadcast::channel(self.limits.buffer.max(1)).0,
                history: BTreeMap::new(),
                watchers: 0,
                idle_since: None,
                subscribed: subscribe.clone(),
            });
        if channel.watchers >= self.limits.per_session {
            return Err(format!(
                "the session has {} watchers on this replica, the most allowed \
                 (watch.max_per_session): close one",
                channel.watchers
            ));
        }
        channel.watchers += 1;
        channel.idle_since = None;
        let rx = channel.tx.subscribe();
        let history: Vec<Arc<SessionEvent>> = channel.history.values().cloned().collect();
        *state.tenants.entry(tenant.to_string()).or_default() += 1;
        drop(state);
        if let (Some(l), Some(c)) = (&self.listener, subscribe) {
            l.subscribe(c);
        }
        metrics::gauge!("fusion_session_watchers").increment(1.0);
        Ok(Joined {
            rx,
            history,
            shutdown: self.shutdown.subscribe(),
            guard: Guard {
                hub: Arc::clone(self),
                key,
                forget: false,
            },
        })
    }

    /// Counts a watcher out. `forget`: a channel left without watchers and
    /// without history goes at once, with its subscription, instead of
    /// after [`HISTORY_GRACE`] (a watch that failed as it started).
    fn leave(&self, key: &Key, forget: bool) {
        let mut guard = self.lock();
        let state = &mut *guard;
        if let Some(c) = state.channels.get_mut(key) {
            c.watchers = c.watchers.saturating_sub(1);
            if c.watchers == 0 {
                let now = Instant::now();
                c.idle_since = Some(now);
                state.idle.push_back((now, key.clone()));
                if forget
                    && c.history.is_empty()
                    && let Some(c) = state.channels.remove(key)
                    && let (Some(l), Some(name)) = (&self.listener, c.subscribed)
                {
                    l.unsubscribe(name);
                }
            }
        }
        if let Some(n) = state.tenants.get_mut(&key.0) {
            *n = n.saturating_sub(1);
            if *n == 0 {
                state.tenants.remove(&key.0);
            }
        }
        metrics::gauge!("fusion_session_watchers").decrement(1.0);
    }
}

/// Decrements the watcher counts when a watch ends, however it ends.
pub(super) struct Guard {
    hub: Arc<EventHub>,
    key: Key,
    forget: bool,
}

impl Guard {
    /// Leaves at once for a watch that did not start (its session is
    /// gone): a channel this watch made is removed, not kept for resuming.
    pub(super) fn abandon(mut self) {
        self.forget = true;
    }
}

impl Drop for Guard {
    fn drop(&mut self) {
        self.hub.leave(&self.key, self.forget);
    }
}

pub(super) struct Joined {
    pub rx: broadcast::Receiver<HubItem>,
    /// The events held for resuming, by version.
    pub history: Vec<Arc<SessionEvent>>,
    pub shutdown: watch::Receiver<bool>,
    /// Keeps the watcher counted until dropped.
    pub guard: Guard,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::session::correlation::BatchUpdate;
    use crate::session::correlation::CorrelationSession;

    /// The purge of idle channels looks at the entries past the grace
    /// period only (before, every join scanned every channel), and removes
    /// only a channel still idle since the time of its entry.
    #[test]
    fn the_purge_of_idle_channels_costs_what_it_removes() {
        let t0 = Instant::now();
        let second = Duration::from_secs(1);
        let channel = |name: &str, watchers: usize, idle_since: Option<Instant>| Channel {
            tx: broadcast::channel(1).0,
            history: BTreeMap::new(),
            watchers,
            idle_since,
            subscribed: Some(format!("ch:{name}")),
        };
        let key = |name: &str| ("t".to_string(), name.to_string());
        let mut state = HubState {
            channels: HashMap::new(),
            tenants: HashMap::new(),
            idle: VecDeque::new(),
        };
        // Left at t0: "gone" still idle, "back" watched again, "again"
        // watched again and left at t0 + 2 s.
        state
            .channels
            .insert(key("gone"), channel("gone", 0, Some(t0)));
        state.channels.insert(key("back"), channel("back", 1, None));
        state
            .channels
            .insert(key("again"), channel("again", 0, Some(t0 + 2 * second)));
        for name in ["gone", "back", "again"] {
            state.idle.push_back((t0, key(name)));
        }
        // 10,000 channels left at t0 + 1 s.
        for i in 0..10_000 {
            let name = format!("many{i}");
            state
                .channels
                .insert(key(&name), channel(&name, 0, Some(t0 + second)));
            state.idle.push_back((t0 + second, key(&name)));
        }
        state.idle.push_back((t0 + 2 * second, key("again")));

        let mut names = Vec::new();
        let half = Duration::from_millis(500);
        assert_eq!(state.purge_idle(t0 + HISTORY_GRACE + half, &mut names), 3);
        assert_eq!(names, ["ch:gone"]);
        assert_eq!(state.channels.len(), 10_002);
        // Nothing else is due: nothing is looked at.
        assert_eq!(state.purge_idle(t0 + HISTORY_GRACE + half, &mut names), 0);
        assert_eq!(
            state.purge_idle(t0 + HISTORY_GRACE + second + half, &mut names),
            10_000
        );
        assert_eq!(state.channels.len(), 2);
        assert_eq!(
            state.purge_idle(t0 + HISTORY_GRACE + 2 * second + half, &mut names),
            1
        );
        assert_eq!(names.last().map(String::as_str), Some("ch:again"));
        assert_eq!(state.channels.keys().collect::<Vec<_>>(), [&key("back")]);
        assert!(state.idle.is_empty());
    }

    /// A correlation session's update event reads back (it once failed
    /// with "trailing bytes": the plot marks written for every kind were
    /// read for plot fusion only, so watchers of correlation sessions got
    /// no updates).
    #[test]
    fn a_correlation_update_event_round_trips() {
        let update = Update {
            session_id: "s1".to_string(),
            sequence: Some(3),
            version: 4,
            duplicate: false,
            body: BatchUpdate {
                instants: vec![1.5, 2.5],
                pending_reports: 2,
                changes: Vec::new(),
                pairs: Vec::new(),
                system_tracks: Vec::new(),
                retired: Vec::new(),
            },
            warnings: vec!["w".to_string()],
        };
        let bytes = encode_update::<CorrelationSession>("t", &update, &[]);
        let event = decode(&bytes).unwrap();
        assert_eq!((event.tenant.as_str(), event.version), ("t", 4));
        match event.body {
            EventBody::Correlation(u) => {
                assert_eq!(u.body, update.body);
                assert_eq!(u.sequence, Some(3));
                assert_eq!(u.warnings, update.warnings);
            }
            other => panic!("{other:?}"),
        }
    }
}
