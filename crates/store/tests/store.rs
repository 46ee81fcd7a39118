//! The session store: one suite run against both backends (memory, and Redis
//! on 127.0.0.1:6379 under a key prefix unique to the run), plus memory-only
//! bounds and a Redis outage-and-recovery test on a redis-server of its own.
//!
//! Redis tests fail loudly when Redis is not running, unless
//! `FUSION_SKIP_REDIS_TESTS=1` is set.

use std::{
    sync::Arc,
    time::{Duration, Instant},
};

use store::{
    CasOutcome, Compacted, Expected, SessionStore, StoreError, StoreSettings, Stored, Write,
};

use test_support::redis::{
    RedisServer, free_port, redis_is_up, redis_server_available, redis_url, unique,
};
const LONG: Duration = Duration::from_secs(60);
/// A TTL short enough to wait out; tests then sleep at least twice as long.
const SHORT: Duration = Duration::from_millis(300);

// ---------------------------------------------------------------- harness

fn settings(url: &str) -> StoreSettings {
    StoreSettings {
        url: url.to_string(),
        key_prefix: unique("radar-fusion-test:"),
        max_sessions_per_tenant: 100,
        redis: Default::default(),
        wait_replicas: 0,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_secs(1),
    }
}

async fn memory(configure: impl FnOnce(&mut StoreSettings)) -> Arc<SessionStore> {
    let mut s = settings("memory");
    configure(&mut s);
    let store = SessionStore::connect(&s).await.expect("memory store");
    assert_eq!(store.backend(), "memory");
    Arc::new(store)
}

/// A Redis store on 127.0.0.1:6379 with a fresh key prefix, or `None` (with a
/// loud warning) when Redis is down and `FUSION_SKIP_REDIS_TESTS=1`.
async fn redis(configure: impl FnOnce(&mut StoreSettings)) -> Option<Arc<SessionStore>> {
    if !redis_is_up() {
        return None;
    }
    let mut s = settings(&redis_url());
    configure(&mut s);
    let store = SessionStore::connect(&s).await.expect("redis store");
    assert_eq!(store.backend(), "redis");
    store.ping().await.expect("Redis answers PING");
    Some(Arc::new(store))
}

/// Declares a memory test and a Redis test running the same suite function.
macro_rules! both_backends {
    ($suite:ident, $memory:ident, $redis:ident) => {
        both_backends!($suite, $memory, $redis, |_s: &mut StoreSettings| {});
    };
    ($suite:ident, $memory:ident, $redis:ident, $configure:expr) => {
        #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
        async fn $memory() {
            $suite(&memory($configure).await).await;
        }

        #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
        async fn $redis() {
            if let Some(store) = redis($configure).await {
                $suite(&store).await;
            }
        }
    };
}

both_backends!(crud, crud_memory, crud_redis);
both_backends!(cas, cas_memory, cas_redis);
both_backends!(tenants_are_isolated, tenants_memory, tenants_redis);
both_backends!(ids_are_not_confused, ids_memory, ids_redis);
both_backends!(ttl_expires_and_cas_refreshes, ttl_memory, ttl_redis);
both_backends!(
    sessions_per_tenant_are_bounded,
    limit_memory,
    limit_redis,
    |s: &mut StoreSettings| s.max_sessions_per_tenant = 3
);
both_backends!(log_and_snapshots, log_memory, log_redis);
both_backends!(compaction, compact_memory, compact_redis);
both_backends!(
    concurrent_cas_loses_no_update,
    concurrent_memory,
    concurrent_redis
);

// ---------------------------------------------------------------- the suite

