# Shared by docker/loopback.sh and docker/loopback_sentinel.sh (sourced, from
# the repository root): the binary, nginx and redis-server (installed when
# missing and apt-get is there), a scratch directory cleaned on exit, free
# loopback ports, the service replicas and nginx with docker/nginx.conf
# rewritten to loopback addresses.
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
  if [ -n "${KEEP_WORK:-}" ]; then echo "loopback: logs kept in $WORK"; else rm -rf "$WORK"; fi
}
trap cleanup EXIT

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
wait_port() { for _ in $(seq 1 100); do (exec 3<>/dev/tcp/127.0.0.1/"$1") 2>/dev/null && return 0; sleep 0.1; done; echo "port $1 never opened" >&2; return 1; }
F1H=$(free_port); F1G=$(free_port); F2H=$(free_port); F2G=$(free_port)
LBH=$(free_port); LBG=$(free_port)
printf '# loopback keys\nloopback-key-acme=acme\n' >"$WORK/api-keys"

start_replica() { # name http grpc session-store-url
  FUSION_SESSION_STORE="$4" FUSION_API_KEYS_FILE="$WORK/api-keys" FUSION_MAX_CONNECTIONS_PER_CLIENT=0 \
  FUSION_LOG=warn FUSION_HTTP_ADDR="127.0.0.1:$2" FUSION_GRPC_ADDR="127.0.0.1:$3" \
    "$BIN" serve >"$WORK/$1.log" 2>&1 &
  PIDS+=($!)
  echo $! >"$WORK/$1.pid"
  wait_port "$2"
}

# docker/nginx.conf with loopback addresses; nginx older than 1.25.1 (Debian
# 12 has 1.22) knows no `http2 on`: then 8080 serves REST only, said below.
start_nginx() {
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
}

grpc_health() { # port: gRPC health Check of the server ("") through the balancer
  printf '\x00\x00\x00\x00\x00' | curl -s --http2-prior-knowledge -D - -o /dev/null \
    -H 'content-type: application/grpc' -H 'te: trailers' --data-binary @- \
    "http://127.0.0.1:$1/grpc.health.v1.Health/Check" | tr -d '\r' | grep -i '^grpc-status:' | head -1
}

session_through_balancer() { # pid-to-kill victim-label
  python3 docker/loopback_session.py "http://127.0.0.1:$LBH" loopback-key-acme "$1" \
    "http://127.0.0.1:$F1H" "http://127.0.0.1:$F2H" "$2"
}
