//! Sentinel failover against real processes on loopback: a primary, a
//! replica and three sentinels (`redis-server --sentinel`) on ports
//! 6450–6451 and 26450–26452. A session is pushed version after version
//! while the primary is SIGKILLed; every push is applied exactly once
//! (an `Unavailable` push is checked by reading, and retried with the same
//! expected version only when it did not apply).

use std::{
    process::{Child, Command, Stdio},
    time::{Duration, Instant},
};

use store::{CasOutcome, SessionStore, StoreError, StoreSettings, events::Feed};

struct Proc(Child);
impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn redis_server(args: &[&str]) -> Proc {
    Proc(
        Command::new("redis-server")
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("redis-server starts"),
    )
}

fn wait_port(port: u16) {
    for _ in 0..100 {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("nothing listens on {port}");
}

fn skip() -> bool {
    if std::env::var("FUSION_SKIP_REDIS_TESTS").is_ok_and(|v| v == "1") {
        eprintln!("SKIPPED: sentinel failover (FUSION_SKIP_REDIS_TESTS=1)");
        return true;
    }
    if Command::new("redis-server")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED: sentinel failover: redis-server is not on PATH");
        return true;
    }
    false
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pushes_survive_a_primary_kill_exactly_once() {
    if skip() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("fusion-sentinel-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Each server in its own directory: a replica's full sync writes dump.rdb there.
    let (d0, d1) = (dir.join("primary"), dir.join("replica"));
    std::fs::create_dir_all(&d0).unwrap();
    std::fs::create_dir_all(&d1).unwrap();
    let common = ["--bind", "127.0.0.1", "--save", "", "--appendonly", "no"];
    let mut primary = Some(redis_server(
        &[
            &["--port", "6450", "--dir", d0.to_str().unwrap()][..],
            &common[..],
        ]
        .concat(),
    ));
    let _replica = redis_server(
        &[
            &["--port", "6451", "--dir", d1.to_str().unwrap()][..],
            &["--replicaof", "127.0.0.1", "6450"][..],
            &common[..],
        ]
        .concat(),
    );
    wait_port(6450);
    wait_port(6451);
    let mut sentinels = Vec::new();
    for port in [26450u16, 26451, 26452] {
        let conf = dir.join(format!("sentinel-{port}.conf"));
        std::fs::write(
            &conf,
            format!(
                "port {port}\nbind 127.0.0.1\nsentinel monitor fusion 127.0.0.1 6450 2\n\
                 sentinel down-after-milliseconds fusion 1000\n\
                 sentinel failover-timeout fusion 5000\n"
            ),
        )
        .unwrap();
        sentinels.push(redis_server(&[conf.to_str().unwrap(), "--sentinel"]));
        wait_port(port);
    }
    let settings = StoreSettings {
        url: "redis+sentinel://127.0.0.1:26450,127.0.0.1:26451,127.0.0.1:26452/fusion/0".into(),
        key_prefix: "sentinel-test".into(),
        max_sessions_per_tenant: 10,
        redis: Default::default(),
        max_memory_bytes: 1 << 20,
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
            let c = redis::Client::open("redis://127.0.0.1:6450/").unwrap();
            let mut c = c.get_multiplexed_async_connection().await.unwrap();
            let mut acked = 0i64;
            for _ in 0..100 {
                acked = redis::cmd("WAIT")
                    .arg(1)
                    .arg(200)
                    .query_async(&mut c)
                    .await
                    .unwrap();
                if acked == 1 {
                    break;
                }
            }
            assert_eq!(acked, 1, "the replica acknowledged");
            drop(primary.take());
            killed_at = Some(Instant::now());
        }
        let data = format!("{v}").into_bytes();
        let deadline = Instant::now() + Duration::from_secs(45);
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
                    assert!(Instant::now() < deadline, "no primary again within 45 s");
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
    let topology = store.topology().unwrap();
    assert_eq!(topology.primary.as_deref(), Some("127.0.0.1:6451"));
    assert_eq!(topology.failovers, 1);
    assert!(topology.redirections >= 1, "{topology:?}");
    assert!(!topology.failing_over, "{topology:?}");
    eprintln!(
        "sentinel failover: kill -> first accepted push {:?}, {unavailable} Unavailable answers",
        recovered.unwrap()
    );
    drop(sentinels);
    let _ = std::fs::remove_dir_all(&dir);
}
