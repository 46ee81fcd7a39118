//! Sessions over the store: create, read, list, delete and push a batch.
//! Every write is a compare-and-set on the session's version, retried on
//! conflict from a fresh read, so two replicas pushing to one session never
//! lose or double an update; a batch whose sequence number was applied
//! already is acknowledged without being applied again. The session is
//! decoded, changed and encoded on a copy: a failed request leaves the stored
//! session as it was.

use std::{
    sync::Arc,
    time::{Duration, SystemTime, UNIX_EPOCH},
};

use super::{
    ServiceError, offload,
    session::{BatchInput, BatchUpdate, Limits, Session, SessionSpec, SessionView},
};
use crate::store::{CasOutcome, SessionMeta, SessionStore, StoreError};

/// How many times a push re-reads the session after losing a race.
const MAX_ATTEMPTS: usize = 32;

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

fn ttl(s: &Session) -> Duration {
    Duration::from_secs_f64(s.idle_expiry_s())
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

pub async fn create(
    store: &SessionStore,
    tenant: &str,
    spec: SessionSpec,
) -> Result<SessionView, ServiceError> {
    let session = Session::create(spec, unix_ms())?;
    let data = session.encode();
    let id = new_id();
    let bytes = data.len();
    let version = store.create(tenant, &id, data, ttl(&session)).await?;
    session.view(&id, version, bytes)
}

pub async fn get(
    store: &SessionStore,
    tenant: &str,
    id: &str,
) -> Result<SessionView, ServiceError> {
    check_id(id)?;
    let stored = store.get(tenant, id).await?.ok_or_else(|| not_found(id))?;
    let id = id.to_string();
    offload(move || {
        let session = Session::decode(&stored.data)?;
        session.view(&id, stored.version, stored.data.len())
    })
    .await
}

pub async fn list(store: &SessionStore, tenant: &str) -> Result<Vec<SessionMeta>, ServiceError> {
    Ok(store.list(tenant).await?)
}

pub async fn delete(store: &SessionStore, tenant: &str, id: &str) -> Result<(), ServiceError> {
    check_id(id)?;
    if store.delete(tenant, id).await? {
        Ok(())
    } else {
        Err(not_found(id))
    }
}

/// Applies one batch with compare-and-set, retrying on a lost race.
pub async fn push(
    store: &SessionStore,
    tenant: &str,
    id: &str,
    batch: BatchInput,
    limits: Limits,
) -> Result<BatchUpdate, ServiceError> {
    check_id(id)?;
    if batch.reports.len() > limits.max_batch_reports {
        return Err(ServiceError::TooLarge(format!(
            "the batch holds {} reports; the limit is {} per batch",
            batch.reports.len(),
            limits.max_batch_reports
        )));
    }
    let batch = Arc::new(batch);
    for attempt in 0..MAX_ATTEMPTS {
        let stored = store.get(tenant, id).await?.ok_or_else(|| not_found(id))?;
        let version = stored.version;
        let (batch2, id2) = (Arc::clone(&batch), id.to_string());
        let outcome = offload(move || {
            let mut session = Session::decode(&stored.data)?;
            if session.check_sequence(batch2.sequence)? {
                let sequence = batch2.sequence.unwrap_or_default();
                return Ok(Err(session.duplicate_ack(&id2, sequence, version)));
            }
            let update = session.apply(&id2, (*batch2).clone(), &limits)?;
            Ok(Ok((update, session.encode(), ttl(&session))))
        })
        .await?;
        let (mut update, data, ttl) = match outcome {
            Err(duplicate) => return Ok(duplicate),
            Ok(applied) => applied,
        };
        match store
            .compare_and_set(tenant, id, version, data, ttl)
            .await?
        {
            CasOutcome::Stored { version } => {
                update.version = version;
                return Ok(update);
            }
            CasOutcome::Missing => return Err(not_found(id)),
            CasOutcome::Conflict { .. } => {
                metrics::counter!("fusion_session_cas_conflicts_total").increment(1);
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
