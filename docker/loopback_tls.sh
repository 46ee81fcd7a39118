#!/usr/bin/env bash
# The TLS variant of the compose topology (docker/compose.tls.yaml) on
# loopback with real processes (issue 34): openssl makes a CA, the servers'
# certificate and client certificates; Redis, two replicas with mutual TLS
# required, client certificates mapped to tenants and an API key, and nginx
# passing TCP through (docker/nginx.tls.conf). Checked with curl and openssl
# s_client: REST over HTTP/2 and HTTP/1.1 (ALPN) and gRPC health over TLS on
# both ports of a replica and through the balancer; refusals (no client
# certificate, plaintext); tenants by certificate across both replicas and
# a key that disagrees (403); the `healthcheck` command over TLS; a
# certificate reloaded on SIGHUP, a broken one refused (the old one kept);
# the TLS metrics.
#   docker/loopback_tls.sh            (builds the release binary if needed)
# Needs openssl, curl, redis-server, nginx with the stream module (Debian:
# nginx-light libnginx-mod-stream; installed when missing and apt-get is
# there), python3.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-${CARGO_TARGET_DIR:-target}/release/radar-fusion}
[ -x "$BIN" ] || cargo build --release --bin radar-fusion
install() { echo "loopback-tls: installing $*"; apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null; }
for tool in openssl curl redis-server; do
  command -v "$tool" >/dev/null 2>&1 || install "$tool"
done
command -v nginx >/dev/null 2>&1 || install nginx-light
STREAM_MODULE=/usr/lib/nginx/modules/ngx_stream_module.so
if ! nginx -V 2>&1 | grep -q -- '--with-stream[ =]' || nginx -V 2>&1 | grep -q -- '--with-stream=dynamic'; then
  [ -f "$STREAM_MODULE" ] || install libnginx-mod-stream
fi

WORK=$(mktemp -d /tmp/radar-fusion-loopback-tls.XXXXXX)
PIDS=()
cleanup() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
  [ -f "$WORK/nginx.pid" ] && kill "$(cat "$WORK/nginx.pid")" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT
