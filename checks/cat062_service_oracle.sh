#!/usr/bin/env bash
# Check the service's CAT062 out (the batch call's `cat062`) with an
# independent decoder: libasterix from PyPI in checks/.venv-asterix (shared
# with cat062_oracle.sh). For each fixture under tests/fixtures/cat062/
# (service_seed001.json: the plot-fusion tests' seed-001 scene;
# service_asterix.json: the ASTERIX fixture scene; service_cooperative.json:
# ADS-B and multilateration beside Mode S radars), decodes the answer's
# cat062 into *_decoded.json (checked in; `cargo test` compares the JSON
# answer with it) and compares every record field by field with the JSON
# track it stands for. Exits non-zero on a mismatch. Idempotent.
#
# Regenerate the fixtures first when the tracker or the encoder changes:
#   cargo test --test api regenerate_the_service_cat062_fixtures -- --ignored
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
status=0
for name in service_seed001 service_asterix service_cooperative; do
    "$venv/bin/python" "$here/cat062_oracle.py" service "$fixtures/$name.json" \
        "$fixtures/${name}_decoded.json" || status=1
done
exit $status