async fn crud(store: &Arc<SessionStore>) {
    assert_eq!(store.get("default", "a").await.unwrap(), None);
    assert_eq!(store.list("default").await.unwrap(), vec![]);
    assert!(!store.delete("default", "a").await.unwrap());

    assert_eq!(
        store
            .create("default", "b", "correlation", b"bee".to_vec(), LONG)
            .await,
        Ok(1)
    );
    assert_eq!(
        store
            .create("default", "a", "correlation", vec![0, 255, 7], LONG)
            .await,
        Ok(1)
    );
    assert_eq!(
        store
            .create("default", "c", "correlation", vec![], LONG)
            .await,
        Ok(1)
    );
    assert_eq!(
        store
            .create("default", "a", "correlation", b"again".to_vec(), LONG)
            .await,
        Err(StoreError::AlreadyExists)
    );
    assert_eq!(
        store.get("default", "a").await.unwrap(),
        Some(Stored {
            version: 1,
            token: 0,
            data: vec![0, 255, 7],
            log: vec![],
        })
    );
    assert_eq!(
        store.get("default", "c").await.unwrap(),
        Some(Stored {
            version: 1,
            token: 0,
            data: vec![],
            log: vec![],
        })
    );

    let listed = store.list("default").await.unwrap();
    let ids: Vec<&str> = listed.iter().map(|m| m.id.as_str()).collect();
    assert_eq!(ids, ["a", "b", "c"], "sorted by id");
    let bytes: Vec<usize> = listed.iter().map(|m| m.bytes).collect();
    assert_eq!(bytes, [3, 3, 0]);
    for m in &listed {
        assert_eq!(m.version, 1);
        assert!(
            m.ttl_remaining > Duration::ZERO && m.ttl_remaining <= LONG,
            "{m:?}"
        );
    }

    assert!(store.delete("default", "b").await.unwrap());
    assert!(!store.delete("default", "b").await.unwrap());
    assert_eq!(store.get("default", "b").await.unwrap(), None);
    let ids: Vec<String> = store
        .list("default")
        .await
        .unwrap()
        .into_iter()
        .map(|m| m.id)
        .collect();
    assert_eq!(ids, ["a", "c"]);
    // A deleted id can be created again, from version 1.
    assert_eq!(
        store
            .create("default", "b", "correlation", b"new".to_vec(), LONG)
            .await,
        Ok(1)
    );
    store.ping().await.unwrap();
}

