//! The in-process session store: one mutex over a map per tenant (a
//! `BTreeMap`, so listing is sorted by id). Expired sessions are invisible at
//! once and removed on access to their tenant, by a sweep of every tenant at
//! most once a second, and before a create or update is refused for memory.
//! Memory is bounded twice: the bytes of every tenant's sessions together
//! (`max_memory_bytes`), and those of each tenant
//! (`max_memory_bytes_per_tenant`), so that one tenant cannot fill the store
//! for all.

use std::{
    collections::{BTreeMap, HashMap},
    sync::{Mutex, MutexGuard},
    time::{Duration, Instant},
};

use super::{
    CasOutcome, Compacted, Expected, SessionMeta, StoreError, StoreSettings, Stored, Write,
};

/// How often, at most, a write sweeps the expired sessions of every tenant.
const SWEEP_EVERY: Duration = Duration::from_secs(1);

pub struct MemoryStore {
    max_sessions_per_tenant: usize,
    max_memory_bytes: usize,
    max_memory_bytes_per_tenant: usize,
    inner: Mutex<Inner>,
}

struct Inner {
    tenants: HashMap<String, Tenant>,
    /// Bytes (snapshot and log) of every entry held (expired ones included until swept).
    bytes: usize,
    last_sweep: Instant,
}

/// One tenant's sessions and the bytes they hold (expired ones included
/// until swept).
#[derive(Default)]
struct Tenant {
    sessions: BTreeMap<String, Entry>,
    bytes: usize,
}

struct Entry {
    version: u64,
    token: u64,
    kind: String,
    /// The snapshot, at `version - log.len()`.
    data: Vec<u8>,
    log: Vec<Vec<u8>>,
    /// The token of the write that appended each log entry.
    log_tokens: Vec<u64>,
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
            max_memory_bytes_per_tenant: settings.max_memory_bytes_per_tenant,
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

    /// Bytes of `tenant`'s session data held now (expired sessions not yet
    /// swept included).
    pub fn tenant_bytes(&self, tenant: &str) -> usize {
        self.lock().tenants.get(tenant).map_or(0, |t| t.bytes)
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
        let live = inner.tenants.get(tenant).map(|t| &t.sessions);
        if live.is_some_and(|m| m.contains_key(id)) {
            return Err(StoreError::AlreadyExists);
        }
        if live.map_or(0, BTreeMap::len) >= self.max_sessions_per_tenant {
            return Err(StoreError::TooManySessions {
                limit: self.max_sessions_per_tenant,
            });
        }
        self.reserve(&mut inner, tenant, now, 0, data.len())?;
        let held = inner.tenants.entry(tenant.to_string()).or_default();
        held.bytes += data.len();
        held.sessions.insert(
            id.to_string(),
            Entry {
                version: 1,
                token: 0,
                kind: kind.to_string(),
                data,
                log: Vec::new(),
                log_tokens: Vec::new(),
                expires_at: expiry(now, ttl),
            },
        );
        Ok(1)
    }

    pub fn version(&self, tenant: &str, id: &str) -> Option<u64> {
        let now = Instant::now();
        let inner = self.lock();
        let e = inner.tenants.get(tenant)?.sessions.get(id)?;
        (e.expires_at > now).then_some(e.version)
    }

    pub fn get(&self, tenant: &str, id: &str) -> Option<Stored> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        let entry = inner.tenants.get(tenant)?.sessions.get(id)?;
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
        let Some(entry) = inner.tenants.get(tenant).and_then(|t| t.sessions.get(id)) else {
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
        self.reserve(&mut inner, tenant, now, old_len, new_len)?;
        let version = expected.version + 1;
        let inner = &mut *inner;
        let held = inner
            .tenants
            .get_mut(tenant)
            .expect("the tenant's entry was live a moment ago under the same lock");
        held.bytes = held.bytes - old_len + new_len;
        let entry = held
            .sessions
            .get_mut(id)
            .expect("the entry was live a moment ago under the same lock");
        entry.version = version;
        entry.token = token;
        match write {
            Write::Snapshot(d) => {
                entry.data = d;
                entry.log.clear();
                entry.log_tokens.clear();
            }
            Write::Append(e) => {
                entry.log.push(e);
                entry.log_tokens.push(token);
            }
        }
        entry.expires_at = expiry(now, ttl);
        Ok(CasOutcome::Stored { version })
    }

