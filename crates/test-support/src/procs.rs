//! Processes for the Redis tests: a child killed (SIGKILL) and reaped when
//! dropped, free loopback ports, waiting for a port, `redis-cli`, and loud
//! lines the test harness does not capture; the processes of
//! [`crate::sentinel`] and [`crate::cluster`].

use std::{
    io::Write,
    net::TcpListener,
    process::{Child, Command},
    time::{Duration, Instant},
};

/// A process killed (SIGKILL) and reaped when dropped.
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// One loud line on the real standard error (the harness captures
/// `eprintln!` of passing tests, and a skip must be seen).
pub fn loud(line: &str) {
    let _ = writeln!(std::io::stderr(), "\n!!!!!!!! {line}\n");
}

/// `None` after a loud SKIPPED line naming `what` when one of `tools` is not
/// on PATH or `FUSION_SKIP_REDIS_TESTS=1`.
pub fn redis_tools(what: &str, tools: &[&str]) -> Option<()> {
    if std::env::var("FUSION_SKIP_REDIS_TESTS").is_ok_and(|v| v == "1") {
        loud(&format!("SKIPPED: {what} (FUSION_SKIP_REDIS_TESTS=1)"));
        return None;
    }
    for tool in tools {
        if Command::new(tool).arg("--version").output().is_err() {
            loud(&format!(
                "SKIPPED: {what}: {tool} is not on PATH (apt-get install redis-server)"
            ));
            return None;
        }
    }
    Some(())
}

pub fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

pub fn wait_port(port: u16) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while Instant::now() < deadline {
        if std::net::TcpStream::connect(("127.0.0.1", port)).is_ok() {
            return;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    panic!("nothing listens on {port}");
}

/// `redis-cli -p PORT ARGS…`, its standard output trimmed.
pub fn cli(port: u16, args: &[&str]) -> String {
    let out = Command::new("redis-cli")
        .args(["-p", &port.to_string()])
        .args(args)
        .output()
        .expect("redis-cli runs");
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}
