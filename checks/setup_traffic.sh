#!/usr/bin/env bash
# Extend checks/.venv (made by checks/setup.sh: Stone Soup 1.9.1, numpy,
# scipy, requests) with what checks/real_traffic_vs_stonesoup.py needs:
# traffic (its sample flights ship inside the wheel: no download at run
# time), pyproj, and a pandas that traffic 2.13 imports (pandas 3 removed
# pandas.core.internals.blocks.DatetimeTZBlock, which traffic's Flight uses).
# Idempotent; packages come from PyPI only.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
venv="$here/.venv"
bash "$here/setup.sh"

want=(traffic==2.13 "pandas>=2.2,<3" pyproj==3.7.2)
if "$venv/bin/python" - <<'PY' 2>/dev/null
import importlib.metadata as m, sys
ok = (m.version("traffic") == "2.13" and m.version("pyproj") == "3.7.2"
      and m.version("pandas").split(".")[0] == "2")
sys.exit(0 if ok else 1)
PY
then
    echo "checks/.venv already has: ${want[*]}"
else
    "$venv/bin/python" -m pip install --quiet "${want[@]}"
fi
"$venv/bin/python" -c '
import pyproj, pandas, traffic.data.samples as s
print("traffic", __import__("importlib.metadata").metadata.version("traffic"),
      "pyproj", pyproj.__version__, "PROJ", pyproj.proj_version_str, "pandas", pandas.__version__,
      "quickstart flights", len(s.quickstart))'