    /// See [`crate::SessionStore::compact`].
    pub fn compact(
        &self,
        tenant: &str,
        id: &str,
        at: u64,
        token: u64,
        data: Vec<u8>,
    ) -> Result<Compacted, StoreError> {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        let Some(entry) = inner.tenants.get(tenant).and_then(|t| t.sessions.get(id)) else {
            return Ok(Compacted::Missing);
        };
        let base = entry.version - entry.log.len() as u64;
        if at <= base || at > entry.version || entry.log_tokens[(at - base - 1) as usize] != token {
            return Ok(Compacted::Stale);
        }
        let folded = (at - base) as usize;
        let old_len = entry.bytes();
        let new_len = data.len() + entry.log[folded..].iter().map(Vec::len).sum::<usize>();
        self.reserve(&mut inner, tenant, now, old_len, new_len)?;
        let held = inner
            .tenants
            .get_mut(tenant)
            .expect("the tenant's entry was live a moment ago under the same lock");
        held.bytes = held.bytes - old_len + new_len;
        let entry = held
            .sessions
            .get_mut(id)
            .expect("the entry was live a moment ago under the same lock");
        entry.data = data;
        entry.log.drain(..folded);
        entry.log_tokens.drain(..folded);
        Ok(Compacted::Stored)
    }

