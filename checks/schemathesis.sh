#!/usr/bin/env bash
# Property-based API check of the served OpenAPI document with schemathesis
# (PyPI): starts a release server on loopback with an API key, runs
# schemathesis against /openapi.json with every check, prints its summary,
# then checks a real event stream against the document (sse_contract.py).
#   checks/schemathesis.sh [MAX_EXAMPLES]      (default 100 per operation)
# The venv is checks/.venv-schemathesis (created on first use, gitignored).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here/.."
examples="${1:-100}"
venv="$here/.venv-schemathesis"
if [ ! -x "$venv/bin/schemathesis" ]; then
  "${PYTHON:-python3}" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip
  "$venv/bin/python" -m pip install --quiet "schemathesis>=4,<5"
fi
BIN=${BIN:-${CARGO_TARGET_DIR:-target}/release/radar-fusion}
[ -x "$BIN" ] || cargo build --release --bin radar-fusion
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
gport=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
key="schemathesis-key-$$"
FUSION_LOG=error FUSION_HTTP_ADDR="127.0.0.1:$port" FUSION_GRPC_ADDR="127.0.0.1:$gport" \
  FUSION_MAX_BODY_BYTES=1048576 FUSION_API_KEYS="$key=schemathesis" "$BIN" serve &
server=$!
trap 'kill $server 2>/dev/null || true' EXIT
for _ in $(seq 1 100); do (exec 3<>/dev/tcp/127.0.0.1/"$port") 2>/dev/null && break; sleep 0.1; done
status=0
"$venv/bin/schemathesis" run "http://127.0.0.1:$port/openapi.json" \
  --checks all --max-examples "$examples" --seed 18 --no-color \
  -H "Authorization: Bearer $key" "${@:2}" || status=$?
"$venv/bin/python" "$here/sse_contract.py" "http://127.0.0.1:$port" "$key" || status=$?
exit "$status"