async fn cas(store: &Arc<SessionStore>) {
    let t = "default";
    assert_eq!(
        store.compare_and_set(t, "x", 1, b"v2".to_vec(), LONG).await,
        Ok(CasOutcome::Missing)
    );
    store
        .create(t, "x", "correlation", b"v1".to_vec(), LONG)
        .await
        .unwrap();
    assert_eq!(
        store.compare_and_set(t, "x", 1, b"v2".to_vec(), LONG).await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    // A writer still holding version 1 loses and learns the current version.
    assert_eq!(
        store
            .compare_and_set(t, "x", 1, b"stale".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Conflict { current: 2 })
    );
    assert_eq!(
        store
            .compare_and_set(t, "x", 3, b"future".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Conflict { current: 2 })
    );
    let x = store.get(t, "x").await.unwrap().unwrap();
    assert_eq!((x.version, x.data, x.log), (2, b"v2".to_vec(), vec![]));
    assert_ne!(x.token, 0, "a write's token is never 0");
    for expected in 2..10 {
        let data = format!("v{}", expected + 1).into_bytes();
        assert_eq!(
            store.compare_and_set(t, "x", expected, data, LONG).await,
            Ok(CasOutcome::Stored {
                version: expected + 1
            })
        );
    }
    let now = store.get(t, "x").await.unwrap().unwrap();
    assert_eq!((now.version, now.data), (10, b"v10".to_vec()));
    let listed = store.list(t).await.unwrap();
    assert_eq!((listed[0].version, listed[0].bytes), (10, 3));
    // A larger value replaces a smaller one entirely.
    let big = vec![42u8; 10_000];
    assert_eq!(
        store.compare_and_set(t, "x", 10, big.clone(), LONG).await,
        Ok(CasOutcome::Stored { version: 11 })
    );
    assert_eq!(store.get(t, "x").await.unwrap().unwrap().data, big);
    store.delete(t, "x").await.unwrap();
    assert_eq!(
        store.compare_and_set(t, "x", 11, vec![], LONG).await,
        Ok(CasOutcome::Missing)
    );
}

/// Appends go to the log after the snapshot, a snapshot drops the log,
/// and a write expects the token of the write it read as well as the
/// version.
async fn log_and_snapshots(store: &Arc<SessionStore>) {
    let t = "log";
    store
        .create(t, "s", "plot_fusion", b"snap1".to_vec(), LONG)
        .await
        .unwrap();
    let at = |version: u64, token: u64| Expected {
        version,
        token: Some(token),
    };
    let append = |e: &[u8]| Write::Append(e.to_vec());
    // A created session's token is 0.
    assert_eq!(
        store.write(t, "s", at(1, 0), 11, append(b"e2"), LONG).await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    assert_eq!(
        store
            .write(t, "s", at(2, 11), 12, append(b"e3"), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 3 })
    );
    assert_eq!(
        store.get(t, "s").await.unwrap(),
        Some(Stored {
            version: 3,
            token: 12,
            data: b"snap1".to_vec(),
            log: vec![b"e2".to_vec(), b"e3".to_vec()],
        })
    );
    // Listed with its log's bytes.
    assert_eq!(store.list(t).await.unwrap()[0].bytes, 5 + 2 + 2);
    // The right version under another token (a version lost and made
    // again): a conflict, nothing written.
    assert_eq!(
        store
            .write(t, "s", at(3, 99), 13, append(b"e4"), LONG)
            .await,
        Ok(CasOutcome::Conflict { current: 3 })
    );
    assert_eq!(
        store
            .write(t, "s", at(2, 11), 13, append(b"e4"), LONG)
            .await,
        Ok(CasOutcome::Conflict { current: 3 })
    );
    // Any token: the version alone.
    let any = Expected {
        version: 3,
        token: None,
    };
    assert_eq!(
        store.write(t, "s", any, 14, append(b"e4"), LONG).await,
        Ok(CasOutcome::Stored { version: 4 })
    );
    // A snapshot drops the log.
    assert_eq!(
        store
            .write(
                t,
                "s",
                at(4, 14),
                15,
                Write::Snapshot(b"snap5".to_vec()),
                LONG
            )
            .await,
        Ok(CasOutcome::Stored { version: 5 })
    );
    assert_eq!(
        store.get(t, "s").await.unwrap(),
        Some(Stored {
            version: 5,
            token: 15,
            data: b"snap5".to_vec(),
            log: vec![],
        })
    );
    assert_eq!(
        store
            .write(t, "s", at(5, 15), 16, append(b"e6"), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 6 })
    );
    let s = store.get(t, "s").await.unwrap().unwrap();
    assert_eq!(
        (s.version, s.data, s.log),
        (6, b"snap5".to_vec(), vec![b"e6".to_vec()])
    );
    assert_eq!(store.list(t).await.unwrap()[0].bytes, 5 + 2);
    // Waiting for replicas needs none here (wait_replicas 0).
    store.replicated(t, "s", LONG).await.unwrap();
    assert!(store.delete(t, "s").await.unwrap());
    assert_eq!(
        store
            .write(t, "s", at(6, 16), 17, append(b"e7"), LONG)
            .await,
        Ok(CasOutcome::Missing)
    );
}