    pub fn delete(&self, tenant: &str, id: &str) -> bool {
        let now = Instant::now();
        let mut inner = self.lock();
        inner.prune_tenant(tenant, now);
        let Some(held) = inner.tenants.get_mut(tenant) else {
            return false;
        };
        let removed = held.sessions.remove(id);
        if let Some(entry) = &removed {
            held.bytes -= entry.bytes();
        }
        if held.sessions.is_empty() {
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
        inner.tenants.get(tenant).map_or_else(Vec::new, |held| {
            held.sessions
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

    /// Accounts in the store's total for replacing `old_len` bytes of
    /// `tenant` by `new_len` (the caller updates the tenant's own count
    /// when it stores them), sweeping every tenant's expired sessions first
    /// when a bound would be exceeded. The tenant's bound is checked first:
    /// a tenant over its share is told so, whatever the others hold.
    fn reserve(
        &self,
        inner: &mut Inner,
        tenant: &str,
        now: Instant,
        old_len: usize,
        new_len: usize,
    ) -> Result<(), StoreError> {
        let tenant_fits = |inner: &Inner| {
            let held = inner.tenants.get(tenant).map_or(0, |t| t.bytes);
            held - old_len + new_len <= self.max_memory_bytes_per_tenant
        };
        let fits = |inner: &Inner| inner.bytes - old_len + new_len <= self.max_memory_bytes;
        if !tenant_fits(inner) {
            // Its own expired sessions were pruned by the caller.
            return Err(StoreError::TenantMemoryFull {
                limit_bytes: self.max_memory_bytes_per_tenant,
            });
        }
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
        let Some(held) = self.tenants.get_mut(tenant) else {
            return;
        };
        let freed = prune(&mut held.sessions, now);
        held.bytes -= freed;
        self.bytes -= freed;
        if held.sessions.is_empty() {
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
        self.tenants.retain(|_, held| {
            let of_tenant = prune(&mut held.sessions, now);
            held.bytes -= of_tenant;
            freed += of_tenant;
            !held.sessions.is_empty()
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

#[cfg(test)]
mod tests {
    use super::*;

    const LONG: Duration = Duration::from_secs(3600);

    /// A store of at most `total` bytes, `per_tenant` of them per tenant.
    fn store(total: usize, per_tenant: usize) -> MemoryStore {
        MemoryStore::new(&StoreSettings {
            url: "memory".into(),
            redis: Default::default(),
            wait_replicas: 0,
            key_prefix: "test".into(),
            max_sessions_per_tenant: 100,
            max_memory_bytes: total,
            max_memory_bytes_per_tenant: per_tenant,
            timeout: Duration::from_secs(1),
        })
    }

    fn at(version: u64) -> Expected {
        Expected {
            version,
            token: None,
        }
    }

    #[test]
    fn one_tenant_cannot_hold_more_than_its_share_and_others_still_can() {
        let s = store(1_000, 100);
        s.create("a", "x", "k", vec![0; 60], LONG).unwrap();
        // 60 + 41 = 101 > 100: refused, naming the tenant's bound.
        assert_eq!(
            s.create("a", "y", "k", vec![0; 41], LONG),
            Err(StoreError::TenantMemoryFull { limit_bytes: 100 })
        );
        assert_eq!(s.tenant_bytes("a"), 60);
        // Another tenant has its own share: 100 more fit, for 160 in all.
        s.create("b", "x", "k", vec![0; 100], LONG).unwrap();
        assert_eq!(s.bytes(), 160);
        // 60 + 40 = 100: at the bound is allowed.
        s.create("a", "y", "k", vec![0; 40], LONG).unwrap();
        assert_eq!(s.tenant_bytes("a"), 100);
        assert_eq!(s.bytes(), 200);
    }

    #[test]
    fn writes_count_the_difference_against_the_tenant_bound() {
        let s = store(1_000, 100);
        s.create("a", "x", "k", vec![0; 50], LONG).unwrap();
        s.create("a", "y", "k", vec![0; 40], LONG).unwrap();
        // An appended entry of 11 bytes: 101 > 100.
        assert_eq!(
            s.write("a", "x", at(1), 1, Write::Append(vec![0; 11]), LONG),
            Err(StoreError::TenantMemoryFull { limit_bytes: 100 })
        );
        assert_eq!(
            s.version("a", "x"),
            Some(1),
            "a refused write changes nothing"
        );
        assert_eq!(
            s.write("a", "x", at(1), 1, Write::Append(vec![0; 10]), LONG),
            Ok(CasOutcome::Stored { version: 2 })
        );
        assert_eq!(s.tenant_bytes("a"), 100);
        // A snapshot of 20 replaces the 50 + 10 of x: 40 + 20 = 60.
        assert_eq!(
            s.write("a", "x", at(2), 2, Write::Snapshot(vec![0; 20]), LONG),
            Ok(CasOutcome::Stored { version: 3 })
        );
        assert_eq!(s.tenant_bytes("a"), 60);
        assert_eq!(s.bytes(), 60);
        // A delete gives its bytes back to the tenant and the store.
        assert!(s.delete("a", "y"));
        assert_eq!(s.tenant_bytes("a"), 20);
        assert_eq!(s.bytes(), 20);
        assert!(s.delete("a", "x"));
        assert_eq!(s.tenant_bytes("a"), 0);
        assert_eq!(s.bytes(), 0);
    }

    #[test]
    fn a_tenants_expired_sessions_do_not_count_against_it() {
        let s = store(1_000, 100);
        // A time-to-live of zero: expired as soon as it is stored.
        s.create("a", "old", "k", vec![0; 100], Duration::ZERO)
            .unwrap();
        s.create("a", "new", "k", vec![0; 100], LONG).unwrap();
        assert_eq!(s.tenant_bytes("a"), 100);
        assert_eq!(s.bytes(), 100);
    }

    #[test]
    fn the_total_bound_still_holds_when_every_tenant_is_within_its_share() {
        let s = store(150, 100);
        s.create("a", "x", "k", vec![0; 100], LONG).unwrap();
        // b is within its 100, the store is not: 100 + 51 > 150.
        assert_eq!(
            s.create("b", "x", "k", vec![0; 51], LONG),
            Err(StoreError::MemoryFull { limit_bytes: 150 })
        );
        assert_eq!(s.tenant_bytes("b"), 0);
        s.create("b", "x", "k", vec![0; 50], LONG).unwrap();
        assert_eq!(s.bytes(), 150);
    }
}
