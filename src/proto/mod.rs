//! The generated gRPC contract (`proto/radar/fusion/v1`), compiled by build.rs
//! with protox, and its encoded file descriptor set for server reflection.
#![allow(clippy::all, clippy::pedantic, missing_docs)]

tonic::include_proto!("radar.fusion.v1");

/// The encoded `FileDescriptorSet` of `radar.fusion.v1`, served by reflection.
pub const FILE_DESCRIPTOR_SET: &[u8] =
    include_bytes!(concat!(env!("OUT_DIR"), "/radar_fusion_descriptor.bin"));

pub mod codec;
pub mod matrix;

pub use matrix::Matrix;
