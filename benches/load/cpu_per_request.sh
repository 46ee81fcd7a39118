#!/usr/bin/env bash
# Issue 18's request-path figures for one server binary, in one run:
# requests/s and the server's CPU µs per request (user + system time of the
# process from /proc over the requests wrk counted) for the rules endpoint
# and the small correlation request at 64 connections, then the JPDA
# 500-target update's compute / server / client times and the server's CPU
# per call over REST and gRPC.
#   cargo run --release --example correlation_payload -- 5 grid > /tmp/corr-5.json
#   benches/load/cpu_per_request.sh target/release/radar-fusion
# Alternate binaries (before, after, before, after) on a shared machine.
set -euo pipefail
BIN=$1
cd "$(dirname "$0")/../.."
BODY=${BODY:-/tmp/corr-5.json}
"$BIN" serve --http-addr 127.0.0.1:8080 --grpc-addr 127.0.0.1:50051 >/tmp/cpu_per_request.log 2>&1 &
PID=$!
trap 'kill $PID 2>/dev/null' EXIT
sleep 1
ticks() { awk '{print $14 + $15}' "/proc/$PID/stat"; }
hz=$(getconf CLK_TCK)
one() {
  local label=$1; shift
  local t0 out t1 n rps
  t0=$(ticks); out=$("$@"); t1=$(ticks)
  n=$(echo "$out" | awk '/requests in/ {print $1}')
  rps=$(echo "$out" | awk '/Requests\/sec/ {print $2}')
  echo "$label: $rps req/s, server CPU $(awk -v a="$t0" -v b="$t1" -v n="$n" -v hz="$hz" 'BEGIN {printf "%.1f", (b - a) * 1e6 / hz / n}') µs per request"
}
one "rules endpoint" wrk -t2 -c64 -d6s -s benches/load/evaluate.lua http://127.0.0.1:8080
BODY=$BODY one "small correlation" wrk -t2 -c64 -d6s -s benches/load/correlation.lua http://127.0.0.1:8080
# The JPDA update one transport at a time, with the server's CPU per call
# (the 5 warm-up calls counted in).
REPEAT=${REPEAT:-150}
cargo build --quiet --release --example request_path
for transport in rest grpc; do
  t0=$(ticks)
  line=$(target/release/examples/request_path --repeat "$REPEAT" --only "$transport" | grep -E '^(REST|gRPC)')
  t1=$(ticks)
  echo "$line | server CPU $(awk -v a="$t0" -v b="$t1" -v n="$((REPEAT + 5))" -v hz="$hz" 'BEGIN {printf "%.3f", (b - a) * 1e3 / hz / n}') ms per call"
done
