#!/usr/bin/env bash
# Regenerate tests/fixtures/cat021/{adsb,mlat,mixed}.bin and expected.json with an independent
# ASTERIX encoder and decoder: libasterix from PyPI (pure Python), in its
# own venv, checks/.venv-asterix. Idempotent.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv-asterix"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("libasterix") != "0.36.3")' 2>/dev/null; then
    "$venv/bin/python" -m pip install --quiet libasterix==0.36.3
fi
"$venv/bin/python" "$here/cat021_fixture.py"
