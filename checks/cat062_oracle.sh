#!/usr/bin/env bash
# Check the CAT062 encoder (crates/wire-formats/src/cat062.rs) with an
# independent decoder: libasterix from PyPI (pure Python), in its own venv,
# checks/.venv-asterix (shared with asterix_fixture.sh). Decodes
# tests/fixtures/cat062/sample.bin into sample_decoded.json (checked in;
# `cargo test -p wire-formats` compares it with the encoder), then compares it
# field by field with sample_input.json. Exits non-zero on a mismatch.
# Idempotent.
#
# Regenerate sample.bin and sample_input.json first when the encoder or
# the sample changes:
#   cargo test -p wire-formats regenerate_the_cat062_sample -- --ignored
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv-asterix"
python="${PYTHON:-python3}"
fixtures="$here/../tests/fixtures/cat062"

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import importlib.metadata as m, sys; sys.exit(m.version("libasterix") != "0.36.3")' 2>/dev/null; then
    "$venv/bin/python" -m pip install --quiet libasterix==0.36.3
fi
"$venv/bin/python" "$here/cat062_oracle.py" decode "$fixtures/sample.bin" >"$fixtures/sample_decoded.json.tmp"
mv "$fixtures/sample_decoded.json.tmp" "$fixtures/sample_decoded.json"
"$venv/bin/python" "$here/cat062_oracle.py" compare "$fixtures/sample_input.json" "$fixtures/sample_decoded.json"
