#!/usr/bin/env bash
# The compose topology (docker/compose.yaml) without Docker: a persistent
# Redis, two service processes sharing their sessions in it with API keys
# from a file, and nginx with docker/nginx.conf (upstream and listen
# addresses rewritten to loopback ports), all on 127.0.0.1. Then a
# correlation session runs through the balancer across both replicas, one
# replica is killed mid-session, and the session finishes on the other with
# the batch endpoint's decisions; gRPC health answers through both
# balancer ports.
#   docker/loopback.sh            (builds the release binary if needed)
# Needs nginx and redis-server (Debian: apt-get install nginx-light
# redis-server; installed when missing and apt-get is there), curl, python3.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-${CARGO_TARGET_DIR:-target}/release/radar-fusion}
[ -x "$BIN" ] || cargo build --release --bin radar-fusion
for tool in nginx redis-server; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    pkg=$([ "$tool" = nginx ] && echo nginx-light || echo redis-server)
    echo "loopback: installing $pkg"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$pkg" >/dev/null
  fi
done

WORK=$(mktemp -d /tmp/radar-fusion-loopback.XXXXXX)
PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
  [ -f "$WORK/nginx.pid" ] && kill "$(cat "$WORK/nginx.pid")" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
REDIS=$(free_port); F1H=$(free_port); F1G=$(free_port); F2H=$(free_port); F2G=$(free_port)
LBH=$(free_port); LBG=$(free_port)
wait_port() { for _ in $(seq 1 100); do (exec 3<>/dev/tcp/127.0.0.1/"$1") 2>/dev/null && return 0; sleep 0.1; done; echo "port $1 never opened" >&2; return 1; }

redis-server --port "$REDIS" --bind 127.0.0.1 --dir "$WORK" --appendonly yes --save "" >"$WORK/redis.log" 2>&1 &
PIDS+=($!)
wait_port "$REDIS"

printf '# loopback keys\nloopback-key-acme=acme\n' >"$WORK/api-keys"
start_replica() { # name http grpc
  FUSION_SESSION_STORE="redis://127.0.0.1:$REDIS/0" FUSION_API_KEYS_FILE="$WORK/api-keys" FUSION_MAX_CONNECTIONS_PER_CLIENT=0 \
  FUSION_LOG=warn FUSION_HTTP_ADDR="127.0.0.1:$2" FUSION_GRPC_ADDR="127.0.0.1:$3" \
    "$BIN" serve >"$WORK/$1.log" 2>&1 &
  PIDS+=($!)
  echo $! >"$WORK/$1.pid"
  wait_port "$2"
}
start_replica fusion-1 "$F1H" "$F1G"
start_replica fusion-2 "$F2H" "$F2G"

# docker/nginx.conf with loopback addresses; nginx older than 1.25.1 (Debian
# 12 has 1.22) knows no `http2 on`: then 8080 serves REST only, said below.
sed -e "s/fusion-1:8080/127.0.0.1:$F1H/; s/fusion-2:8080/127.0.0.1:$F2H/" \
    -e "s/fusion-1:50051/127.0.0.1:$F1G/; s/fusion-2:50051/127.0.0.1:$F2G/" \
    -e "s/listen 8080;/listen 127.0.0.1:$LBH;/; s/listen 50051 http2;/listen 127.0.0.1:$LBG http2;/" \
    docker/nginx.conf >"$WORK/nginx.conf"
NGINX_V=$(nginx -v 2>&1 | sed 's/.*nginx\///')
GRPC_ON_REST=yes
if [ "$(printf '%s\n1.25.1\n' "$NGINX_V" | sort -V | head -1)" != "1.25.1" ]; then
  sed -i 's/^    http2 on;$//' "$WORK/nginx.conf"
  GRPC_ON_REST=no
fi
nginx -p "$WORK" -c "$WORK/nginx.conf" -g "daemon on; pid $WORK/nginx.pid; error_log $WORK/nginx-error.log;"
wait_port "$LBH"
echo "loopback: redis :$REDIS, fusion-1 :$F1H/:$F1G, fusion-2 :$F2H/:$F2G, nginx $NGINX_V :$LBH (REST) :$LBG (gRPC)"

grpc_health() { # port: gRPC health Check of the server ("") through the balancer
  printf '\x00\x00\x00\x00\x00' | curl -s --http2-prior-knowledge -D - -o /dev/null \
    -H 'content-type: application/grpc' -H 'te: trailers' --data-binary @- \
    "http://127.0.0.1:$1/grpc.health.v1.Health/Check" | tr -d '\r' | grep -i '^grpc-status:' | head -1
}
echo "gRPC health through :$LBG: $(grpc_health "$LBG")"
if [ "$GRPC_ON_REST" = yes ]; then
  echo "gRPC health through :$LBH: $(grpc_health "$LBH")"
else
  echo "gRPC through the REST port: not tested (nginx $NGINX_V < 1.25.1 has no 'http2 on'; compose uses nginx 1.27)"
fi

python3 docker/loopback_session.py "http://127.0.0.1:$LBH" loopback-key-acme "$(cat "$WORK/fusion-1.pid")" \
  "http://127.0.0.1:$F1H" "http://127.0.0.1:$F2H"
echo "loopback: OK"
