//! Test harnesses shared by the workspace's test targets, so that no test
//! includes another crate's files by path: a dev-dependency of `store`,
//! `service` and the server.
//!
//! - [`redis`]: the Redis of a test binary (the shared one on
//!   127.0.0.1:6379, or a private `redis-server`), unique key prefixes,
//!   private servers for outage tests;
//! - [`procs`]: child processes killed when dropped, free ports,
//!   `redis-cli`;
//! - [`sentinel`] and [`cluster`]: a Sentinel deployment and a Redis
//!   Cluster on loopback.

pub mod cluster;
pub mod procs;
pub mod redis;
pub mod sentinel;
