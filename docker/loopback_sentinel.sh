#!/usr/bin/env bash
# The Sentinel topology (docker/compose.sentinel.yaml) without Docker: a
# Redis primary, its replica, three sentinels (quorum 2), two service
# processes on `redis+sentinel://`, and nginx with docker/nginx.conf, all on
# 127.0.0.1. A correlation session runs through the balancer across both
# replicas; the Redis primary is SIGKILLed halfway; the sentinels promote
# the replica, both service replicas follow it, every batch answered
# 502/503/504 meanwhile is retried with its sequence number, and the session
# finishes with every batch applied once and the batch endpoint's
# decisions. Prints the time from the kill to the first accepted batch, the
# refused answers, and /healthz/store and the failover counters of both
# replicas.
#   docker/loopback_sentinel.sh   (builds the release binary if needed;
#                                  BIN=path/to/radar-fusion to use another)
# Needs nginx and redis-server (installed when missing and apt-get is
# there), curl, python3.
set -euo pipefail
cd "$(dirname "$0")/.."
source docker/loopback_common.sh
PRIMARY=$(free_port); REPLICA=$(free_port)
S1=$(free_port); S2=$(free_port); S3=$(free_port)

redis_node() { # name port [args…]
  local name=$1 port=$2; shift 2
  mkdir -p "$WORK/$name"
  redis-server --port "$port" --bind 127.0.0.1 --dir "$WORK/$name" --appendonly yes --save "" \
    --logfile "$WORK/$name.log" "$@" &
  PIDS+=($!)
  echo $! >"$WORK/$name.pid"
  wait_port "$port"
}
redis_node redis-primary "$PRIMARY"
redis_node redis-replica "$REPLICA" --replicaof 127.0.0.1 "$PRIMARY"
# A replica that has not finished its first sync has nothing to take over.
for _ in $(seq 1 100); do
  redis-cli -p "$REPLICA" info replication | grep -q '^master_link_status:up' && break
  sleep 0.1
done
redis-cli -p "$REPLICA" info replication | grep -q '^master_link_status:up' \
  || { echo "the replica never synced with the primary" >&2; exit 1; }
# The same sentinel settings as docker/compose.sentinel.yaml.
for s in "$S1" "$S2" "$S3"; do
  cat >"$WORK/sentinel-$s.conf" <<CONF
port $s
bind 127.0.0.1
dir $WORK
logfile $WORK/sentinel-$s.log
sentinel monitor fusion 127.0.0.1 $PRIMARY 2
sentinel down-after-milliseconds fusion 2000
sentinel failover-timeout fusion 10000
sentinel parallel-syncs fusion 1
CONF
  redis-server "$WORK/sentinel-$s.conf" --sentinel &
  PIDS+=($!)
  wait_port "$s"
done

STORE="redis+sentinel://127.0.0.1:$S1,127.0.0.1:$S2,127.0.0.1:$S3/fusion/0"
start_replica fusion-1 "$F1H" "$F1G" "$STORE"
start_replica fusion-2 "$F2H" "$F2G" "$STORE"
start_nginx
echo "loopback: redis primary :$PRIMARY, replica :$REPLICA, sentinels :$S1 :$S2 :$S3, fusion-1 :$F1H, fusion-2 :$F2H, nginx $NGINX_V :$LBH (REST) :$LBG (gRPC)"
echo "gRPC health through :$LBG: $(grpc_health "$LBG")"
for r in "$F1H" "$F2H"; do echo "fusion :$r /healthz/store: $(curl -s "http://127.0.0.1:$r/healthz/store")"; done

session_through_balancer "$(cat "$WORK/redis-primary.pid")" "the Redis primary"

# /metrics takes a tenant's key (the API keys are on); /healthz/store
# names no host, so the promoted replica is asked for its role instead.
METRICS_AUTH="authorization: Bearer loopback-key-acme"
for r in "$F1H" "$F2H"; do
  health=$(curl -s "http://127.0.0.1:$r/healthz/store")
  echo "fusion :$r /healthz/store: $health"
  [ "$health" = '{"status":"ok","failing_over":false}' ] \
    || { echo "fusion :$r store health: $health" >&2; exit 1; }
  curl -s -H "$METRICS_AUTH" "http://127.0.0.1:$r/metrics" | grep -E '^session_store_(failovers_total|redirections_total|failing_over) ' | sed "s/^/fusion :$r   /"
  failovers=$(curl -s -H "$METRICS_AUTH" "http://127.0.0.1:$r/metrics" | awk '$1 == "session_store_failovers_total" {print $2}')
  [ "$failovers" = 1 ] || { echo "fusion :$r counted $failovers failovers, not 1" >&2; exit 1; }
done
redis-cli -p "$REPLICA" role | head -1 | grep -q '^master$' \
  || { echo "the replica was not promoted" >&2; exit 1; }
echo "loopback (Sentinel): OK"
