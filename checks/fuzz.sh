#!/usr/bin/env bash
# Fuzzes the decoders of untrusted bytes (issue 53) on stable Rust: ASTERIX
# CAT048/CAT034/CAT021/CAT020, NMEA, stored sessions of both kinds, stored
# tracker state, session events and the X.509 fields read from client
# certificates, each for FUZZ_SECONDS (60 s by default) of mutated inputs
# from fuzz/corpus/ and the fixtures (examples/fuzz.rs says how). Fails,
# with the inputs in target/fuzz-crashes/, when a decoder panics.
#
#   checks/fuzz.sh                  # every target, 60 s each
#   FUZZ_SECONDS=600 checks/fuzz.sh asterix nmea
set -euo pipefail
cd "$(dirname "$0")/.."
seconds="${FUZZ_SECONDS:-60}"
seed="${FUZZ_SEED:-$(date +%s)}"
echo "fuzz: ${seconds} s per target, seed ${seed}"
cargo run --release --quiet --example fuzz -- --seconds "$seconds" --seed "$seed" "$@"
