//! A Sentinel deployment on loopback for tests: a primary, two replicas and
//! three sentinels (`redis-server --sentinel`, quorum 2, down after 1 s) on
//! free ports, each server in a scratch directory of its own. Used by
//! `crates/store/tests/sentinel_failover.rs` and the server's
//! `tests/sessions_redis.rs`.

use std::{
    io::Write,
    path::PathBuf,
    process::{Command, Stdio},
    time::{Duration, Instant},
};

use crate::procs::{Proc, cli, free_port, loud, redis_tools, wait_port};

/// The master name the sentinels monitor.
pub const MASTER: &str = "fusion";

pub struct Topology {
    dir: PathBuf,
    primary: Option<Proc>,
    _replicas: Vec<Proc>,
    _sentinels: Vec<Proc>,
    /// Ports of the first primary and of its replicas (one of which the
    /// sentinels promote when it dies; the other then replicates it, so a
    /// write that waits for one replica still can).
    pub primary_port: u16,
    pub replica_ports: Vec<u16>,
    pub sentinel_ports: Vec<u16>,
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

/// One data server in its own directory (a replica's full sync writes
/// dump.rdb there), logging to `redis.log` in it.
fn start_server(dir: &std::path::Path, port: u16, extra: &[&str]) -> Proc {
    let d = dir.join(port.to_string());
    std::fs::create_dir_all(&d).unwrap();
    let log = d.join("redis.log");
    let port = port.to_string();
    let mut args = vec!["--port", &port, "--dir", d.to_str().unwrap()];
    args.extend(["--logfile", log.to_str().unwrap()]);
    args.extend(["--bind", "127.0.0.1", "--save", "", "--appendonly", "no"]);
    args.extend(extra);
    redis_server(&args)
}

impl Topology {
    /// Starts the deployment, or `None` after a loud SKIPPED line naming
    /// `what` when redis-server is not on PATH or `FUSION_SKIP_REDIS_TESTS=1`.
    pub fn start(what: &str) -> Option<Self> {
        redis_tools(what, &["redis-server", "redis-cli"])?;
        let primary_port = free_port();
        let replica_ports = vec![free_port(), free_port()];
        let dir = std::env::temp_dir().join(format!(
            "fusion-sentinel-{}-{primary_port}",
            std::process::id()
        ));
        let primary = start_server(&dir, primary_port, &[]);
        let replicas: Vec<Proc> = replica_ports
            .iter()
            .map(|port| {
                start_server(
                    &dir,
                    *port,
                    &["--replicaof", "127.0.0.1", &primary_port.to_string()],
                )
            })
            .collect();
        wait_port(primary_port);
        for port in &replica_ports {
            wait_port(*port);
            // A replica that has not finished its first sync has nothing to
            // take over, and writes that wait for it would fail.
            let deadline = Instant::now() + Duration::from_secs(20);
            while !cli(*port, &["INFO", "replication"]).contains("master_link_status:up") {
                assert!(Instant::now() < deadline, "replica :{port} never synced");
                std::thread::sleep(Duration::from_millis(50));
            }
        }
        let mut sentinels = Vec::new();
        let mut sentinel_ports = Vec::new();
        for _ in 0..3 {
            let port = free_port();
            let conf = dir.join(format!("sentinel-{port}.conf"));
            std::fs::write(
                &conf,
                format!(
                    "port {port}\nbind 127.0.0.1\ndir {}\nlogfile {}/sentinel-{port}.log\n\
                     sentinel monitor {MASTER} 127.0.0.1 {primary_port} 2\n\
                     sentinel down-after-milliseconds {MASTER} 1000\n\
                     sentinel failover-timeout {MASTER} 5000\n",
                    dir.display(),
                    dir.display()
                ),
            )
            .unwrap();
            sentinels.push(redis_server(&[conf.to_str().unwrap(), "--sentinel"]));
            wait_port(port);
            sentinel_ports.push(port);
        }
        Some(Self {
            dir,
            primary: Some(primary),
            _replicas: replicas,
            _sentinels: sentinels,
            primary_port,
            replica_ports,
            sentinel_ports,
        })
    }

    /// `redis+sentinel://` URL of the three sentinels, database 0.
    pub fn url(&self) -> String {
        let hosts: Vec<String> = self
            .sentinel_ports
            .iter()
            .map(|p| format!("127.0.0.1:{p}"))
            .collect();
        format!("redis+sentinel://{}/{MASTER}/0", hosts.join(","))
    }

    /// Waits until both replicas have every write of the primary: a write
    /// and `WAIT 2` on one connection (WAIT waits for its own connection's
    /// writes only, so alone on a fresh connection it returns at once).
    pub fn sync_replicas(&self) {
        for _ in 0..100 {
            let mut child = Command::new("redis-cli")
                .args(["-p", &self.primary_port.to_string()])
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .spawn()
                .expect("redis-cli runs");
            child
                .stdin
                .take()
                .unwrap()
                .write_all(b"SET fusion-test:sync 1\nWAIT 2 200\n")
                .unwrap();
            let out = child.wait_with_output().unwrap();
            if String::from_utf8_lossy(&out.stdout).lines().nth(1) == Some("2") {
                return;
            }
        }
        panic!("the replicas did not acknowledge");
    }

    /// SIGKILLs the first primary.
    pub fn kill_primary(&mut self) {
        drop(self.primary.take());
    }

    /// The primary the first sentinel names, `host:port`.
    pub fn current_primary(&self) -> String {
        cli(
            self.sentinel_ports[0],
            &["SENTINEL", "get-master-addr-by-name", MASTER],
        )
        .replace('\n', ":")
    }
}

impl Drop for Topology {
    fn drop(&mut self) {
        self.primary.take();
        if std::thread::panicking() {
            loud(&format!(
                "the Sentinel deployment's logs are kept in {}",
                self.dir.display()
            ));
        } else {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
    }
}
