//! Sentinel failover against real processes on loopback: a primary, two
//! replicas and three sentinels (`redis-server --sentinel`) on free ports
//! (`common/sentinel.rs`). A session is pushed version after version
//! while the primary is SIGKILLed; every push is applied exactly once
//! (an `Unavailable` push is checked by reading, and retried with the same
//! expected version only when it did not apply).

use std::time::{Duration, Instant};

use store::{CasOutcome, SessionStore, StoreError, StoreSettings, events::Feed};

use test_support::sentinel;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pushes_survive_a_primary_kill_exactly_once() {
    let Some(mut topology) = sentinel::Topology::start("sentinel failover") else {
        return;
    };
    let settings = StoreSettings {
        url: topology.url(),
        key_prefix: "sentinel-test".into(),
        max_sessions_per_tenant: 10,
        redis: Default::default(),
        wait_replicas: 0,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_millis(500),
    };
    let store = SessionStore::connect(&settings).await.unwrap();
    let ttl = Duration::from_secs(600);
    let mut created = store
        .create("t", "s", "correlation", b"0".to_vec(), ttl)
        .await;
    while let Err(StoreError::Unavailable { .. }) = created {
        tokio::time::sleep(Duration::from_millis(100)).await;
        created = store
            .create("t", "s", "correlation", b"0".to_vec(), ttl)
            .await;
    }
    assert_eq!(created, Ok(1), "a fresh primary takes the session");
    // The event listener, subscribed on the first primary, must follow the
    // failover to the second.
    let (listener, mut feed) = store.listen(16).expect("a listener behind Sentinel");
    let channel = store.channel("t", "s").unwrap();
    listener.subscribe(channel);
    let mut heard = false;
    for _ in 0..50 {
        store.publish("t", "s", b"before").await.unwrap();
        if let Ok(Some(Feed::Message(m))) =
            tokio::time::timeout(Duration::from_millis(100), feed.recv()).await
        {
            assert_eq!(m, b"before");
            heard = true;
            break;
        }
    }
    assert!(heard, "the listener hears the first primary");
    let (mut unavailable, mut killed_at, mut recovered) = (0u32, None, None);
    let total = 40u64;
    for v in 1..=total {
        if v == 15 {
            // Let the replica catch up (as `WAIT 1` would), then kill the primary.
            topology.sync_replicas();
            topology.kill_primary();
            killed_at = Some(Instant::now());
        }
        let data = format!("{v}").into_bytes();
        let deadline = Instant::now() + Duration::from_secs(90);
        loop {
            match store.compare_and_set("t", "s", v, data.clone(), ttl).await {
                Ok(CasOutcome::Stored { version }) => {
                    assert_eq!(version, v + 1);
                    break;
                }
                Ok(other) => panic!("push {v}: {other:?}"),
                Err(StoreError::Unavailable { .. }) => {
                    unavailable += 1;
                    assert!(store.topology().unwrap().failing_over, "failing over");
                    assert!(
                        Instant::now() < deadline,
                        "no primary again within 90 s (a sentinel in TILT mode waits 30 s)"
                    );
                    tokio::time::sleep(Duration::from_millis(100)).await;
                    // Did it apply after all? Then it must not be applied twice.
                    if let Ok(Some(s)) = store.get("t", "s").await
                        && s.version == v + 1
                    {
                        assert_eq!(s.data, data);
                        break;
                    }
                }
                Err(e) => panic!("push {v}: {e}"),
            }
        }
        if killed_at.is_some() && recovered.is_none() {
            recovered = killed_at.map(|k| k.elapsed());
        }
    }
    let s = store.get("t", "s").await.unwrap().unwrap();
    assert_eq!(s.version, total + 1);
    assert_eq!(s.data, format!("{total}").into_bytes());
    // After the failover: a Resync (the subscription was lost), then the
    // new primary's messages.
    let deadline = Instant::now() + Duration::from_secs(20);
    let (mut resynced, mut heard) = (false, false);
    while !heard {
        assert!(
            Instant::now() < deadline,
            "the listener did not follow the failover"
        );
        store.publish("t", "s", b"after").await.unwrap();
        while let Ok(Some(item)) =
            tokio::time::timeout(Duration::from_millis(200), feed.recv()).await
        {
            match item {
                Feed::Resync => resynced = true,
                Feed::Message(m) if m == b"after" => heard = true,
                Feed::Message(_) => {}
            }
        }
    }
    assert!(resynced, "a Resync says messages may have been missed");
    let seen = store.topology().unwrap();
    assert_eq!(seen.primary, Some(topology.current_primary()));
    assert_ne!(
        seen.primary,
        Some(format!("127.0.0.1:{}", topology.primary_port))
    );
    assert_eq!(seen.failovers, 1);
    assert!(seen.redirections >= 1, "{seen:?}");
    assert!(!seen.failing_over, "{seen:?}");
    eprintln!(
        "sentinel failover: kill -> first accepted push {:?}, {unavailable} Unavailable answers",
        recovered.unwrap()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_switch_master_announcement_moves_the_store_before_any_command_fails() {
    let Some(topology) = sentinel::Topology::start("sentinel +switch-master") else {
        return;
    };
    let store = SessionStore::connect(&StoreSettings {
        url: topology.url(),
        redis: Default::default(),
        wait_replicas: 0,
        key_prefix: "switch-test".into(),
        max_sessions_per_tenant: 10,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_millis(500),
    })
    .await
    .unwrap();
    let ttl = Duration::from_secs(600);
    let mut created = store
        .create("t", "s", "correlation", b"0".to_vec(), ttl)
        .await;
    let deadline = Instant::now() + Duration::from_secs(10);
    while let Err(StoreError::Unavailable { .. }) = created {
        assert!(Instant::now() < deadline, "no primary at start");
        tokio::time::sleep(Duration::from_millis(100)).await;
        created = store
            .create("t", "s", "correlation", b"0".to_vec(), ttl)
            .await;
    }
    assert_eq!(created, Ok(1));
    let first = format!("127.0.0.1:{}", topology.primary_port);
    assert_eq!(store.topology().unwrap().primary, Some(first));
    topology.sync_replicas();
    // A manual failover: the old primary lives on as a replica, so nothing
    // fails; only the sentinels' announcement tells the store.
    // (Refused with NOGOODSLAVE until the sentinels have found the replicas
    // in the primary's INFO.)
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let out = std::process::Command::new("redis-cli")
            .args(["-p", &topology.sentinel_ports[0].to_string()])
            .args(["SENTINEL", "FAILOVER", sentinel::MASTER])
            .output()
            .expect("redis-cli runs");
        let answer = String::from_utf8_lossy(&out.stdout).trim().to_string();
        if answer == "OK" {
            break;
        }
        assert!(Instant::now() < deadline, "SENTINEL FAILOVER: {answer}");
        tokio::time::sleep(Duration::from_millis(200)).await;
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    while store.topology().unwrap().primary.is_some() {
        assert!(
            Instant::now() < deadline,
            "+switch-master did not drop the primary"
        );
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // The next command goes to the new primary at once.
    assert_eq!(
        store.compare_and_set("t", "s", 1, b"1".to_vec(), ttl).await,
        Ok(CasOutcome::Stored { version: 2 })
    );
    let seen = store.topology().unwrap();
    assert_eq!(seen.primary, Some(topology.current_primary()));
    assert_ne!(
        seen.primary,
        Some(format!("127.0.0.1:{}", topology.primary_port))
    );
    assert_eq!((seen.failovers, seen.failing_over), (1, false));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_write_fewer_replicas_hold_than_waited_for_is_unavailable_not_lost() {
    let Some(topology) = sentinel::Topology::start("sentinel WAIT") else {
        return;
    };
    let settings = |wait_replicas| StoreSettings {
        url: topology.url(),
        redis: Default::default(),
        wait_replicas,
        key_prefix: "wait-test".into(),
        max_sessions_per_tenant: 10,
        max_memory_bytes: 1 << 20,
        max_memory_bytes_per_tenant: 1 << 20,
        timeout: Duration::from_millis(500),
    };
    let ttl = Duration::from_secs(600);
    // Two replicas hold it: done.
    let two = SessionStore::connect(&settings(2)).await.unwrap();
    let mut created = two
        .create("t", "a", "correlation", b"0".to_vec(), ttl)
        .await;
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut retried = false;
    while let Err(StoreError::Unavailable { .. }) = created {
        assert!(Instant::now() < deadline, "no primary at start");
        tokio::time::sleep(Duration::from_millis(100)).await;
        retried = true;
        created = two
            .create("t", "a", "correlation", b"0".to_vec(), ttl)
            .await;
    }
    // An attempt the replicas did not confirm in time (a loaded machine)
    // may still have landed: its retry then finds the session, at version 1.
    if retried && created == Err(StoreError::AlreadyExists) {
        let stored = two
            .get("t", "a")
            .await
            .unwrap()
            .expect("the session landed");
        assert_eq!(stored.version, 1);
        created = Ok(1);
    }
    assert_eq!(created, Ok(1));
    // Three are waited for, two exist: "unavailable", though the primary
    // has it (a retry with the same expected version then sees it applied).
    let three = SessionStore::connect(&settings(3)).await.unwrap();
    match three.compare_and_set("t", "a", 1, b"1".to_vec(), ttl).await {
        // Two replicas exist; on a loaded machine one of them may not
        // acknowledge within the timeout either (seen in CI: "1 of the 3").
        Err(StoreError::Unavailable { reason }) => assert!(
            reason.contains("reached 2 of the 3 replicas")
                || reason.contains("reached 1 of the 3 replicas"),
            "{reason}"
        ),
        other => panic!("{other:?}"),
    }
    assert_eq!(three.version("t", "a").await, Ok(Some(2)));
}
