//! Redis for the integration tests: the shared Redis on 127.0.0.1:6379, or
//! a private `redis-server` started on a free port when none answers there,
//! or a loud skip when redis-server is not installed (or
//! `FUSION_SKIP_REDIS_TESTS=1`); unique key prefixes, and private
//! `redis-server` processes for outage tests.
//! Used by `crates/store/tests/store.rs`,
//! `crates/service/tests/session_kinds.rs` and `tests/sessions_redis.rs`.

use std::{
    net::{SocketAddr, TcpListener, TcpStream},
    path::{Path, PathBuf},
    process::{Child, Command, Stdio},
    sync::{
        OnceLock,
        atomic::{AtomicU64, Ordering},
    },
    time::{Duration, Instant, SystemTime, UNIX_EPOCH},
};

pub const REDIS_ADDR: &str = "127.0.0.1:6379";

pub fn skip_redis() -> bool {
    std::env::var("FUSION_SKIP_REDIS_TESTS").is_ok_and(|v| v == "1")
}

/// The Redis this test binary uses: the shared one on 127.0.0.1:6379 when
/// it answers, else a private `redis-server` on a free port started once
/// (and stopped when the test binary exits), else none.
static REDIS: OnceLock<Option<String>> = OnceLock::new();

/// A line on the real standard error: the test harness captures `eprintln!`
/// of passing tests, and a skip must be seen.
/// The test's name is its thread's.
fn loud(line: &str) {
    use std::io::Write;
    let test = std::thread::current().name().unwrap_or("?").to_string();
    let _ = writeln!(std::io::stderr(), "\n!!!!!!!! {test}: {line}\n");
}

fn loud_skip(what: &str) {
    loud(&format!(
        "SKIPPED: {what}: no Redis answers on {REDIS_ADDR} and redis-server is not on PATH. \
         Install it (apt-get install redis-server) or start Redis on {REDIS_ADDR} to run the \
         Redis tests; .ci/run does."
    ));
}

/// Whether a Redis is available for the shared-store tests (see
/// [`redis_url`]); `false`, with one loud line naming what is skipped,
/// only when none can be had or `FUSION_SKIP_REDIS_TESTS=1`.
pub fn redis_is_up() -> bool {
    if skip_redis() {
        loud("SKIPPED: a Redis test (FUSION_SKIP_REDIS_TESTS=1)");
        return false;
    }
    let up = REDIS
        .get_or_init(|| {
            // FUSION_TEST_REDIS_ADDR moves the shared Redis (a dead address
            // there tries the fallbacks).
            let shared =
                std::env::var("FUSION_TEST_REDIS_ADDR").unwrap_or_else(|_| REDIS_ADDR.to_string());
            let addr: SocketAddr = shared.parse().expect("FUSION_TEST_REDIS_ADDR is host:port");
            if TcpStream::connect_timeout(&addr, Duration::from_secs(1)).is_ok() {
                return Some(format!("redis://{shared}/0"));
            }
            if !redis_server_on_path() {
                return None;
            }
            let port = free_port();
            // The server lives as long as this test binary: a watcher
            // shell stops it when this process is gone.
            let me = std::process::id();
            let script = format!(
                "redis-server --port {port} --bind 127.0.0.1 --save '' --appendonly no \
                 >/dev/null 2>&1 & r=$!; while kill -0 {me} 2>/dev/null; do sleep 1; done; \
                 kill $r"
            );
            // Never waited for: the watcher outlives the tests by design.
            #[allow(clippy::zombie_processes)]
            Command::new("sh")
                .args(["-c", &script])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("sh runs");
            let addr: SocketAddr = format!("127.0.0.1:{port}").parse().unwrap();
            let start = Instant::now();
            while TcpStream::connect_timeout(&addr, Duration::from_millis(200)).is_err() {
                if start.elapsed() > Duration::from_secs(10) {
                    return None;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            eprintln!("redis: none on {shared}; started a private redis-server on port {port}");
            Some(format!("redis://127.0.0.1:{port}/0"))
        })
        .is_some();
    if !up {
        loud_skip("a test of the Redis session store");
    }
    up
}

/// The URL of the Redis of [`redis_is_up`] (call that first).
pub fn redis_url() -> String {
    REDIS
        .get()
        .cloned()
        .flatten()
        .expect("redis_is_up() said true")
}

fn redis_server_on_path() -> bool {
    Command::new("redis-server")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok()
}

/// Whether `redis-server` is on PATH (the outage tests start their own);
/// `false`, with one loud line, when it is not or `FUSION_SKIP_REDIS_TESTS=1`.
pub fn redis_server_available() -> bool {
    if skip_redis() {
        loud("SKIPPED: a Redis outage test (FUSION_SKIP_REDIS_TESTS=1)");
        return false;
    }
    if redis_server_on_path() {
        return true;
    }
    loud_skip("a Redis outage test (it starts and kills its own redis-server)");
    false
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
