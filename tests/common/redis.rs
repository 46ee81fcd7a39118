//! Redis for the integration tests: the shared Redis on 127.0.0.1:6379 (a
//! loud failure when it is down, unless `FUSION_SKIP_REDIS_TESTS=1`), unique
//! key prefixes, and private `redis-server` processes for outage tests.
//! Included by `tests/store.rs` and `tests/sessions_redis.rs`.
#![allow(dead_code)] // each test crate uses its own part

use std::{
    net::{SocketAddr, TcpListener, TcpStream},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::atomic::{AtomicU64, Ordering},
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

pub const REDIS_ADDR: &str = "127.0.0.1:6379";
pub const REDIS_URL: &str = "redis://127.0.0.1:6379/0";

pub fn skip_redis() -> bool {
    std::env::var("FUSION_SKIP_REDIS_TESTS").is_ok_and(|v| v == "1")
}

/// Whether Redis runs on 127.0.0.1:6379; `false` (with a loud warning) only
/// when it does not and `FUSION_SKIP_REDIS_TESTS=1`; panics otherwise.
pub fn redis_is_up() -> bool {
    let addr: SocketAddr = REDIS_ADDR.parse().expect("literal address");
    if TcpStream::connect_timeout(&addr, Duration::from_secs(1)).is_ok() {
        return true;
    }
    let message = "Redis is not running on 127.0.0.1:6379: start it with \
         `redis-server --port 6379 --save '' --daemonize yes` — .ci/run does this";
    if skip_redis() {
        eprintln!(
            "\n!!!!!!!! WARNING: SKIPPING REDIS TEST (FUSION_SKIP_REDIS_TESTS=1): {message}\n"
        );
        return false;
    }
    panic!("\n\n{message}\n(set FUSION_SKIP_REDIS_TESTS=1 to skip the Redis tests)\n");
}

/// Whether `redis-server` is on PATH; `false` (with a loud warning) only when
/// it is not and `FUSION_SKIP_REDIS_TESTS=1`; panics otherwise.
pub fn redis_server_available() -> bool {
    if Command::new("redis-server")
        .arg("--version")
        .output()
        .is_ok()
    {
        return true;
    }
    let message = "redis-server is not on PATH: install it (apt-get install redis-server)";
    if skip_redis() {
        eprintln!("\n!!!!!!!! WARNING: SKIPPING REDIS OUTAGE TEST: {message}\n");
        return false;
    }
    panic!("{message}");
}

/// A name unique to this call (process id, clock, counter) under `tag`.
pub fn unique(tag: &str) -> String {
    static RUN: AtomicU64 = AtomicU64::new(0);
    let nanos = SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .expect("clock after 1970")
        .as_nanos();
    format!(
        "{tag}{}-{nanos}-{}",
        std::process::id(),
        RUN.fetch_add(1, Ordering::Relaxed)
    )
}

pub fn free_port() -> u16 {
    let listener = TcpListener::bind("127.0.0.1:0").expect("bind port 0");
    listener.local_addr().expect("bound").port()
}

/// A redis-server child process on a port of its own, killed on drop. With a
/// directory it keeps an append-only file there (so that its data survive a
/// restart, and the directory is removed on drop); without one it keeps
/// nothing.
pub struct RedisServer {
    pub port: u16,
    dir: Option<PathBuf>,
    child: Option<Child>,
}

impl RedisServer {
    /// Starts the server; it may not accept connections yet.
    pub fn start(port: u16, dir: Option<PathBuf>) -> Self {
        let child = Self::spawn(port, dir.as_deref());
        Self {
            port,
            dir,
            child: Some(child),
        }
    }

    fn spawn(port: u16, dir: Option<&Path>) -> Child {
        let mut command = Command::new("redis-server");
        command
            .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
            .args(["--save", ""]);
        match dir {
            Some(dir) => {
                std::fs::create_dir_all(dir).expect("redis data directory");
                command
                    .args(["--appendonly", "yes", "--appendfsync", "always"])
                    .arg("--dir")
                    .arg(dir);
            }
            None => {
                command.args(["--appendonly", "no"]);
            }
        }
        command
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("redis-server is on PATH (apt-get install redis-server)")
    }

    /// A persistent server on a free port in a fresh temporary directory,
    /// accepting connections.
    pub fn persistent() -> Self {
        let dir = std::env::temp_dir().join(unique("radar-fusion-sessions-redis-"));
        let server = Self::start(free_port(), Some(dir));
        server.wait_accepting();
        server
    }

    pub fn wait_accepting(&self) {
        let addr: SocketAddr = format!("127.0.0.1:{}", self.port).parse().unwrap();
        let start = Instant::now();
        while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "redis-server did not start on port {}",
                self.port
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Kills the server at once (SIGKILL): no shutdown save.
    pub fn kill(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Starts it again on the same port and directory, and waits for it.
    pub fn restart(&mut self) {
        self.kill();
        self.child = Some(Self::spawn(self.port, self.dir.as_deref()));
        self.wait_accepting();
    }

    /// Sends a signal (`STOP`, `CONT`, …) with kill(1).
    pub fn signal(&self, name: &str) {
        let pid = self.child.as_ref().expect("running").id().to_string();
        let status = Command::new("kill")
            .args([&format!("-{name}"), &pid])
            .status()
            .expect("kill(1) runs");
        assert!(status.success(), "kill -{name} {pid}");
    }

    pub fn url(&self) -> String {
        format!("redis://127.0.0.1:{}/0", self.port)
    }
}

impl Drop for RedisServer {
    fn drop(&mut self) {
        self.kill();
        if let Some(dir) = &self.dir {
            let _ = std::fs::remove_dir_all(dir);
        }
    }
}
