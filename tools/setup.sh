#!/usr/bin/env bash
# Idempotent setup: Debian packages for offscreen MuJoCo rendering and Chromium (the report's
# headless-browser test), a virtual environment in .venv, and the pinned Python dependencies
# (constraints.txt).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-$(command -v python3.11 || command -v python3)}

need_apt=()
for pkg in libegl1 libegl-mesa0 libgl1-mesa-dri libosmesa6 chromium; do
  dpkg -s "$pkg" >/dev/null 2>&1 || need_apt+=("$pkg")
done
# Debian's python3 needs python3-venv (ensurepip) for `python3 -m venv`.
if [ ! -x "$VENV/bin/python" ] && ! "$PYTHON" -c "import ensurepip, venv" >/dev/null 2>&1; then
  need_apt+=("python3-venv")
fi
if [ ${#need_apt[@]} -gt 0 ]; then
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  echo "setup: installing Debian packages: ${need_apt[*]}"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${need_apt[@]}" >/dev/null
fi

[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
stamp="$VENV/.zsrm-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ constraints.txt -nt "$stamp" ]; then
  # torch first and pinned: an unpinned resolve pulls the multi-GB CUDA build.
  "$VENV/bin/pip" install -q -c constraints.txt "torch==2.13.0"
  "$VENV/bin/pip" install -q -c constraints.txt -e ".[dev]"
  touch "$stamp"
fi
