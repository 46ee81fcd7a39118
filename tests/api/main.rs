//! Black-box tests through the real servers: one test binary, one
//! `spawn_app` helper that starts REST and gRPC on port 0.

mod accuracy;
mod ais_radar;
mod asterix;
mod auth;
mod cat062;
mod compression;
mod connections;
mod cooperative;
mod correlation;
mod dimension;
mod docs_examples;
mod errors;
mod events;
mod fuzz;
mod grpc;
mod helpers;
mod hostile;
mod hostile_bodies;
mod jpda;
mod ops;
mod plot_fusion;
mod rules;
mod sessions;
mod ssr;
mod tls;
