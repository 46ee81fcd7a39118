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
source docker/loopback_common.sh
REDIS=$(free_port)

redis-server --port "$REDIS" --bind 127.0.0.1 --dir "$WORK" --appendonly yes --save "" >"$WORK/redis.log" 2>&1 &
PIDS+=($!)
wait_port "$REDIS"

start_replica fusion-1 "$F1H" "$F1G" "redis://127.0.0.1:$REDIS/0"
start_replica fusion-2 "$F2H" "$F2G" "redis://127.0.0.1:$REDIS/0"

start_nginx
echo "loopback: redis :$REDIS, fusion-1 :$F1H/:$F1G, fusion-2 :$F2H/:$F2G, nginx $NGINX_V :$LBH (REST) :$LBG (gRPC)"

echo "gRPC health through :$LBG: $(grpc_health "$LBG")"
if [ "$GRPC_ON_REST" = yes ]; then
  echo "gRPC health through :$LBH: $(grpc_health "$LBH")"
else
  echo "gRPC through the REST port: not tested (nginx $NGINX_V < 1.25.1 has no 'http2 on'; compose uses nginx 1.27)"
fi

session_through_balancer "$(cat "$WORK/fusion-1.pid")" "replica 1"
echo "loopback: OK"
