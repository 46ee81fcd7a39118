#!/usr/bin/env bash
# Create checks/.venv with the Python packages used by the comparison scripts
# in this folder (Stone Soup 1.9.1 as the reference tracker). Idempotent:
# re-running only installs what is missing. Packages come from PyPI only.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
python="${PYTHON:-python3}"

if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi

want=(stonesoup==1.9.1 requests numpy scipy)
if "$venv/bin/python" - <<'PY' 2>/dev/null
import importlib.metadata as m, sys
sys.exit(0 if m.version("stonesoup") == "1.9.1" and all(
    m.version(p) for p in ("requests", "numpy", "scipy")) else 1)
PY
then
    echo "checks/.venv already has: ${want[*]}"
else
    "$venv/bin/python" -m pip install --upgrade --quiet pip
    "$venv/bin/python" -m pip install --quiet "${want[@]}"
fi
"$venv/bin/python" -c 'import stonesoup, numpy, scipy, requests; print("stonesoup", stonesoup.__version__ if hasattr(stonesoup, "__version__") else "?", "numpy", numpy.__version__, "scipy", scipy.__version__)'
