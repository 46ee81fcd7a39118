#!/usr/bin/env bash
# Create checks/.venv-sea for checks/sea_real_ais.py: pyais 3.3.1 (the
# independent AIVDM encoder) and numpy; and fetch the real AIS recording it
# uses, Stone Soup's Solent demo data, from the stonesoup 1.9.1 sdist on
# PyPI (docs/demos/SolentAIS_20160112_130211.csv) into checks/.cache.
# Idempotent; everything comes from PyPI.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv-sea"
cache="$here/.cache"
python="${PYTHON:-python3}"
[ -x "$venv/bin/python" ] || "$python" -m venv "$venv"
"$venv/bin/python" -m pip install --quiet pyais==3.3.1 numpy
mkdir -p "$cache"
csv="$cache/SolentAIS_20160112_130211.csv"
if [ ! -s "$csv" ]; then
    tmp="$(mktemp -d)"
    "$venv/bin/python" -m pip download --quiet --no-deps --no-binary :all: \
        stonesoup==1.9.1 -d "$tmp"
    tar -xzf "$tmp"/stonesoup-1.9.1.tar.gz -C "$tmp" \
        stonesoup-1.9.1/docs/demos/SolentAIS_20160112_130211.csv
    mv "$tmp"/stonesoup-1.9.1/docs/demos/SolentAIS_20160112_130211.csv "$csv"
    rm -rf "$tmp"
fi
wc -l "$csv"
