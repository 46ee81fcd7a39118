#!/usr/bin/env bash
# The /view/ page in a real browser: starts the server (debug build), feeds a
# plot_fusion session with the seed-001 scene of tests/fixtures/cat062,
# opens /view/ in headless Chromium (Debian's `chromium`, installed with apt
# when missing), enters the API key as a user does (session storage), waits
# for the tracks and asserts from the page's own state (`window.viewState`)
# that it draws exactly the session's confirmed tracks at the session's last
# version; saves a screenshot to checks/out/view.png. Driven over the
# DevTools protocol with websocket-client (PyPI) in checks/.venv-view.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here/.."
if ! command -v chromium >/dev/null 2>&1; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq chromium >/dev/null
fi
venv="$here/.venv-view"
[ -x "$venv/bin/python" ] || python3 -m venv "$venv"
"$venv/bin/python" -c 'import websocket' 2>/dev/null || "$venv/bin/python" -m pip install --quiet websocket-client==1.8.0
cargo build --quiet --bin radar-fusion
bin="${CARGO_TARGET_DIR:-target}/debug/radar-fusion"
exec "$venv/bin/python" "$here/view_browser.py" "$bin"