/// A snapshot lands behind later writes: it replaces the snapshot and the
/// entries up to its version, the later ones stay; only a version the log
/// holds, made by the token given, is compacted.
async fn compaction(store: &Arc<SessionStore>) {
    let t = "compact";
    store
        .create(t, "s", "plot_fusion", b"snap1".to_vec(), LONG)
        .await
        .unwrap();
    let at = |version: u64, token: u64| Expected {
        version,
        token: Some(token),
    };
    // Version v + 1 made by token v + 11 (a created session's token is 0).
    for v in 1..=4u64 {
        let expected = at(v, if v == 1 { 0 } else { v + 10 });
        let entry = Write::Append(format!("e{}", v + 1).into_bytes());
        assert_eq!(
            store.write(t, "s", expected, v + 11, entry, LONG).await,
            Ok(CasOutcome::Stored { version: v + 1 })
        );
    }
    // Versions 2..=5 were made by tokens 12, 13, 14, 15.
    let log =
        |from: u64| -> Vec<Vec<u8>> { (from..=5).map(|v| format!("e{v}").into_bytes()).collect() };
    // Version 3 under another token (made again elsewhere): stale, nothing
    // changes; so is a version the log does not hold (the snapshot's own,
    // or one not written yet), and the unknown token `None`.
    for (version, token) in [(3, 99), (1, 0), (6, 16)] {
        assert_eq!(
            store
                .compact(t, "s", at(version, token), b"x".to_vec())
                .await,
            Ok(Compacted::Stale)
        );
    }
    let none = Expected {
        version: 3,
        token: None,
    };
    assert_eq!(
        store.compact(t, "s", none, b"x".to_vec()).await,
        Ok(Compacted::Stale)
    );
    assert_eq!(
        store.get(t, "s").await.unwrap().unwrap().log,
        log(2),
        "unchanged"
    );
    // The state at 3: entries 4 and 5 stay, the version and token too.
    assert_eq!(
        store.compact(t, "s", at(3, 13), b"snap3".to_vec()).await,
        Ok(Compacted::Stored)
    );
    assert_eq!(
        store.get(t, "s").await.unwrap(),
        Some(Stored {
            version: 5,
            token: 15,
            data: b"snap3".to_vec(),
            log: log(4),
        })
    );
    assert_eq!(store.list(t).await.unwrap()[0].bytes, 5 + 2 + 2);
    // An older snapshot landing late is stale.
    assert_eq!(
        store.compact(t, "s", at(2, 12), b"snap2".to_vec()).await,
        Ok(Compacted::Stale)
    );
    // Writes go on from the version and token as they were.
    assert_eq!(
        store
            .write(t, "s", at(5, 15), 16, Write::Append(b"e6".to_vec()), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 6 })
    );
    // The newest version itself: the log becomes empty.
    assert_eq!(
        store.compact(t, "s", at(6, 16), b"snap6".to_vec()).await,
        Ok(Compacted::Stored)
    );
    let s = store.get(t, "s").await.unwrap().unwrap();
    assert_eq!(
        (s.version, s.token, s.data, s.log),
        (6, 16, b"snap6".to_vec(), vec![])
    );
    // After a snapshot written in place of an entry (a new version), no
    // entry is left to compact.
    assert_eq!(
        store
            .write(
                t,
                "s",
                at(6, 16),
                17,
                Write::Snapshot(b"snap7".to_vec()),
                LONG
            )
            .await,
        Ok(CasOutcome::Stored { version: 7 })
    );
    assert_eq!(
        store.compact(t, "s", at(7, 17), b"x".to_vec()).await,
        Ok(Compacted::Stale)
    );
    assert!(store.delete(t, "s").await.unwrap());
    assert_eq!(
        store.compact(t, "s", at(7, 17), b"x".to_vec()).await,
        Ok(Compacted::Missing)
    );
}

