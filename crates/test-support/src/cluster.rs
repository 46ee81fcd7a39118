//! A Redis Cluster on loopback for tests: three primaries
//! (`redis-server --cluster-enabled yes`, joined by `redis-cli --cluster
//! create … --cluster-yes`) on free ports whose bus ports are free too.
//! Used by `crates/store/tests/cluster.rs` and the server's
//! `tests/sessions_redis.rs`.

use std::{
    net::TcpListener,
    path::PathBuf,
    process::{Command, Stdio},
    time::{Duration, Instant},
};

use crate::procs::{Proc, cli, redis_tools, wait_port};

pub struct Cluster {
    _procs: Vec<Proc>,
    pub ports: Vec<u16>,
    pub dir: PathBuf,
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A free port whose cluster bus port (port + 10000) is free too.
pub fn cluster_port() -> u16 {
    loop {
        let l = TcpListener::bind("127.0.0.1:0").unwrap();
        let port = l.local_addr().unwrap().port();
        if port < 55000 && TcpListener::bind(("127.0.0.1", port + 10000)).is_ok() {
            return port;
        }
    }
}

impl Cluster {
    /// Starts the cluster, or `None` after a loud SKIPPED line naming
    /// `what`.
    pub fn start(what: &str) -> Option<Self> {
        redis_tools(what, &["redis-server", "redis-cli"])?;
        let ports: Vec<u16> = (0..3).map(|_| cluster_port()).collect();
        let dir = std::env::temp_dir().join(format!(
            "fusion-cluster-{}-{}",
            std::process::id(),
            ports[0]
        ));
        let mut procs = Vec::new();
        for port in &ports {
            let d = dir.join(port.to_string());
            std::fs::create_dir_all(&d).unwrap();
            procs.push(Proc(
                Command::new("redis-server")
                    .args(["--port", &port.to_string(), "--bind", "127.0.0.1"])
                    .args([
                        "--cluster-enabled",
                        "yes",
                        "--cluster-config-file",
                        "nodes.conf",
                    ])
                    .args([
                        "--cluster-node-timeout",
                        "5000",
                        "--save",
                        "",
                        "--appendonly",
                        "no",
                    ])
                    .args(["--dir", d.to_str().unwrap()])
                    .args(["--logfile", d.join("redis.log").to_str().unwrap()])
                    .stdout(Stdio::null())
                    .spawn()
                    .expect("redis-server starts"),
            ));
        }
        for port in &ports {
            wait_port(*port);
        }
        let nodes: Vec<String> = ports.iter().map(|p| format!("127.0.0.1:{p}")).collect();
        let out = Command::new("redis-cli")
            .arg("--cluster")
            .arg("create")
            .args(&nodes)
            .args(["--cluster-replicas", "0", "--cluster-yes"])
            .output()
            .expect("redis-cli --cluster create runs");
        assert!(
            out.status.success(),
            "cluster create: {}",
            String::from_utf8_lossy(&out.stdout)
        );
        let cluster = Self {
            _procs: procs,
            ports,
            dir,
        };
        let deadline = Instant::now() + Duration::from_secs(20);
        while !cluster
            .ports
            .iter()
            .all(|p| cli(*p, &["cluster", "info"]).contains("cluster_state:ok"))
        {
            assert!(Instant::now() < deadline, "the cluster is not ok");
            std::thread::sleep(Duration::from_millis(100));
        }
        Some(cluster)
    }

    /// Two of the three nodes as seeds: the client learns the third.
    pub fn url(&self) -> String {
        format!(
            "redis+cluster://127.0.0.1:{},127.0.0.1:{}",
            self.ports[0], self.ports[1]
        )
    }

    /// The store's keys each node holds.
    pub fn keys_per_node(&self, prefix: &str) -> Vec<usize> {
        self.ports
            .iter()
            .map(|p| {
                cli(*p, &["--scan", "--pattern", &format!("{prefix}:*")])
                    .lines()
                    .filter(|l| !l.is_empty())
                    .count()
            })
            .collect()
    }

    /// The node (index) that serves `slot`.
    pub fn owner(&self, slot: u16) -> usize {
        let nodes = cli(self.ports[0], &["cluster", "nodes"]);
        let id = nodes
            .lines()
            .find(|line| {
                line.split_whitespace().skip(8).any(|range| {
                    let (a, b) = range.split_once('-').unwrap_or((range, range));
                    matches!((a.parse::<u16>(), b.parse::<u16>()), (Ok(a), Ok(b)) if a <= slot && slot <= b)
                })
            })
            .and_then(|line| line.split_whitespace().next())
            .expect("a node serves the slot")
            .to_string();
        self.ports
            .iter()
            .position(|p| cli(*p, &["cluster", "myid"]) == id)
            .unwrap()
    }
}
