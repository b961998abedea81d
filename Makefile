# Quick start: `make demo` (main job, offline) and `make test` (test suite).
VENV ?= .venv
PY := $(VENV)/bin/python
export MUJOCO_GL ?= egl
export HF_HUB_OFFLINE ?= 1
REPORT ?= reports/demo

.PHONY: setup demo test results clean

setup:
	@bash tools/setup.sh

demo: setup
	$(VENV)/bin/zsrm demo --out $(REPORT)

test: setup
	$(PY) -m pytest

# Rebuild every figure under results/ (slow: minutes to hours on 2 CPU cores).
results: setup
	$(VENV)/bin/zsrm scripted-eval --episodes 20 --out results/scripted_success.json
	$(PY) benchmarks/env_speed.py --out results/env_speed.json

clean:
	rm -rf reports .pytest_cache