async fn tenants_are_isolated(store: &Arc<SessionStore>) {
    store
        .create("acme", "s1", "correlation", b"acme's".to_vec(), LONG)
        .await
        .unwrap();
    assert_eq!(store.get("default", "s1").await.unwrap(), None);
    assert_eq!(store.list("default").await.unwrap(), vec![]);
    assert!(!store.delete("default", "s1").await.unwrap());
    assert_eq!(
        store
            .compare_and_set("default", "s1", 1, b"x".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Missing)
    );
    // The same id in another tenant is another session.
    assert_eq!(
        store
            .create("default", "s1", "correlation", b"default's".to_vec(), LONG)
            .await,
        Ok(1)
    );
    assert_eq!(
        store
            .compare_and_set("default", "s1", 1, b"d2".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    assert_eq!(
        store.get("acme", "s1").await.unwrap(),
        Some(Stored {
            version: 1,
            token: 0,
            data: b"acme's".to_vec(),
            log: vec![],
        })
    );
    assert!(store.delete("default", "s1").await.unwrap());
    assert_eq!(store.list("acme").await.unwrap().len(), 1);
    assert_eq!(store.list("default").await.unwrap(), vec![]);
}

/// Separators and escapes in tenants and ids never make two names one key.
async fn ids_are_not_confused(store: &Arc<SessionStore>) {
    let names = [
        ("a", "b:s:c"),
        ("a:b", "c"),
        ("a", "b"),
        ("a%3Ab", "c"),
        ("a", "b%3As%3Ac"),
        ("a:s", "x"),
        ("", ""),
        ("ü", "ü:%"),
    ];
    for (i, (tenant, id)) in names.iter().enumerate() {
        store
            .create(tenant, id, "correlation", vec![i as u8], LONG)
            .await
            .unwrap_or_else(|e| panic!("{tenant:?}/{id:?}: {e}"));
    }
    for (i, (tenant, id)) in names.iter().enumerate() {
        let got = store.get(tenant, id).await.unwrap().expect("stored");
        assert_eq!(got.data, vec![i as u8], "{tenant:?}/{id:?}");
    }
    let ids: Vec<String> = store
        .list("a")
        .await
        .unwrap()
        .into_iter()
        .map(|m| m.id)
        .collect();
    assert_eq!(ids, ["b", "b%3As%3Ac", "b:s:c"]);
    let ids: Vec<String> = store
        .list("ü")
        .await
        .unwrap()
        .into_iter()
        .map(|m| m.id)
        .collect();
    assert_eq!(ids, ["ü:%"]);
}

async fn ttl_expires_and_cas_refreshes(store: &Arc<SessionStore>) {
    let t = "default";
    store
        .create(t, "short", "correlation", b"s".to_vec(), SHORT)
        .await
        .unwrap();
    store
        .create(t, "kept", "correlation", b"k".to_vec(), SHORT)
        .await
        .unwrap();
    let ttl = store.list(t).await.unwrap()[0].ttl_remaining;
    assert!(ttl > Duration::ZERO && ttl <= SHORT, "{ttl:?}");
    // The update restarts the idle time with its own TTL.
    assert_eq!(
        store
            .compare_and_set(t, "kept", 1, b"k2".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    tokio::time::sleep(SHORT * 2).await;
    assert_eq!(store.get(t, "short").await.unwrap(), None);
    assert_eq!(
        store
            .compare_and_set(t, "short", 1, b"late".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Missing)
    );
    assert!(!store.delete(t, "short").await.unwrap());
    assert_eq!(store.get(t, "kept").await.unwrap().unwrap().version, 2);
    let ids: Vec<String> = store
        .list(t)
        .await
        .unwrap()
        .into_iter()
        .map(|m| m.id)
        .collect();
    assert_eq!(ids, ["kept"]);
    // An expired id can be created afresh.
    assert_eq!(
        store
            .create(t, "short", "correlation", b"again".to_vec(), LONG)
            .await,
        Ok(1)
    );
    // And a CAS can shorten the TTL too: it sets it, it does not only extend it.
    assert_eq!(
        store
            .compare_and_set(t, "kept", 2, b"k3".to_vec(), SHORT)
            .await,
        Ok(CasOutcome::Stored { version: 3 })
    );
    tokio::time::sleep(SHORT * 2).await;
    assert_eq!(store.get(t, "kept").await.unwrap(), None);
}

/// Run with `max_sessions_per_tenant = 3`.
async fn sessions_per_tenant_are_bounded(store: &Arc<SessionStore>) {
    let t = "acme";
    store
        .create(t, "long", "correlation", vec![1], LONG)
        .await
        .unwrap();
    store
        .create(t, "short1", "correlation", vec![2], SHORT)
        .await
        .unwrap();
    store
        .create(t, "short2", "correlation", vec![3], SHORT)
        .await
        .unwrap();
    assert_eq!(
        store
            .create(t, "fourth", "correlation", vec![4], LONG)
            .await,
        Err(StoreError::TooManySessions { limit: 3 })
    );
    // Other tenants have their own allowance.
    store
        .create("default", "fourth", "correlation", vec![4], LONG)
        .await
        .unwrap();
    // A deleted session frees its place.
    assert!(store.delete(t, "short2").await.unwrap());
    store
        .create(t, "fourth", "correlation", vec![4], LONG)
        .await
        .unwrap();
    assert_eq!(
        store.create(t, "fifth", "correlation", vec![5], LONG).await,
        Err(StoreError::TooManySessions { limit: 3 })
    );
    // Expired sessions do not count.
    tokio::time::sleep(SHORT * 2).await;
    store
        .create(t, "fifth", "correlation", vec![5], LONG)
        .await
        .unwrap();
    assert_eq!(
        store.create(t, "sixth", "correlation", vec![6], LONG).await,
        Err(StoreError::TooManySessions { limit: 3 })
    );
    let ids: Vec<String> = store
        .list(t)
        .await
        .unwrap()
        .into_iter()
        .map(|m| m.id)
        .collect();
    assert_eq!(ids, ["fifth", "fourth", "long"]);
}

/// Many tasks increment a counter held in the data, each by read, CAS and
/// retry on conflict: no increment may be lost.
async fn concurrent_cas_loses_no_update(store: &Arc<SessionStore>) {
    const TASKS: u64 = 8;
    const EACH: u64 = 25;
    let t = "default";
    store
        .create(
            t,
            "counter",
            "correlation",
            0u64.to_le_bytes().to_vec(),
            LONG,
        )
        .await
        .unwrap();
    let mut tasks = tokio::task::JoinSet::new();
    for _ in 0..TASKS {
        let store = Arc::clone(store);
        tasks.spawn(async move {
            let mut conflicts = 0u64;
            for _ in 0..EACH {
                loop {
                    let cur = store.get(t, "counter").await.unwrap().expect("counter");
                    let n = u64::from_le_bytes(cur.data.try_into().expect("8 bytes"));
                    let next = (n + 1).to_le_bytes().to_vec();
                    match store
                        .compare_and_set(t, "counter", cur.version, next, LONG)
                        .await
                    {
                        Ok(CasOutcome::Stored { version }) => {
                            assert_eq!(version, cur.version + 1);
                            break;
                        }
                        Ok(CasOutcome::Conflict { current }) => {
                            assert!(current > cur.version);
                            conflicts += 1;
                        }
                        other => panic!("unexpected {other:?}"),
                    }
                }
            }
            conflicts
        });
    }
    let mut conflicts = 0;
    while let Some(done) = tasks.join_next().await {
        conflicts += done.expect("task finished");
    }
    let last = store.get(t, "counter").await.unwrap().unwrap();
    let n = u64::from_le_bytes(last.data.try_into().unwrap());
    assert_eq!(n, TASKS * EACH, "{conflicts} conflicts");
    assert_eq!(last.version, 1 + TASKS * EACH);
}

// ---------------------------------------------------------------- memory only

#[tokio::test]
async fn memory_bound_counts_live_bytes_and_frees_expired_ones() {
    let store = memory(|s| s.max_memory_bytes = 100).await;
    let SessionStore::Memory(inner) = &*store else {
        unreachable!()
    };
    store
        .create("a", "x", "correlation", vec![0; 60], SHORT)
        .await
        .unwrap();
    store
        .create("b", "y", "correlation", vec![0; 30], LONG)
        .await
        .unwrap();
    assert_eq!(inner.bytes(), 90);
    assert_eq!(
        store
            .create("a", "z", "correlation", vec![0; 11], LONG)
            .await,
        Err(StoreError::MemoryFull { limit_bytes: 100 })
    );
    store
        .create("a", "z", "correlation", vec![0; 10], LONG)
        .await
        .unwrap();
    // Growing a session counts only the difference; shrinking frees bytes.
    assert_eq!(
        store.compare_and_set("b", "y", 1, vec![0; 31], LONG).await,
        Err(StoreError::MemoryFull { limit_bytes: 100 })
    );
    assert_eq!(store.get("b", "y").await.unwrap().unwrap().version, 1);
    assert_eq!(
        store.compare_and_set("b", "y", 1, vec![0; 20], LONG).await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    assert_eq!(inner.bytes(), 90);
    assert!(store.delete("a", "z").await.unwrap());
    assert_eq!(inner.bytes(), 80);
    // Expired sessions of any tenant are evicted before refusing.
    tokio::time::sleep(SHORT * 2).await;
    store
        .create("b", "w", "correlation", vec![0; 80], LONG)
        .await
        .unwrap();
    assert_eq!(inner.bytes(), 100);
    assert_eq!(store.get("a", "x").await.unwrap(), None);
}

// ---------------------------------------------------------------- Redis outage

/// Polls `ping` until it succeeds; panics after `limit`.
async fn wait_until_up(store: &SessionStore, limit: Duration) {
    let start = Instant::now();
    loop {
        match store.ping().await {
            Ok(()) => return,
            Err(e) if start.elapsed() > limit => {
                panic!("store did not recover within {limit:?}: {e}")
            }
            Err(_) => tokio::time::sleep(Duration::from_millis(50)).await,
        }
    }
}

async fn assert_unavailable_fast<T: std::fmt::Debug>(
    what: &str,
    timeout: Duration,
    call: impl std::future::Future<Output = Result<T, StoreError>>,
) {
    let start = Instant::now();
    let result = call.await;
    let took = start.elapsed();
    assert!(
        matches!(result, Err(StoreError::Unavailable { .. })),
        "{what}: {result:?}"
    );
    assert!(took <= timeout * 2, "{what} took {took:?}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn redis_outage_fails_fast_and_recovers() {
    if !redis_server_available() {
        return;
    }
    let port = free_port();
    let mut s = settings(&format!("redis://127.0.0.1:{port}/0"));
    s.timeout = Duration::from_millis(500);
    let timeout = s.timeout;

    // Redis down at start: connecting still succeeds, calls fail fast.
    let store = SessionStore::connect(&s).await.expect("connects lazily");
    assert_unavailable_fast("ping", timeout, store.ping()).await;
    assert_unavailable_fast("get", timeout, store.get("t", "a")).await;

    let mut server = RedisServer::start(port, None);
    assert_eq!(server.url(), s.url);
    wait_until_up(&store, Duration::from_secs(10)).await;
    assert_eq!(
        store
            .create("t", "a", "correlation", b"1".to_vec(), LONG)
            .await,
        Ok(1)
    );

    // Redis goes away.
    server.kill();
    assert_unavailable_fast("ping", timeout, store.ping()).await;
    assert_unavailable_fast("get", timeout, store.get("t", "a")).await;
    assert_unavailable_fast(
        "create",
        timeout,
        store.create("t", "b", "correlation", b"2".to_vec(), LONG),
    )
    .await;
    assert_unavailable_fast(
        "cas",
        timeout,
        store.compare_and_set("t", "a", 1, b"2".to_vec(), LONG),
    )
    .await;
    assert_unavailable_fast("list", timeout, store.list("t")).await;
    assert_unavailable_fast("delete", timeout, store.delete("t", "a")).await;

    // Redis comes back (empty): the store reconnects by itself.
    let _server = RedisServer::start(port, None);
    wait_until_up(&store, Duration::from_secs(10)).await;
    assert_eq!(store.get("t", "a").await, Ok(None));
    assert_eq!(
        store
            .create("t", "b", "correlation", b"2".to_vec(), LONG)
            .await,
        Ok(1)
    );
    assert_eq!(
        store
            .compare_and_set("t", "b", 1, b"3".to_vec(), LONG)
            .await,
        Ok(CasOutcome::Stored { version: 2 })
    );
}
