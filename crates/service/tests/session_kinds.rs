//! A kind of session is one module: a toy kind (a counter), defined here and
//! nowhere in the service, gets the whole generic machinery (create, push,
//! the sequence protocol with replay, compare-and-set with retries, the
//! decoded-session cache, list, wrong-kind batches) on both store backends,
//! next to the service's own correlation kind.
//!
//! Redis tests fail loudly when Redis is not running, unless
//! `FUSION_SKIP_REDIS_TESTS=1` is set.

use std::{future::Future, task::Poll, time::Duration};

use service::{
    ServiceError, Violations,
    correlation::{CorrelateInput, MethodInput, MotionModelInput, NodeInput, RuleInput},
    session::{
        Batch, Limits, SessionKind, Spec,
        correlation::{self as corr, CorrelationSession},
        persist::Sessions,
    },
};
use store::{SessionStore, StoreSettings};
use wire_formats::wire::{self, FormatError, Reader, Writer};

use test_support::redis::{
    RedisServer, free_port, redis_is_up, redis_server_available, redis_url, unique,
};

/// The toy kind: a running total of integer increments, each at most
/// `limit`. Its apply adds the increments one by one and fails at the first
/// one over the limit, so a failed batch leaves the decoded copy half
/// changed: the machinery must never store or reuse it.
#[derive(Debug)]
struct Counter {
    limit: i64,
    total: i64,
}

impl SessionKind for Counter {
    const TAG: u8 = 250;
    const NAME: &'static str = "counter";
    const BATCH_FIELD: &'static str = "increments";

    type Spec = i64;
    type Batch = Vec<i64>;
    type Update = i64;
    type View = (i64, i64);

    fn create(limit: i64, _warnings: &mut Vec<String>) -> Result<Self, ServiceError> {
        if limit <= 0 {
            return Err(Violations::single("limit", "must be positive"));
        }
        Ok(Self { limit, total: 0 })
    }

    fn check_size(batch: &Vec<i64>, limits: &Limits) -> Result<(), ServiceError> {
        if batch.len() > limits.max_batch_reports {
            return Err(ServiceError::TooLarge("too many increments".into()));
        }
        Ok(())
    }

    fn apply(
        &mut self,
        batch: &Vec<i64>,
        _limits: &Limits,
        warnings: &mut Vec<String>,
    ) -> Result<i64, ServiceError> {
        for (i, &inc) in batch.iter().enumerate() {
            if inc > self.limit {
                return Err(Violations::single(
                    format!("increments[{i}]"),
                    format!("is above the limit {}", self.limit),
                ));
            }
            self.total += inc;
        }
        if batch.is_empty() {
            warnings.push("empty batch".into());
        }
        Ok(self.total)
    }

    fn acknowledgement(&self) -> i64 {
        self.total
    }

    fn view(&self) -> Result<(i64, i64), ServiceError> {
        Ok((self.limit, self.total))
    }

    fn encode(&self, w: &mut Writer) {
        w.u8(1);
        w.u64(self.limit as u64);
        w.u64(self.total as u64);
        // Ballast: a snapshot larger than a few batches, as a real
        // session's is, so that pushes go to the log.
        w.bytes(&[0; BALLAST]);
    }

    fn encode_batch(batch: &Vec<i64>, w: &mut Writer) -> bool {
        w.usize(batch.len());
        batch.iter().for_each(|&i| w.u64(i as u64));
        true
    }

