//! Compiles the gRPC contract in `proto/` with protox (pure Rust, no `protoc`)
//! and writes the file descriptor set used by gRPC server reflection.

use std::{env, path::PathBuf};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=proto");
    let files = [
        "proto/radar/fusion/v1/ais.proto",
        "proto/radar/fusion/v1/common.proto",
        "proto/radar/fusion/v1/correlation.proto",
        "proto/radar/fusion/v1/dimension.proto",
        "proto/radar/fusion/v1/jpda.proto",
        "proto/radar/fusion/v1/plot_fusion.proto",
        "proto/radar/fusion/v1/session.proto",
    ];
    let fds = protox::compile(files, ["proto"])?;
    let out = PathBuf::from(env::var("OUT_DIR")?);
    std::fs::write(
        out.join("radar_fusion_descriptor.bin"),
        prost::Message::encode_to_vec(&fds),
    )?;
    tonic_prost_build::configure()
        // Malformed protobuf is INVALID_ARGUMENT, not INTERNAL (src/proto/codec.rs).
        .codec_path("crate::proto::codec::ProtoCodec")
        // Decoded by hand: packed doubles a chunk at a time (src/proto/matrix.rs).
        .extern_path(".radar.fusion.v1.Matrix", "crate::proto::matrix::Matrix")
        .build_client(true)
        .build_server(true)
        .compile_fds(fds)?;
    Ok(())
}