fail() { echo "loopback-tls: FAILED: $*" >&2; for l in "$WORK"/*.log; do echo "--- $l" >&2; cat "$l" >&2; done; exit 1; }

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
REDIS=$(free_port); H=$(free_port); G=$(free_port); H2=$(free_port); G2=$(free_port); LBH=$(free_port); LBG=$(free_port)
wait_port() { for _ in $(seq 1 100); do (exec 3<>/dev/tcp/127.0.0.1/"$1") 2>/dev/null && return 0; sleep 0.1; done; fail "port $1 never opened"; }

# --- certificates (the commands of docs/operations.md, "TLS")
cd "$WORK"
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 7 \
  -subj "/CN=Radar Fusion loopback CA" -keyout ca-key.pem -out ca.pem \
  -addext basicConstraints=critical,CA:TRUE -addext keyUsage=critical,keyCertSign,cRLSign 2>/dev/null
issue() { # name subject extensions: a key and a certificate signed by the CA
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "$2" \
    -keyout "$1-key.pem" -out "$1.csr" 2>/dev/null
  printf '%b' "$3" >"$1.ext"
  openssl x509 -req -in "$1.csr" -CA ca.pem -CAkey ca-key.pem -CAcreateserial -days 7 \
    -extfile "$1.ext" -out "$1.pem" 2>/dev/null
}
issue server /CN=localhost 'subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n'
issue acme /CN=acme-ingest 'subjectAltName=URI:spiffe://radar.example/ingest/acme\nextendedKeyUsage=clientAuth\n'
issue globex /CN=globex-batch 'extendedKeyUsage=clientAuth\n'
issue probe /CN=healthcheck 'extendedKeyUsage=clientAuth\n'
printf '# client certificate names -> tenants\nuri:spiffe://radar.example/ingest/acme=acme\ncn:globex-batch=globex\n' >tenants
fingerprint() { openssl x509 -noout -fingerprint -sha256 -in "$1" | cut -d= -f2; }
cd - >/dev/null

# --- Redis and two replicas: mutual TLS required, tenants by certificate,
# one API key; reloads on SIGHUP only (FUSION_TLS_RELOAD_S=0; the default
# also polls every 10 s).
redis-server --port "$REDIS" --bind 127.0.0.1 --dir "$WORK" --save "" >"$WORK/redis.log" 2>&1 &
PIDS+=($!)
wait_port "$REDIS"
start_replica() { # name http grpc
  FUSION_HTTP_ADDR="127.0.0.1:$2" FUSION_GRPC_ADDR="127.0.0.1:$3" FUSION_LOG=info \
  FUSION_SESSION_STORE="redis://127.0.0.1:$REDIS/0" FUSION_MAX_CONNECTIONS_PER_CLIENT=0 \
  FUSION_TLS_CERT="$WORK/server.pem" FUSION_TLS_KEY="$WORK/server-key.pem" \
  FUSION_TLS_CLIENT_CA="$WORK/ca.pem" FUSION_TLS_CLIENT_TENANTS="$WORK/tenants" \
  FUSION_TLS_RELOAD_S=0 FUSION_API_KEYS=loopback-key-globex=globex \
    "$BIN" serve >"$WORK/$1.log" 2>&1 &
  PIDS+=($!)
  echo $! >"$WORK/$1.pid"
  wait_port "$2"
}
start_replica fusion-1 "$H" "$G"
start_replica fusion-2 "$H2" "$G2"
PID=$(cat "$WORK/fusion-1.pid")

# docker/nginx.tls.conf with loopback addresses (and Debian's stream module).
{
  if [ -f "$STREAM_MODULE" ]; then echo "load_module $STREAM_MODULE;"; fi
  sed -e "s/fusion-1:8080/127.0.0.1:$H/; s/fusion-2:8080/127.0.0.1:$H2/" \
      -e "s/fusion-1:50051/127.0.0.1:$G/; s/fusion-2:50051/127.0.0.1:$G2/" \
      -e "s/listen 8080;/listen 127.0.0.1:$LBH;/; s/listen 50051;/listen 127.0.0.1:$LBG;/" docker/nginx.tls.conf
} >"$WORK/nginx.conf"
nginx -p "$WORK" -c "$WORK/nginx.conf" -g "daemon on; pid $WORK/nginx.pid; error_log $WORK/nginx-error.log;"
wait_port "$LBH"
echo "loopback-tls: redis :$REDIS, fusion-1 :$H/:$G, fusion-2 :$H2/:$G2 (TLS, client certificates required), nginx $(nginx -v 2>&1 | sed 's/.*nginx\///') TCP passthrough :$LBH :$LBG"

as() { # tenant-certificate curl-args...: curl over TLS with that client certificate
  local who=$1; shift
  curl -sS --cacert "$WORK/ca.pem" --cert "$WORK/$who.pem" --key "$WORK/$who-key.pem" "$@"
}
RULES='{"alpha": 0.05, "rules": [{"l": 3, "r": 4}]}'
URL="https://localhost:$H"

# REST over HTTP/2 and HTTP/1.1, chosen by ALPN, on a replica and through the balancer.
for port in "$H" "$LBH"; do
  v2=$(as acme -o /dev/null -w '%{http_code} HTTP/%{http_version}' "https://localhost:$port/v1/correlation/rules/evaluate" \
    -H 'content-type: application/json' -d "$RULES")
  v1=$(as acme --http1.1 -o /dev/null -w '%{http_code} HTTP/%{http_version}' "https://localhost:$port/v1/correlation/rules/evaluate" \
    -H 'content-type: application/json' -d "$RULES")
  echo "REST over TLS on :$port: $v2; $v1"
  [ "$v2" = "200 HTTP/2" ] && [ "$v1" = "200 HTTP/1.1" ] || fail "REST over TLS on :$port"
done

# gRPC health over TLS on both ports (a hand-made Check request).
grpc_health() {
  printf '\x00\x00\x00\x00\x00' | as acme --http2 -D - -o /dev/null -H 'content-type: application/grpc' \
    -H 'te: trailers' --data-binary @- "https://localhost:$1/grpc.health.v1.Health/Check" \
    | tr -d '\r' | grep -i '^grpc-status:' | head -1
}
for port in "$G" "$H" "$LBG" "$LBH"; do
  status=$(grpc_health "$port")
  echo "gRPC health over TLS on :$port: $status"
  [ "$status" = "grpc-status: 0" ] || fail "gRPC over TLS on :$port"
done

# Refusals: no client certificate; plaintext to the TLS port (closed at once).
if curl -sS --cacert "$WORK/ca.pem" -o /dev/null "$URL/healthz" 2>"$WORK/err"; then fail "served without a client certificate"; fi
echo "without a client certificate: refused ($(head -c 90 "$WORK/err"))"
t=$(curl -s -m 5 -o /dev/null -w '%{time_total}' "http://localhost:$H/healthz" || true)
echo "plaintext to the TLS port: closed after $t s (header-read timeout 10 s)"
python3 -c "import sys; sys.exit(0 if float('$t') < 1.0 else 1)" || fail "plaintext not closed at once"

# Tenants, through the balancer (each call a new connection, so both
# replicas serve; the session lives in Redis): acme's certificate alone
# creates a session; globex's does not see it; acme's certificate with
# globex's key is refused.
LB="https://localhost:$LBH"
SESSION='{"state_layout": ["x","vx","y","vy"], "method": {"kind": "independent_double_threshold",
  "rule": {"l": 3, "r": 4}}, "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0}, "nodes": ["a","b"]}'
created=$(as acme -w '\n%{http_code}' "$LB/v1/sessions" -H 'content-type: application/json' -d "$SESSION")
[ "$(tail -1 <<<"$created")" = 201 ] || fail "session create as acme: $created"
id=$(head -1 <<<"$created" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
own=$(for _ in 1 2 3 4; do as acme -o /dev/null -w '%{http_code} ' "$LB/v1/sessions/$id"; done)
other=$(as globex -o /dev/null -w '%{http_code}' "$LB/v1/sessions/$id")
mixed=$(as acme -o /dev/null -w '%{http_code}' -H 'authorization: Bearer loopback-key-globex' "$LB/v1/sessions/$id")
echo "session $id through the balancer: acme by certificate ${own% }, globex by certificate $other, acme's certificate + globex's key $mixed"
[ "$own$other $mixed" = "200 200 200 200 404 403" ] || fail "tenants"
served() { # port: GET /v1/sessions/{id} answered by that replica
  as acme "https://localhost:$1/metrics" | grep '^http_requests_total{method="GET",route="/v1/sessions/{id}"' \
    | awk '{s += $2} END {print s + 0}'
}
echo "session reads served: fusion-1 $(served "$H"), fusion-2 $(served "$H2")"

# The healthcheck command over TLS, with the probe's client certificate.
"$BIN" healthcheck --addr "127.0.0.1:$H" --tls-ca "$WORK/ca.pem" \
  --tls-client-cert "$WORK/probe.pem" --tls-client-key "$WORK/probe-key.pem" || fail "healthcheck over TLS"
echo "healthcheck over TLS: healthy"

# Reload on SIGHUP: a new certificate (new key) serves new connections.
served_cert() { openssl s_client -connect "127.0.0.1:$H" -servername localhost -CAfile "$WORK/ca.pem" \
  -cert "$WORK/acme.pem" -key "$WORK/acme-key.pem" </dev/null 2>/dev/null | openssl x509 -noout -fingerprint -sha256 | cut -d= -f2; }
old=$(served_cert)
[ "$old" = "$(fingerprint "$WORK/server.pem")" ] || fail "served certificate"
cd "$WORK"
issue server2 /CN=localhost 'subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n'
cp server2-key.pem server-key.pem.new && mv server-key.pem.new server-key.pem
cp server2.pem server.pem.new && mv server.pem.new server.pem
cd - >/dev/null
kill -HUP "$PID"
new=
for _ in $(seq 1 50); do new=$(served_cert); [ "$new" != "$old" ] && break; sleep 0.1; done
echo "SIGHUP: served certificate ${old:0:23}… -> ${new:0:23}…"
[ "$new" = "$(fingerprint "$WORK/server2.pem")" ] || fail "reload on SIGHUP"

# A broken certificate: refused, logged, counted; the last good one is kept.
printf -- '-----BEGIN CERTIFICATE-----\nbroken\n-----END CERTIFICATE-----\n' >"$WORK/server.pem"
kill -HUP "$PID"
for _ in $(seq 1 50); do grep -q 'TLS reload failed' "$WORK/fusion-1.log" && break; sleep 0.1; done
grep -q 'TLS reload failed' "$WORK/fusion-1.log" || fail "a broken certificate is not reported"
kept=$(served_cert)
echo "broken certificate on SIGHUP: $(grep -o 'TLS reload failed.*' "$WORK/fusion-1.log" | head -1 | cut -c1-160)"
[ "$kept" = "$new" ] || fail "the last good certificate is not kept"
echo "still serving the last good certificate: ${kept:0:23}…"

echo "metrics:"
as acme "$URL/metrics" | grep -E '^tls_' | sed 's/^/  /'
if grep -q 'PRIVATE KEY' "$WORK"/fusion-*.log; then fail "key material in a log"; fi
echo "loopback-tls: OK"
