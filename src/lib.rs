//! The fusion centre of a radar network as a service.
//!
//! `algo` is the pure numerical core; `service` is the application layer over
//! it; `http` (axum) and `grpc` (tonic) are sibling adapters over `service`;
//! `app` wires them into one process. See ARCHITECTURE.md.

pub mod algo;
pub mod app;
pub mod asterix_udp;
pub mod auth;
pub mod config;
pub mod grpc;
pub mod http;
pub mod proto;
pub mod serve;
pub mod service;
pub mod sim;
pub mod state;
pub mod store;
pub mod telemetry;
