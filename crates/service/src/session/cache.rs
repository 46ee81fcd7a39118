//! Decoded sessions kept in process between batches, so that a push to a
//! session this replica wrote last needs neither a read of the store nor a
//! decode of the state.
//!
//! The cache is never trusted on its own: an entry holds the version the
//! store had when this replica wrote it, and a push that starts from it
//! writes with a compare-and-set on that version. If any other writer
//! (another replica, or another request here) changed the session since, the
//! compare-and-set fails and the push starts again from a fresh read, exactly
//! as without the cache. An entry is taken out while a push works on it, so
//! two requests never share one decoded state; a failed or uncertain push
//! (an error, a store that did not answer) simply does not put it back.
//!
//! The cache is bounded by the encoded size of what it holds (a proxy for the
//! decoded size); the least recently used entries go first.

use std::{any::Any, collections::HashMap, sync::Mutex};

/// Decoded sessions by (tenant, id).
pub struct SessionCache {
    inner: Mutex<Inner>,
    max_bytes: usize,
}

#[derive(Default)]
struct Inner {
    entries: HashMap<(String, String), Entry>,
    bytes: usize,
    tick: u64,
}

struct Entry {
    version: u64,
    bytes: usize,
    used: u64,
    value: Box<dyn Any + Send>,
}

impl SessionCache {
    /// A cache holding sessions of at most `max_bytes` encoded bytes in
    /// total; 0 disables it.
    pub fn new(max_bytes: usize) -> Self {
        Self {
            inner: Mutex::new(Inner::default()),
            max_bytes,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // A panic while the lock was held cannot leave the map inconsistent
        // (every change is one call), so a poisoned lock is still usable.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes the decoded session out of the cache, with the version it had
    /// when it was put; `None` when absent or of another type.
    pub fn take<T: Any + Send>(&self, tenant: &str, id: &str) -> Option<(u64, T)> {
        if self.max_bytes == 0 {
            return None;
        }
        let mut inner = self.lock();
        let entry = inner
            .entries
            .remove(&(tenant.to_string(), id.to_string()))?;
        inner.bytes -= entry.bytes;
        let version = entry.version;
        entry.value.downcast::<T>().ok().map(|v| (version, *v))
    }

    /// Takes the decoded session `id` if it holds `version`; another
    /// version stays.
    pub fn take_at<T: Any + Send>(&self, tenant: &str, id: &str, version: u64) -> Option<T> {
        if self.max_bytes == 0 {
            return None;
        }
        let mut inner = self.lock();
        let key = (tenant.to_string(), id.to_string());
        if inner.entries.get(&key)?.version != version {
            return None;
        }
        let entry = inner.entries.remove(&key)?;
        inner.bytes -= entry.bytes;
        entry.value.downcast::<T>().ok().map(|v| *v)
    }

    /// Puts a decoded session at `version` (`bytes` its encoded size),
    /// unless a newer version is cached already; evicts the least recently
    /// used entries beyond the bound.
    pub fn put<T: Any + Send>(&self, tenant: &str, id: &str, version: u64, bytes: usize, value: T) {
        if bytes > self.max_bytes {
            return;
        }
        let mut inner = self.lock();
        let key = (tenant.to_string(), id.to_string());
        if inner
            .entries
            .get(&key)
            .is_some_and(|e| e.version >= version)
        {
            return;
        }
        inner.tick += 1;
        let used = inner.tick;
        if let Some(old) = inner.entries.insert(
            key,
            Entry {
                version,
                bytes,
                used,
                value: Box::new(value),
            },
        ) {
            inner.bytes -= old.bytes;
        }
        inner.bytes += bytes;
        while inner.bytes > self.max_bytes {
            let Some(oldest) = inner
                .entries
                .iter()
                .min_by_key(|(_, e)| e.used)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some(e) = inner.entries.remove(&oldest) {
                inner.bytes -= e.bytes;
            }
        }
    }

    /// Drops the entry of a session (deleted, or its state unknown).
    pub fn forget(&self, tenant: &str, id: &str) {
        let mut inner = self.lock();
        if let Some(e) = inner.entries.remove(&(tenant.to_string(), id.to_string())) {
            inner.bytes -= e.bytes;
        }
    }

    /// Entries and encoded bytes held.
    pub fn usage(&self) -> (usize, usize) {
        let inner = self.lock();
        (inner.entries.len(), inner.bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn take_put_version_and_bound() {
        let c = SessionCache::new(100);
        assert!(c.take::<u32>("t", "a").is_none());
        c.put("t", "a", 3, 40, 7u32);
        // Another tenant's session of the same id is another entry.
        assert!(c.take::<u32>("u", "a").is_none());
        // The wrong type is not handed out.
        assert!(c.take::<String>("t", "a").is_none());
        c.put("t", "a", 3, 40, 7u32);
        assert_eq!(c.take::<u32>("t", "a"), Some((3, 7)));
        assert!(c.take::<u32>("t", "a").is_none(), "taken out");
        // An older version does not replace a newer one.
        c.put("t", "a", 5, 40, 1u32);
        c.put("t", "a", 4, 40, 2u32);
        assert_eq!(c.take::<u32>("t", "a"), Some((5, 1)));
        // 40 + 40 + 40 > 100: the least recently put goes.
        c.put("t", "a", 1, 40, 1u32);
        c.put("t", "b", 1, 40, 2u32);
        c.put("t", "c", 1, 40, 3u32);
        assert_eq!(c.usage(), (2, 80));
        assert!(c.take::<u32>("t", "a").is_none());
        c.forget("t", "b");
        assert_eq!(c.usage(), (1, 40));
        // Larger than the whole bound: not kept.
        c.put("t", "d", 1, 101, 4u32);
        assert!(c.take::<u32>("t", "d").is_none());
        // Disabled.
        let off = SessionCache::new(0);
        off.put("t", "a", 1, 0, 1u32);
        assert!(off.take::<u32>("t", "a").is_none());
    }
}
