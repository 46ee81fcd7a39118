//! The radar fusion server: the adapters and the process around the
//! libraries of the workspace.
//!
//! `http` (axum) and `grpc` (tonic) are sibling adapters over the `service`
//! crate; `asterix_udp` feeds a session from radar datagrams; `app` wires
//! them, the `store` and the `telemetry` into one process, `serve` is the
//! accept loop (with `tls`), `config` the settings. The numerical core (`algo`) is not a
//! dependency of this crate: the adapters see only service types. See
//! ARCHITECTURE.md.

pub mod allowlist;
pub mod app;
pub mod asterix_udp;
pub mod auth;
pub mod config;
pub mod grpc;
pub mod http;
pub mod proto;
pub mod serve;
pub mod state;
pub mod telemetry;
pub mod tls;
