//! A Sentinel deployment on loopback for tests: a primary, a replica and
//! three sentinels (`redis-server --sentinel`, quorum 2, down after 1 s) on
//! free ports, each server in a scratch directory of its own. Included by
//! path from `crates/store/tests/sentinel_failover.rs` and the server's
//! `tests/sessions_sentinel.rs`.

// Shared by test targets: `pub` is for the modules that include it.
#![allow(unreachable_pub)]
#![allow(dead_code)] // each test crate uses its own part

use std::{
    io::Write,
    net::TcpListener,
    path::PathBuf,
    process::{Child, Command, Stdio},
    time::{Duration, Instant},
};

/// The master name the sentinels monitor.
pub const MASTER: &str = "fusion";

/// A process killed (SIGKILL) and reaped when dropped.
pub struct Proc(Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

pub struct Topology {
    dir: PathBuf,
    primary: Option<Proc>,
    _replica: Proc,
    _sentinels: Vec<Proc>,
    /// Ports of the first primary and of its replica.
    pub primary_port: u16,
    pub replica_port: u16,
    pub sentinel_ports: Vec<u16>,
}

/// One loud line on the real standard error (the harness captures
/// `eprintln!` of passing tests, and a skip must be seen).
pub fn loud(line: &str) {
    let _ = writeln!(std::io::stderr(), "\n!!!!!!!! {line}\n");
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn wait_port(port: u16) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("nothing listens on {port}");
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

impl Topology {
    /// Starts the deployment, or `None` after a loud SKIPPED line naming
    /// `what` when redis-server is not on PATH or `FUSION_SKIP_REDIS_TESTS=1`.
    pub fn start(what: &str) -> Option<Self> {
        if std::env::var("FUSION_SKIP_REDIS_TESTS").is_ok_and(|v| v == "1") {
            loud(&format!("SKIPPED: {what} (FUSION_SKIP_REDIS_TESTS=1)"));
            return None;
        }
        if Command::new("redis-server")
            .arg("--version")
            .output()
            .is_err()
        {
            loud(&format!(
                "SKIPPED: {what}: redis-server is not on PATH (apt-get install redis-server)"
            ));
            return None;
        }
        let (primary_port, replica_port) = (free_port(), free_port());
        let dir = std::env::temp_dir().join(format!(
            "fusion-sentinel-{}-{primary_port}",
            std::process::id()
        ));
        // Each server in its own directory: a replica's full sync writes
        // dump.rdb there.
        let server = |port: u16, extra: &[&str]| {
            let d = dir.join(port.to_string());
            std::fs::create_dir_all(&d).unwrap();
            let port = port.to_string();
            let log = d.join("redis.log");
            let mut args = vec!["--port", &port, "--dir", d.to_str().unwrap()];
            args.extend(["--logfile", log.to_str().unwrap()]);
            args.extend(["--bind", "127.0.0.1", "--save", "", "--appendonly", "no"]);
            args.extend(extra);
            redis_server(&args)
        };
        let primary = server(primary_port, &[]);
        let replica = server(
            replica_port,
            &["--replicaof", "127.0.0.1", &primary_port.to_string()],
        );
        wait_port(primary_port);
        wait_port(replica_port);
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
            _replica: replica,
            _sentinels: sentinels,
            primary_port,
            replica_port,
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

    /// Waits until the replica has every write of the primary (`WAIT 1`,
    /// through redis-cli).
    pub fn sync_replica(&self) {
        for _ in 0..100 {
            let out = Command::new("redis-cli")
                .args(["-p", &self.primary_port.to_string(), "WAIT", "1", "200"])
                .output()
                .expect("redis-cli runs");
            if String::from_utf8_lossy(&out.stdout).trim() == "1" {
                return;
            }
        }
        panic!("the replica did not acknowledge");
    }

    /// SIGKILLs the first primary.
    pub fn kill_primary(&mut self) {
        drop(self.take_primary());
    }

    /// The first primary's process, SIGKILLed when dropped (from another
    /// thread, to kill it while a test pushes).
    pub fn take_primary(&mut self) -> Option<Proc> {
        self.primary.take()
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
