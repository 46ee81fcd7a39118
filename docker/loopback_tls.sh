#!/usr/bin/env bash
# A TLS deployment on loopback with a real process (issue 34): openssl makes
# a CA, the server's certificate and two client certificates; the service
# runs with mutual TLS required, client certificates mapped to tenants and
# an API key, and this script checks, with curl and openssl s_client:
# REST over HTTP/2 and HTTP/1.1 (ALPN), gRPC health over TLS on both ports,
# refusals (no client certificate, plaintext), tenants by certificate and a
# key that disagrees (403), the `healthcheck` command over TLS, a
# certificate reloaded on SIGHUP, a broken one refused (the old one kept)
# and the TLS metrics.
#   docker/loopback_tls.sh            (builds the release binary if needed)
# Needs openssl, curl (installed when missing and apt-get is there), python3.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-${CARGO_TARGET_DIR:-target}/release/radar-fusion}
[ -x "$BIN" ] || cargo build --release --bin radar-fusion
for tool in openssl curl; do
  if ! command -v "$tool" >/dev/null 2>&1; then
    echo "loopback-tls: installing $tool"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$tool" >/dev/null
  fi
done

WORK=$(mktemp -d /tmp/radar-fusion-loopback-tls.XXXXXX)
PID=
cleanup() {
  [ -n "$PID" ] && kill "$PID" 2>/dev/null || true
  wait 2>/dev/null || true
  rm -rf "$WORK"
}
trap cleanup EXIT
fail() { echo "loopback-tls: FAILED: $*" >&2; echo "--- server log" >&2; cat "$WORK/server.log" >&2; exit 1; }

free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])'; }
H=$(free_port); G=$(free_port)
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

# --- the service: mutual TLS required, tenants by certificate, one API key,
# reloads on SIGHUP only (FUSION_TLS_RELOAD_S=0; the default also polls).
FUSION_HTTP_ADDR="127.0.0.1:$H" FUSION_GRPC_ADDR="127.0.0.1:$G" FUSION_LOG=info \
FUSION_TLS_CERT="$WORK/server.pem" FUSION_TLS_KEY="$WORK/server-key.pem" \
FUSION_TLS_CLIENT_CA="$WORK/ca.pem" FUSION_TLS_CLIENT_TENANTS="$WORK/tenants" \
FUSION_TLS_RELOAD_S=0 FUSION_API_KEYS=loopback-key-globex=globex \
  "$BIN" serve >"$WORK/server.log" 2>&1 &
PID=$!
wait_port "$H"
echo "loopback-tls: radar-fusion :$H (REST+gRPC) :$G (gRPC), TLS with client certificates required"

as() { # tenant-certificate curl-args...: curl over TLS with that client certificate
  local who=$1; shift
  curl -sS --cacert "$WORK/ca.pem" --cert "$WORK/$who.pem" --key "$WORK/$who-key.pem" "$@"
}
RULES='{"alpha": 0.05, "rules": [{"l": 3, "r": 4}]}'
URL="https://localhost:$H"

# REST over HTTP/2 and HTTP/1.1, chosen by ALPN.
v2=$(as acme -o /dev/null -w '%{http_code} HTTP/%{http_version}' "$URL/v1/correlation/rules/evaluate" \
  -H 'content-type: application/json' -d "$RULES")
v1=$(as acme --http1.1 -o /dev/null -w '%{http_code} HTTP/%{http_version}' "$URL/v1/correlation/rules/evaluate" \
  -H 'content-type: application/json' -d "$RULES")
echo "REST over TLS: $v2; $v1"
[ "$v2" = "200 HTTP/2" ] && [ "$v1" = "200 HTTP/1.1" ] || fail "REST over TLS"

# gRPC health over TLS on both ports (a hand-made Check request).
grpc_health() {
  printf '\x00\x00\x00\x00\x00' | as acme --http2 -D - -o /dev/null -H 'content-type: application/grpc' \
    -H 'te: trailers' --data-binary @- "https://localhost:$1/grpc.health.v1.Health/Check" \
    | tr -d '\r' | grep -i '^grpc-status:' | head -1
}
for port in "$G" "$H"; do
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

