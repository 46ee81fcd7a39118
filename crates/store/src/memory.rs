//! The in-process session store: one mutex over a map per tenant (a
//! `BTreeMap`, so listing is sorted by id). Expired sessions are invisible at
//! once and removed on access to their tenant, by a sweep of every tenant at
//! most once a second, and before a create or update is refused for memory.

use std::{
    collections::{BTreeMap, HashMap},
    sync::{Mutex, MutexGuard},
    time::{Duration, Instant},
};

use super::{CasOutcome, Expected, SessionMeta, StoreError, StoreSettings, Stored, Write};

/// How often, at most, a write sweeps the expired sessions of every tenant.
const SWEEP_EVERY: Duration = Duration::from_secs(1);

pub struct MemoryStore {
    max_sessions_per_tenant: usize,
    max_memory_bytes: usize,
    inner: Mutex<Inner>,
}

struct Inner {
    tenants: HashMap<String, BTreeMap<String, Entry>>,
    /// Bytes (snapshot and log) of every entry held (expired ones included until swept).
    bytes: usize,
    last_sweep: Instant,
}

struct Entry {
    version: u64,
    token: u64,
    kind: String,
    /// The snapshot, at `version - log.len()`.
    data: Vec<u8>,
    log: Vec<Vec<u8>>,
    expires_at: Instant,
}

impl Entry {
    fn bytes(&self) -> usize {
        self.data.len() + self.log.iter().map(Vec::len).sum::<usize>()
    }
}

impl MemoryStore {
    pub fn new(settings: &StoreSettings) -> Self {
        Self {
            max_sessions_per_tenant: settings.max_sessions_per_tenant,
            max_memory_bytes: settings.max_memory_bytes,
            inner: Mutex::new(Inner {
                tenants: HashMap::new(),
                bytes: 0,
                last_sweep: Instant::now(),
            }),
        }
    }

    /// Bytes of session data held now (expired sessions not yet swept included).
    pub fn bytes(&self) -> usize {
        self.lock().bytes
    }

