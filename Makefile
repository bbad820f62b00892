# Two commands do all set-up on a fresh machine:
#   make train   - create .venv, install, run local training (2 workers, embedded defaults)
#   make test    - create .venv if needed, run the tests
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
# The measured best method (docs/RESULTS.md) at a small budget: ~2 min of demo pre-training, then 30k env steps.
TRAIN_ARGS ?= --local --workers 2 --scenario straight --method dqfd-bc --env-steps 30000 --run-dir runs/demo

.PHONY: train test venv bench clean

venv: $(STAMP)

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	# Exactly torch 2.13.0 first: its CPU wheel is on disk; any other spec downloads GB of CUDA packages.
	$(PY) -m pip install --disable-pip-version-check -q torch==2.13.0
	# torch stays pinned in the same resolve: stable-baselines3 (the sb3 baseline) must not move it.
	$(PY) -m pip install --disable-pip-version-check -q -e ".[test,baselines,cluster]" torch==2.13.0
	@if $(PY) -m pip list 2>/dev/null | grep -i nvidia; then echo "error: CUDA packages were installed"; exit 1; fi
	@touch $(STAMP)

train: $(STAMP)
	$(VENV)/bin/laneshift train $(TRAIN_ARGS)

test: $(STAMP)
	$(PY) -m pytest -q -m "not chaos"

bench: $(STAMP)
	$(VENV)/bin/laneshift bench env

clean:
	rm -rf $(VENV) build *.egg-info