# Tenants: acme's certificate alone creates a session; globex's does not see it;
# acme's certificate with globex's key is refused.
SESSION='{"state_layout": ["x","vx","y","vy"], "method": {"kind": "independent_double_threshold",
  "rule": {"l": 3, "r": 4}}, "motion_model": {"process_noise": "dwna", "sigma_a_mps2": 1.0}, "nodes": ["a","b"]}'
created=$(as acme -w '\n%{http_code}' "$URL/v1/sessions" -H 'content-type: application/json' -d "$SESSION")
[ "$(tail -1 <<<"$created")" = 201 ] || fail "session create as acme: $created"
id=$(head -1 <<<"$created" | python3 -c 'import json,sys; print(json.load(sys.stdin)["id"])')
own=$(as acme -o /dev/null -w '%{http_code}' "$URL/v1/sessions/$id")
other=$(as globex -o /dev/null -w '%{http_code}' "$URL/v1/sessions/$id")
mixed=$(as acme -o /dev/null -w '%{http_code}' -H 'authorization: Bearer loopback-key-globex' "$URL/v1/sessions/$id")
echo "session $id: acme by certificate $own, globex by certificate $other, acme's certificate + globex's key $mixed"
[ "$own $other $mixed" = "200 404 403" ] || fail "tenants"

# The healthcheck command over TLS, with the probe's client certificate.
"$BIN" healthcheck --addr "127.0.0.1:$H" --tls-ca "$WORK/ca.pem" \
  --tls-client-cert "$WORK/probe.pem" --tls-client-key "$WORK/probe-key.pem" || fail "healthcheck over TLS"
echo "healthcheck over TLS: healthy"

# Reload on SIGHUP: a new certificate (new key) serves new connections.
served() { openssl s_client -connect "127.0.0.1:$H" -servername localhost -CAfile "$WORK/ca.pem" \
  -cert "$WORK/acme.pem" -key "$WORK/acme-key.pem" </dev/null 2>/dev/null | openssl x509 -noout -fingerprint -sha256 | cut -d= -f2; }
old=$(served)
[ "$old" = "$(fingerprint "$WORK/server.pem")" ] || fail "served certificate"
cd "$WORK"
issue server2 /CN=localhost 'subjectAltName=DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth\n'
cp server2-key.pem server-key.pem.new && mv server-key.pem.new server-key.pem
cp server2.pem server.pem.new && mv server.pem.new server.pem
cd - >/dev/null
kill -HUP "$PID"
new=
for _ in $(seq 1 50); do new=$(served); [ "$new" != "$old" ] && break; sleep 0.1; done
echo "SIGHUP: served certificate ${old:0:23}… -> ${new:0:23}…"
[ "$new" = "$(fingerprint "$WORK/server2.pem")" ] || fail "reload on SIGHUP"

# A broken certificate: refused, logged, counted; the last good one is kept.
printf -- '-----BEGIN CERTIFICATE-----\nbroken\n-----END CERTIFICATE-----\n' >"$WORK/server.pem"
kill -HUP "$PID"
for _ in $(seq 1 50); do grep -q 'TLS reload failed' "$WORK/server.log" && break; sleep 0.1; done
grep -q 'TLS reload failed' "$WORK/server.log" || fail "a broken certificate is not reported"
kept=$(served)
echo "broken certificate on SIGHUP: $(grep -o 'TLS reload failed.*' "$WORK/server.log" | head -1 | cut -c1-150)"
[ "$kept" = "$new" ] || fail "the last good certificate is not kept"
echo "still serving the last good certificate: ${kept:0:23}…"

echo "metrics:"
as acme "$URL/metrics" | grep -E '^tls_' | sed 's/^/  /'
if grep -q 'PRIVATE KEY' "$WORK/server.log"; then fail "key material in the log"; fi
echo "loopback-tls: OK"