    fn decode_batch(r: &mut Reader<'_>) -> Result<Vec<i64>, FormatError> {
        let n = r.len(8)?;
        (0..n).map(|_| r.u64().map(|i| i as i64)).collect()
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, ServiceError> {
        let bad = |e: FormatError| ServiceError::Internal(e.to_string());
        if r.u8().map_err(bad)? != 1 {
            return Err(ServiceError::Internal("counter format".into()));
        }
        let limit = r.u64().map_err(bad)? as i64;
        let total = r.u64().map_err(bad)? as i64;
        r.bytes().map_err(bad)?;
        Ok(Self { limit, total })
    }

    fn encode_update(u: &i64, w: &mut Writer) {
        w.u64(*u as u64);
    }

    fn decode_update(r: &mut Reader<'_>) -> Result<i64, FormatError> {
        r.u64()
            .map(|v| v as i64)
            .map_err(|_| wire::corrupt("counter update"))
    }
}

/// Bytes of ballast in a counter's snapshot.
const BALLAST: usize = 512;

const LIMITS: Limits = Limits {
    max_tracks: 100,
    max_batch_reports: 100,
};
const TENANT: &str = "acme";

fn settings(url: &str, prefix: &str) -> StoreSettings {
    StoreSettings {
        url: url.to_string(),
        key_prefix: prefix.to_string(),
        max_sessions_per_tenant: 100,
        redis: Default::default(),
        wait_replicas: 0,
        max_memory_bytes: 1 << 24,
        max_memory_bytes_per_tenant: 1 << 24,
        timeout: Duration::from_secs(1),
    }
}

async fn memory() -> Sessions {
    let store = SessionStore::connect(&settings("memory", "unused"))
        .await
        .unwrap();
    Sessions::new(store, 1 << 20)
}

/// Two replicas (each its own connection and cache) on one Redis prefix, or
/// `None` when Redis is down and `FUSION_SKIP_REDIS_TESTS=1`.
async fn redis_pair() -> Option<(Sessions, Sessions)> {
    if !redis_is_up() {
        return None;
    }
    let prefix = unique("radar-fusion-kinds:");
    let mut out = Vec::new();
    for _ in 0..2 {
        let store = SessionStore::connect(&settings(&redis_url(), &prefix))
            .await
            .unwrap();
        store.ping().await.expect("Redis answers PING");
        out.push(Sessions::new(store, 1 << 20));
    }
    let b = out.pop()?;
    Some((out.pop()?, b))
}

fn batch(sequence: Option<u64>, increments: &[i64]) -> Batch<Vec<i64>> {
    Batch {
        sequence,
        body: increments.to_vec(),
    }
}

fn counter(limit: i64) -> Spec<i64> {
    Spec {
        idle_expiry_s: Some(600.0),
        body: limit,
    }
}

fn correlation_spec() -> Spec<corr::SessionSpec> {
    Spec {
        idle_expiry_s: None,
        body: corr::SessionSpec {
            config: CorrelateInput {
                state_layout: ["x", "vx", "y", "vy"].map(String::from).to_vec(),
                method: Some(MethodInput {
                    kind: Some("independent_double_threshold".into()),
                    rule: Some(RuleInput {
                        l: Some(2),
                        r: Some(3),
                    }),
                    ..Default::default()
                }),
                motion_model: Some(MotionModelInput {
                    process_noise: Some("dwna".into()),
                    sigma_a_mps2: Some(1.0),
                    ..Default::default()
                }),
                nodes: ["a", "b"]
                    .map(|id| NodeInput {
                        id: Some(id.into()),
                        tracks: Vec::new(),
                    })
                    .to_vec(),
                ..Default::default()
            },
            retire_after_s: None,
            history_instants: None,
        },
    }
}

fn field_of(e: &ServiceError) -> String {
    match e {
        ServiceError::InvalidInput(v) => v[0].field.clone(),
        other => panic!("expected a field violation, got {other:?}"),
    }
}

/// Create, push, replay, gaps, a failed batch, list and wrong kinds, with
/// `a` and `b` two replicas of one store (or the same one twice).
async fn suite(a: &Sessions, b: &Sessions) {
    // Creation validates the kind's configuration and the envelope's.
    let bad = a
        .create::<Counter>(
            TENANT,
            Spec {
                idle_expiry_s: Some(-1.0),
                body: 0,
            },
        )
        .await
        .unwrap_err();
    let ServiceError::InvalidInput(v) = bad else {
        panic!("{bad:?}")
    };
    let fields: Vec<_> = v.iter().map(|f| f.field.as_str()).collect();
    assert_eq!(fields, ["idle_expiry_s", "limit"]);

    let c = a.create::<Counter>(TENANT, counter(10)).await.unwrap();
    assert_eq!((c.kind, c.version, c.body), ("counter", 1, (10, 0)));
    let id = c.id;
    let cs = a
        .create::<CorrelationSession>(TENANT, correlation_spec())
        .await
        .unwrap();
    assert_eq!(cs.kind, "correlation");

    // Sequenced pushes, alternating replicas: each replica's cached copy
    // goes stale when the other writes, and is caught by the version.
    let u1 = a.push::<Counter>(TENANT, &id, batch(Some(1), &[1, 2]), LIMITS);
    let u1 = u1.await.unwrap();
    assert_eq!((u1.body, u1.version, u1.duplicate), (3, 2, false));
    let u2 = b
        .push::<Counter>(TENANT, &id, batch(Some(2), &[4]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u2.body, u2.version), (7, 3));
    // `a` still caches version 2, where 3 looks like a gap: the cached
    // copy's word is not trusted, a fresh read applies it.
    let u3 = a
        .push::<Counter>(TENANT, &id, batch(Some(3), &[5]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u3.body, u3.version, u3.duplicate), (12, 4, false));

    // A retry of the last batch replays its update, on either replica.
    for s in [a, b] {
        let again = s
            .push::<Counter>(TENANT, &id, batch(Some(3), &[5]), LIMITS)
            .await
            .unwrap();
        assert!(again.duplicate);
        assert_eq!((again.body, again.version), (12, 4));
        assert_eq!(again.sequence, Some(3));
    }
    // An older one is acknowledged with the current total, nothing applied.
    let old = b
        .push::<Counter>(TENANT, &id, batch(Some(1), &[1, 2]), LIMITS)
        .await
        .unwrap();
    assert!(old.duplicate);
    assert_eq!(old.body, 12);
    // A gap names the expected number.
    let gap = a
        .push::<Counter>(TENANT, &id, batch(Some(9), &[1]), LIMITS)
        .await
        .unwrap_err();
    assert!(
        matches!(&gap, ServiceError::Conflict(m) if m.contains("must carry 4")),
        "{gap:?}"
    );

    // A failed batch (half applied to the decoded copy) changes nothing,
    // neither in the store nor in the cache of the replica that ran it.
    let failed = a
        .push::<Counter>(TENANT, &id, batch(Some(4), &[3, 99]), LIMITS)
        .await
        .unwrap_err();
    assert_eq!(field_of(&failed), "increments[1]");
    let view = a.get_as::<Counter>(TENANT, &id).await.unwrap();
    assert_eq!(
        (view.body, view.version, view.last_sequence),
        ((10, 12), 4, Some(3))
    );
    let u4 = a
        .push::<Counter>(TENANT, &id, batch(Some(4), &[3]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u4.body, u4.version), (15, 5));
    // Unsequenced batches apply too.
    let u5 = b
        .push::<Counter>(TENANT, &id, batch(None, &[]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u5.body, u5.version, u5.warnings.len()), (15, 6, 1));
    // Too large before any work.
    let big = vec![1; 101];
    assert!(matches!(
        a.push::<Counter>(TENANT, &id, batch(None, &big), LIMITS)
            .await,
        Err(ServiceError::TooLarge(_))
    ));

    // A batch of the wrong kind is a violation of its own batch field.
    let wrong = a
        .push::<CorrelationSession>(
            TENANT,
            &id,
            Batch {
                sequence: Some(5),
                body: corr::BatchInput::default(),
            },
            LIMITS,
        )
        .await
        .unwrap_err();
    assert_eq!(field_of(&wrong), "reports");
    let wrong = b
        .push::<Counter>(TENANT, &cs.id, batch(Some(1), &[1]), LIMITS)
        .await
        .unwrap_err();
    assert_eq!(field_of(&wrong), "increments");
    let ServiceError::InvalidInput(v) = &wrong else {
        unreachable!()
    };
    assert!(v[0].message.contains("correlation session"), "{v:?}");
    assert!(matches!(
        a.get_as::<Counter>(TENANT, &cs.id).await,
        Err(ServiceError::NotFound(_))
    ));
    // Nothing of either session changed.
    assert_eq!(a.get_as::<Counter>(TENANT, &id).await.unwrap().version, 6);
    let cv = a
        .get_as::<CorrelationSession>(TENANT, &cs.id)
        .await
        .unwrap();
    assert_eq!((cv.version, cv.batches), (1, 0));

    // The list says each session's kind.
    let mut listed: Vec<(String, String)> = b
        .list(TENANT)
        .await
        .unwrap()
        .into_iter()
        .map(|m| (m.id, m.kind))
        .collect();
    listed.sort();
    let mut expected = vec![
        (id.clone(), "counter".to_string()),
        (cs.id.clone(), "correlation".to_string()),
    ];
    expected.sort();
    assert_eq!(listed, expected);

    // Concurrent unsequenced pushes from both replicas: every one applied
    // exactly once (compare-and-set retries, no lost update).
    let mut tasks = Vec::new();
    for i in 0..8 {
        let s = if i % 2 == 0 { a } else { b };
        tasks.push(s.push::<Counter>(TENANT, &id, batch(None, &[1]), LIMITS));
    }
    for r in futures_join(tasks).await {
        r.unwrap();
    }
    let end = b.get_as::<Counter>(TENANT, &id).await.unwrap();
    assert_eq!((end.body.1, end.version), (23, 14));

    // Stored as a snapshot and the batches since: 13 writes of at most
    // 25 bytes each after the creation's snapshot of 535 bytes (1 + 16 +
    // 8 + 512 ballast and 2 + 8 + 9 + 1 + 8 + 8 envelope bytes) fit the
    // default of 32 entries and the snapshot's size, so the log holds them
    // all, and either replica's view replays it.
    let stored = a.store().get(TENANT, &id).await.unwrap().unwrap();
    assert_eq!(stored.version, 14);
    assert_eq!(stored.log.len(), 13, "{stored:?}");
    assert!(stored.log_bytes() < stored.data.len());

    // Deleted on one replica: gone on the other, cache or not.
    a.delete(TENANT, &id).await.unwrap();
    assert!(matches!(
        b.push::<Counter>(TENANT, &id, batch(None, &[1]), LIMITS)
            .await,
        Err(ServiceError::NotFound(_))
    ));
}

/// A version lost in a failover and made again by another write (two
/// replicas, each with its cache, so Redis only): a replica
/// whose cache holds the lost one must not build on it (the write token,
/// not the version alone, identifies what it read).
async fn a_lost_version_made_again(a: &Sessions, b: &Sessions) {
    let id = format!("{:032x}", rand::random::<u128>());
    a.create_with_id::<Counter>(TENANT, &id, counter(10))
        .await
        .unwrap();
    let u = a
        .push::<Counter>(TENANT, &id, batch(Some(1), &[1]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u.body, u.version), (1, 2));
    // The store loses version 2 (as a Redis primary that had not passed it
    // to the replica promoted in its place) and another writer makes a
    // version 2 of its own.
    b.delete(TENANT, &id).await.unwrap();
    b.create_with_id::<Counter>(TENANT, &id, counter(10))
        .await
        .unwrap();
    let u = b
        .push::<Counter>(TENANT, &id, batch(Some(1), &[5]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u.body, u.version), (5, 2));
    // `a` caches its own version 2 (total 1): it must find the store's.
    let u = a
        .push::<Counter>(TENANT, &id, batch(Some(2), &[2]), LIMITS)
        .await
        .unwrap();
    assert_eq!((u.body, u.version, u.duplicate), (7, 3, false));
    let view = b.get_as::<Counter>(TENANT, &id).await.unwrap();
    assert_eq!((view.body.1, view.version), (7, 3));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_lost_version_made_again_is_not_built_on_with_two_redis_replicas() {
    let Some((a, b)) = redis_pair().await else {
        return;
    };
    a_lost_version_made_again(&a, &b).await;
}

/// A redis-server replicating `primary`, killed on drop.
struct Replica(std::process::Child);

impl Drop for Replica {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `call` again, every 100 ms, while it is `Unavailable` and the deadline
/// is ahead; its answer (any other error fails the test).
async fn while_unavailable<T, F: Future<Output = Result<T, ServiceError>>>(
    deadline: std::time::Instant,
    mut call: impl FnMut() -> F,
) -> T {
    loop {
        match call().await {
            Ok(answer) => return answer,
            Err(ServiceError::Unavailable(_)) if std::time::Instant::now() < deadline => {
                tokio::time::sleep(Duration::from_millis(100)).await
            }
            Err(e) => panic!("{e:?}"),
        }
    }
}

/// With `WAIT 1`, the acknowledgement of a duplicate (a retry whose first
/// answer was lost) also waits for the replica: the first write may not
/// have reached it, and a failover then would lose a batch the client was
/// told is applied.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_duplicate_is_acknowledged_only_once_the_replicas_hold_it() {
    if !redis_server_available() {
        return;
    }
    let primary = RedisServer::start(free_port(), None);
    primary.wait_accepting();
    let port = free_port();
    let replica = Replica(
        std::process::Command::new("redis-server")
            .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
            .args(["--save", "", "--appendonly", "no"])
            .args(["--replicaof", "127.0.0.1", &primary.port.to_string()])
            // A replica writes the primary's dump on its first sync.
            .arg("--dir")
            .arg(std::env::temp_dir())
            .stdout(std::process::Stdio::null())
            .spawn()
            .expect("redis-server starts"),
    );
    let mut s = settings(&primary.url(), &unique("radar-fusion-wait:"));
    s.wait_replicas = 1;
    let sessions = Sessions::new(SessionStore::connect(&s).await.unwrap(), 1 << 20);
    // Until the replica has synchronised, writes are not confirmed: the
    // creation is tried again, then the same batch (a duplicate once a
    // write landed).
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    let c = while_unavailable(deadline, || sessions.create::<Counter>(TENANT, counter(10))).await;
    let first = while_unavailable(deadline, || {
        sessions.push::<Counter>(TENANT, &c.id, batch(Some(1), &[2]), LIMITS)
    })
    .await;
    assert_eq!(first.body, 2);
    // The replica is gone: a retry of batch 1 is a duplicate, but cannot be
    // confirmed as replicated, so it is not acknowledged.
    drop(replica);
    let again = sessions
        .push::<Counter>(TENANT, &c.id, batch(Some(1), &[2]), LIMITS)
        .await
        .unwrap_err();
    assert!(
        matches!(&again, ServiceError::Unavailable(m) if m.contains("may or may not")),
        "{again:?}"
    );
    let view = sessions.get_as::<Counter>(TENANT, &c.id).await.unwrap();
    assert_eq!((view.body.1, view.last_sequence), (2, Some(1)));
}

/// Runs the futures concurrently on the current task (a minimal
/// `join_all`: the futures borrow the replicas, so they cannot be spawned).
async fn futures_join<F: Future>(fs: Vec<F>) -> Vec<F::Output> {
    let mut fs: Vec<_> = fs.into_iter().map(Box::pin).collect();
    let mut out: Vec<Option<F::Output>> = fs.iter().map(|_| None).collect();
    std::future::poll_fn(|cx| {
        for (f, slot) in fs.iter_mut().zip(out.iter_mut()) {
            if slot.is_none()
                && let Poll::Ready(v) = f.as_mut().poll(cx)
            {
                *slot = Some(v);
            }
        }
        if out.iter().all(Option::is_some) {
            Poll::Ready(())
        } else {
            Poll::Pending
        }
    })
    .await;
    out.into_iter().map(|v| v.expect("ready")).collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_toy_kind_gets_the_whole_machinery_on_the_memory_store() {
    let s = memory().await;
    suite(&s, &s).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_toy_kind_gets_the_whole_machinery_on_redis_with_two_replicas() {
    let Some((a, b)) = redis_pair().await else {
        return;
    };
    suite(&a, &b).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_a_cache_every_push_reads_the_store() {
    let store = SessionStore::connect(&settings("memory", "unused"))
        .await
        .unwrap();
    let s = Sessions::new(store, 0);
    suite(&s, &s).await;
}
