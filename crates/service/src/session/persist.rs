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
    sync::Arc,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use super::{
    Admission, Batch, DecodeError, Envelope, KindName, Limits, SessionKind, Spec, Update, View,
    cache::SessionCache, correlation::CorrelationSession, plot_fusion::PlotFusionSession,
    stored_kind, tag_name,
};
use crate::{ServiceError, offload};
use store::{CasOutcome, SessionMeta, SessionStore, StoreError, Stored};

/// How many times a push re-reads the session after losing a race.
const MAX_ATTEMPTS: usize = 32;

/// The session store and the cache of decoded sessions in front of it.
pub struct Sessions {
    store: SessionStore,
    cache: SessionCache,
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
        Self {
            store,
            cache: SessionCache::new(cache_bytes),
        }
    }

    pub fn store(&self) -> &SessionStore {
        &self.store
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
        let id = id.to_string();
        offload(move || {
            let tag = stored_kind(&stored.data)?;
            match KindName::from_tag(tag) {
                Some(KindName::Correlation) => {
                    Ok(AnyView::Correlation(view_of::<CorrelationSession>(
                        &id,
                        &stored.data,
                        stored.version,
                    )?))
                }
                Some(KindName::PlotFusion) => Ok(AnyView::PlotFusion(
                    view_of::<PlotFusionSession>(&id, &stored.data, stored.version)?,
                )),
                None => Err(ServiceError::Internal(format!(
                    "stored session: {} is not served by this release",
                    tag_name(tag)
                ))),
            }
        })
        .await
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
        if self.store.delete(tenant, id).await? {
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
                        let data = session.encode();
                        Ok(Ok((update, data, session)))
                    }
                }
            })
            .await;
            let (mut update, data, session) = match worked {
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
