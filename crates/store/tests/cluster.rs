//! Redis Cluster against real processes on loopback: three primaries
//! (`redis-server --cluster-enabled yes`, joined by `redis-cli --cluster
//! create … --cluster-yes`) on free ports. Sessions of several tenants land
//! on every primary (hash tag per tenant); create, compare-and-set, get,
//! list, expiry and delete work; a tenant's slot is migrated to another
//! primary while its session is pushed, and every push is applied exactly
//! once. Skipped with a loud line only when redis-server or redis-cli is not
//! on PATH.

use std::{
    process::{Command, Stdio},
    sync::Arc,
    time::{Duration, Instant},
};

use store::{CasOutcome, SessionStore, StoreError, StoreSettings};

use test_support::{
    cluster::{Cluster, cluster_port},
    procs::{Proc, cli, loud},
};

const PREFIX: &str = "cluster-test";

async fn store(cluster: &Cluster) -> SessionStore {
    SessionStore::connect(&StoreSettings {
        url: cluster.url(),
        redis: Default::default(),
        wait_replicas: 0,
        key_prefix: PREFIX.into(),
        max_sessions_per_tenant: 10,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_secs(1),
    })
    .await
    .expect("the store starts on the cluster")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn tenants_shard_over_the_primaries_and_every_operation_works() {
    let Some(cluster) = Cluster::start("Redis Cluster tests") else {
        return;
    };
    let store = store(&cluster).await;
    let ttl = Duration::from_secs(60);
    let tenants: Vec<String> = (0..12).map(|i| format!("tenant-{i}")).collect();
    for t in &tenants {
        assert_eq!(
            store
                .create(t, "a", "correlation", b"1".to_vec(), ttl)
                .await,
            Ok(1)
        );
        assert_eq!(
            store
                .create(t, "b", "plot_fusion", b"x".to_vec(), ttl)
                .await,
            Ok(1)
        );
        assert_eq!(
            store
                .create(t, "a", "correlation", b"1".to_vec(), ttl)
                .await,
            Err(StoreError::AlreadyExists)
        );
        assert_eq!(
            store.compare_and_set(t, "a", 1, b"2".to_vec(), ttl).await,
            Ok(CasOutcome::Stored { version: 2 })
        );
        assert_eq!(
            store.compare_and_set(t, "a", 1, b"3".to_vec(), ttl).await,
            Ok(CasOutcome::Conflict { current: 2 })
        );
    }
    for t in &tenants {
        let s = store.get(t, "a").await.unwrap().unwrap();
        assert_eq!((s.version, s.data.as_slice()), (2, &b"2"[..]));
        let listed = store.list(t).await.unwrap();
        let ids: Vec<(&str, &str)> = listed
            .iter()
            .map(|m| (m.id.as_str(), m.kind.as_str()))
            .collect();
        assert_eq!(ids, [("a", "correlation"), ("b", "plot_fusion")]);
        assert_eq!(store.delete(t, "b").await, Ok(true));
        assert_eq!(store.list(t).await.unwrap().len(), 1);
        assert_eq!(store.version(t, "b").await, Ok(None));
    }
    // Every primary holds some tenants' keys (the tenant names fix their
    // slots, and `--cluster create` splits the slots in three).
    let keys = cluster.keys_per_node(PREFIX);
    assert!(keys.iter().all(|k| *k > 0), "keys per primary: {keys:?}");
    assert_eq!(keys.iter().sum::<usize>(), 2 * tenants.len(), "{keys:?}");
    // Idle expiry: a session and its index entry go.
    store
        .create(
            "tenant-0",
            "short",
            "correlation",
            b"s".to_vec(),
            Duration::from_millis(200),
        )
        .await
        .unwrap();
    tokio::time::sleep(Duration::from_millis(400)).await;
    assert_eq!(store.get("tenant-0", "short").await, Ok(None));
    assert_eq!(store.list("tenant-0").await.unwrap().len(), 1);
    // Session events: published on the cluster, heard by the listener.
    let (listener, mut feed) = store.listen(16).expect("a listener on the cluster");
    listener.subscribe(store.channel("tenant-3", "a").unwrap());
    let mut heard = false;
    for _ in 0..50 {
        store.publish("tenant-3", "a", b"event").await.unwrap();
        if let Ok(Some(store::events::Feed::Message(m))) =
            tokio::time::timeout(Duration::from_millis(100), feed.recv()).await
        {
            assert_eq!(m, b"event");
            heard = true;
            break;
        }
    }
    assert!(heard, "the listener hears the cluster's events");
    // Health names the seeds.
    assert_eq!(
        store.topology().unwrap().primary,
        Some(format!(
            "127.0.0.1:{},127.0.0.1:{}",
            cluster.ports[0], cluster.ports[1]
        ))
    );
}

/// Pushes a session from version `from` to `to`, each push applied once: an
/// `Unavailable` push is checked by reading and retried only when it did
/// not apply. Returns the number of `Unavailable` answers.
async fn push_exactly_once(store: &SessionStore, tenant: &str, from: u64, to: u64) -> u32 {
    let ttl = Duration::from_secs(60);
    let mut unavailable = 0;
    for v in from..to {
        let data = v.to_string().into_bytes();
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            match store
                .compare_and_set(tenant, "s", v, data.clone(), ttl)
                .await
            {
                Ok(CasOutcome::Stored { version }) => {
                    assert_eq!(version, v + 1);
                    break;
                }
                Ok(other) => panic!("push {v}: {other:?}"),
                Err(StoreError::Unavailable { reason }) => {
                    unavailable += 1;
                    assert!(Instant::now() < deadline, "push {v}: {reason}");
                    tokio::time::sleep(Duration::from_millis(20)).await;
                    if let Ok(Some(s)) = store.get(tenant, "s").await
                        && s.version == v + 1
                    {
                        assert_eq!(s.data, data);
                        break;
                    }
                }
                Err(e) => panic!("push {v}: {e}"),
            }
        }
    }
    unavailable
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_tenants_slot_migrated_during_pushes_loses_and_doubles_nothing() {
    let Some(cluster) = Cluster::start("Redis Cluster tests") else {
        return;
    };
    let store = Arc::new(store(&cluster).await);
    let tenant = "migrating";
    let ttl = Duration::from_secs(60);
    assert_eq!(
        store
            .create(tenant, "s", "correlation", b"0".to_vec(), ttl)
            .await,
        Ok(1)
    );
    let slot: u16 = cli(cluster.ports[0], &["cluster", "keyslot", tenant])
        .parse()
        .unwrap();
    let from = cluster.owner(slot);
    let to = (from + 1) % 3;
    let (from_port, to_port) = (cluster.ports[from], cluster.ports[to]);
    let (from_id, to_id) = (
        cli(from_port, &["cluster", "myid"]),
        cli(to_port, &["cluster", "myid"]),
    );
    let total = 3000u64;
    let pusher = {
        let store = store.clone();
        tokio::spawn(async move { push_exactly_once(&store, tenant, 1, total + 1).await })
    };
    // Migrate the slot while the pushes run (the steps of `redis-cli
    // --cluster reshard`, one slot).
    tokio::time::sleep(Duration::from_millis(50)).await;
    let before = store.version(tenant, "s").await.unwrap().unwrap();
    let migrate = tokio::task::spawn_blocking(move || {
        let slot = slot.to_string();
        cli(
            to_port,
            &["cluster", "setslot", &slot, "importing", &from_id],
        );
        cli(
            from_port,
            &["cluster", "setslot", &slot, "migrating", &to_id],
        );
        loop {
            let keys = cli(from_port, &["cluster", "getkeysinslot", &slot, "100"]);
            let keys: Vec<&str> = keys.lines().filter(|k| !k.is_empty()).collect();
            if keys.is_empty() {
                break;
            }
            let mut args = vec!["migrate", "127.0.0.1", "", "", "0", "5000", "KEYS"];
            let to_port = to_port.to_string();
            args[2] = &to_port;
            args.extend(keys);
            let answer = cli(from_port, &args);
            assert!(answer == "OK" || answer == "NOKEY", "MIGRATE: {answer}");
        }
        for port in [to_port, from_port] {
            cli(port, &["cluster", "setslot", &slot, "node", &to_id]);
        }
    });
    migrate.await.unwrap();
    let after = store.version(tenant, "s").await.unwrap().unwrap();
    assert!(
        1 < before && after <= total,
        "the migration ran during the pushes: versions {before} then {after} of {}",
        total + 1
    );
    let unavailable = pusher.await.unwrap();
    let s = store.get(tenant, "s").await.unwrap().unwrap();
    assert_eq!(s.version, total + 1);
    assert_eq!(s.data, total.to_string().into_bytes());
    assert_eq!(cluster.owner(slot), to, "the slot moved");
    // The keys live on the new owner only.
    let on_new = cli(to_port, &["cluster", "countkeysinslot", &slot.to_string()]);
    let on_old = cli(
        from_port,
        &["cluster", "countkeysinslot", &slot.to_string()],
    );
    assert_eq!((on_new.as_str(), on_old.as_str()), ("2", "0"));
    loud(&format!(
        "cluster: slot {slot} of tenant {tenant:?} migrated from :{from_port} to :{to_port} during \
         {total} pushes (versions {before} to {after} meanwhile); {unavailable} answered \
         Unavailable (retried once checked)"
    ));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sessions_of_a_single_redis_are_copied_to_the_cluster_layout() {
    let Some(cluster) = Cluster::start("Redis Cluster tests") else {
        return;
    };
    // A single Redis with sessions in the layout without braces.
    let port = cluster_port();
    let dir = cluster.dir.join("single");
    std::fs::create_dir_all(&dir).unwrap();
    let _single = Proc(
        Command::new("redis-server")
            .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
            .args([
                "--save",
                "",
                "--appendonly",
                "no",
                "--dir",
                dir.to_str().unwrap(),
            ])
            .stdout(Stdio::null())
            .spawn()
            .expect("redis-server starts"),
    );
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        std::thread::sleep(Duration::from_millis(50));
    }
    let single = SessionStore::connect(&StoreSettings {
        url: format!("redis://127.0.0.1:{port}/0"),
        redis: Default::default(),
        wait_replicas: 0,
        key_prefix: PREFIX.into(),
        max_sessions_per_tenant: 10,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_secs(1),
    })
    .await
    .unwrap();
    let ttl = Duration::from_secs(60);
    let tenants = ["acme", "glob:ex", "100%"];
    for (i, t) in tenants.iter().enumerate() {
        for j in 0..=i {
            let id = format!("s{j}");
            single
                .create(t, &id, "plot_fusion", vec![j as u8], ttl)
                .await
                .unwrap();
            for v in 1..=j as u64 {
                single
                    .compare_and_set(t, &id, v, vec![j as u8, v as u8], ttl)
                    .await
                    .unwrap();
            }
            // A log after the snapshot, copied with it.
            let version = j as u64 + 1;
            let expected = store::Expected {
                version,
                token: None,
            };
            single
                .write(
                    t,
                    &id,
                    expected,
                    7,
                    store::Write::Append(vec![9, j as u8]),
                    ttl,
                )
                .await
                .unwrap();
            let stored = single.get(t, &id).await.unwrap().unwrap();
            assert_eq!((stored.log.len(), stored.token), (1, 7));
        }
    }
    let target = store(&cluster).await;
    let copied = single.copy_sessions_to(&target).await.unwrap();
    assert_eq!((copied.sessions, copied.skipped), (6, 0));
    for (i, t) in tenants.iter().enumerate() {
        let listed = target.list(t).await.unwrap();
        assert_eq!(listed.len(), i + 1, "{t}");
        for (j, meta) in listed.iter().enumerate() {
            assert_eq!(
                (meta.id.as_str(), meta.kind.as_str()),
                (format!("s{j}").as_str(), "plot_fusion")
            );
            assert!(meta.ttl_remaining > Duration::from_secs(50), "{meta:?}");
            let s = target.get(t, &meta.id).await.unwrap().unwrap();
            assert_eq!(s, single.get(t, &meta.id).await.unwrap().unwrap());
        }
    }
    // Again: nothing new; the cluster cannot be a source.
    let again = single.copy_sessions_to(&target).await.unwrap();
    assert_eq!((again.sessions, again.skipped), (0, 6));
    let e = target.copy_sessions_to(&single).await.unwrap_err();
    assert!(e.to_string().contains("--from"), "{e}");
}