    pub fn create(
        &self,
        tenant: &str,
        id: &str,
        kind: &str,
        data: Vec<u8>,
        ttl: Duration,
    ) -> Result<u64, StoreError> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.maybe_sweep(now);
        inner.prune_tenant(tenant, now);
        let live = inner.tenants.get(tenant);
        if live.is_some_and(|m| m.contains_key(id)) {
            return Err(StoreError::AlreadyExists);
        }
        if live.map_or(0, BTreeMap::len) >= self.max_sessions_per_tenant {
            return Err(StoreError::TooManySessions {
                limit: self.max_sessions_per_tenant,
            });
        }
        self.reserve(&mut inner, now, 0, data.len())?;
        inner.tenants.entry(tenant.to_string()).or_default().insert(
            id.to_string(),
            Entry {
                version: 1,
                token: 0,
                kind: kind.to_string(),
                data,
                log: Vec::new(),
                expires_at: expiry(now, ttl),
            },
        );
        Ok(1)
    }

    pub fn version(&self, tenant: &str, id: &str) -> Option<u64> {
        let now = Instant::now();
        let inner = self.lock();
        let e = inner.tenants.get(tenant)?.get(id)?;
        (e.expires_at > now).then_some(e.version)
    }

    pub fn get(&self, tenant: &str, id: &str) -> Option<Stored> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        let entry = inner.tenants.get(tenant)?.get(id)?;
        Some(Stored {
            version: entry.version,
            token: entry.token,
            data: entry.data.clone(),
            log: entry.log.clone(),
        })
    }

    pub fn write(
        &self,
        tenant: &str,
        id: &str,
        expected: Expected,
        token: u64,
        write: Write,
        ttl: Duration,
    ) -> Result<CasOutcome, StoreError> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.maybe_sweep(now);
        inner.prune_tenant(tenant, now);
        let Some(entry) = inner.tenants.get(tenant).and_then(|m| m.get(id)) else {
            return Ok(CasOutcome::Missing);
        };
        if entry.version != expected.version || expected.token.is_some_and(|t| t != entry.token) {
            return Ok(CasOutcome::Conflict {
                current: entry.version,
            });
        }
        let old_len = entry.bytes();
        let new_len = match &write {
            Write::Snapshot(d) => d.len(),
            Write::Append(e) => old_len + e.len(),
        };
        self.reserve(&mut inner, now, old_len, new_len)?;
        let version = expected.version + 1;
        let inner = &mut *inner;
        let entry = inner
            .tenants
            .get_mut(tenant)
            .and_then(|m| m.get_mut(id))
            .expect("the entry was live a moment ago under the same lock");
        entry.version = version;
        entry.token = token;
        match write {
            Write::Snapshot(d) => {
                entry.data = d;
                entry.log.clear();
            }
            Write::Append(e) => entry.log.push(e),
        }
        entry.expires_at = expiry(now, ttl);
        Ok(CasOutcome::Stored { version })
    }

    pub fn delete(&self, tenant: &str, id: &str) -> bool {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        let Some(sessions) = inner.tenants.get_mut(tenant) else {
            return false;
        };
        let removed = sessions.remove(id);
        if sessions.is_empty() {
            inner.tenants.remove(tenant);
        }
        match removed {
            Some(entry) => {
                inner.bytes -= entry.bytes();
                true
            }
            None => false,
        }
    }

    pub fn list(&self, tenant: &str) -> Vec<SessionMeta> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        inner.tenants.get(tenant).map_or_else(Vec::new, |sessions| {
            sessions
                .iter()
                .map(|(id, e)| SessionMeta {
                    id: id.clone(),
                    version: e.version,
                    kind: e.kind.clone(),
                    bytes: e.bytes(),
                    ttl_remaining: e.expires_at.saturating_duration_since(now),
                })
                .collect()
        })
    }

    /// Accounts for replacing `old_len` bytes by `new_len`, sweeping every
    /// tenant's expired sessions first when the bound would be exceeded.
    fn reserve(
        &self,
        inner: &mut Inner,
        now: Instant,
        old_len: usize,
        new_len: usize,
    ) -> Result<(), StoreError> {
        let fits = |inner: &Inner| inner.bytes - old_len + new_len <= self.max_memory_bytes;
        if !fits(inner) {
            inner.sweep(now);
            if !fits(inner) {
                return Err(StoreError::MemoryFull {
                    limit_bytes: self.max_memory_bytes,
                });
            }
        }
        inner.bytes = inner.bytes - old_len + new_len;
        Ok(())
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        // A panic while holding the lock cannot leave the map half-updated in a
        // way that matters more than losing every session, so keep serving.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Inner {
    /// Removes the expired sessions of one tenant.
    fn prune_tenant(&mut self, tenant: &str, now: Instant) {
        let Some(sessions) = self.tenants.get_mut(tenant) else {
            return;
        };
        self.bytes -= prune(sessions, now);
        if sessions.is_empty() {
            self.tenants.remove(tenant);
        }
    }

    fn maybe_sweep(&mut self, now: Instant) {
        if now.duration_since(self.last_sweep) >= SWEEP_EVERY {
            self.sweep(now);
        }
    }

    /// Removes the expired sessions of every tenant.
    fn sweep(&mut self, now: Instant) {
        let mut freed = 0;
        self.tenants.retain(|_, sessions| {
            freed += prune(sessions, now);
            !sessions.is_empty()
        });
        self.bytes -= freed;
        self.last_sweep = now;
    }
}

/// Removes the expired entries; returns the bytes they held.
fn prune(sessions: &mut BTreeMap<String, Entry>, now: Instant) -> usize {
    let mut freed = 0;
    sessions.retain(|_, e| {
        let live = e.expires_at > now;
        if !live {
            freed += e.bytes();
        }
        live
    });
    freed
}

fn expiry(now: Instant, ttl: Duration) -> Instant {
    // A TTL too large for `Instant` (centuries) means "practically never".
    now.checked_add(ttl)
        .or_else(|| now.checked_add(Duration::from_secs(100 * 365 * 24 * 3600)))
        .unwrap_or(now)
}
