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

$(STAMP): pyproject.toml constraints.txt
	$(PYTHON) -m venv $(VENV)
	# torch 2.13.0 first, the build this machine should have (deploy/install_torch.py, which says which
	# and why): the CUDA build where nvidia-smi lists a GPU, else the CPU build from PyTorch's CPU
	# index (or, where that index cannot be reached, pip's own index if it brings no nvidia-* packages).
	$(PY) deploy/install_torch.py -q -c constraints.txt
	# The package and its extras at the tested versions (constraints.txt pins torch too: it stays).
	$(PY) -m pip install --disable-pip-version-check -q -e ".[train,test,baselines,cluster]" -c constraints.txt
	# Where the CPU build was chosen: no nvidia-* package may have come in.
	@$(PY) deploy/install_torch.py --check
	@touch $(STAMP)

train: $(STAMP)
	$(VENV)/bin/laneshift train $(TRAIN_ARGS)

test: $(STAMP)
	$(PY) -m pytest -q -m "not chaos"

bench: $(STAMP)
	$(VENV)/bin/laneshift bench env

clean:
	rm -rf $(VENV) build *.egg-info

# The RLlib peer of the comparison (docs/rllib-peer.md): RLlib 2.60's DQN on the same env, in its own
# venv because ray[rllib] pins gymnasium 1.2.2 and laneshift pins 1.4.0. Only laneshift's env code
# is imported there. make bench-rllib RLLIB_ARGS="--env-steps 3000 --ratio 8"
RLLIB_VENV ?= .venv-rllib
RLLIB_PY := $(RLLIB_VENV)/bin/python
RLLIB_STAMP := $(RLLIB_VENV)/.installed-stamp
RLLIB_ARGS ?=

.PHONY: bench-rllib

$(RLLIB_STAMP): pyproject.toml
	$(PYTHON) -m venv $(RLLIB_VENV)
	# torch 2.13.0 first, by the same rule as .venv (deploy/install_torch.py), then RLlib with torch
	# pinned in the same resolve.
	$(RLLIB_PY) deploy/install_torch.py -q
	$(RLLIB_PY) -m pip install --disable-pip-version-check -q "ray[rllib]==2.60.0" torch==2.13.0
	# The env's own deps under RLlib's gymnasium 1.2.2 (highway-env accepts >=1.0; it brings pygame-ce),
	# and tqdm for laneshift's evaluation code (--eval-every), then laneshift itself without its deps
	# (no zenoh, no gymnasium 1.4.0).
	$(RLLIB_PY) -m pip install --disable-pip-version-check -q highway-env==1.12.1 gymnasium==1.2.2 torch==2.13.0 \
		"tqdm>=4.66"
	$(RLLIB_PY) -m pip install --disable-pip-version-check -q --no-deps -e .
	@$(RLLIB_PY) deploy/install_torch.py --check
	@touch $(RLLIB_STAMP)

bench-rllib: $(RLLIB_STAMP)
	@$(RLLIB_PY) tools/bench/scripts/rllib_dqn.py $(RLLIB_ARGS)

# The replay peer (docs/replay-bench.md): DeepMind Reverb 0.14, the replay service Acme uses, under
# laneshift's replay benchmark's load. Its own venv: Reverb links TensorFlow 2.15, which needs numpy<2.
# tensorflow-cpu, so no CUDA packages. make bench-reverb REVERB_ARGS="--batch 256"
REVERB_VENV ?= .venv-reverb
REVERB_PY := $(REVERB_VENV)/bin/python
REVERB_STAMP := $(REVERB_VENV)/.installed-stamp
REVERB_ARGS ?=

.PHONY: bench-reverb

$(REVERB_STAMP):
	$(PYTHON) -m venv $(REVERB_VENV)
	$(REVERB_PY) -m pip install --disable-pip-version-check -q --no-deps dm-reverb==0.14.0
	$(REVERB_PY) -m pip install --disable-pip-version-check -q tensorflow-cpu==2.15.1 dm-tree portpicker "numpy<2"
	@if $(REVERB_PY) -m pip list 2>/dev/null | grep -i nvidia; then echo "error: CUDA packages were installed"; exit 1; fi
	@touch $(REVERB_STAMP)

bench-reverb: $(REVERB_STAMP)
	@TF_CPP_MIN_LOG_LEVEL=2 $(REVERB_PY) tools/bench/scripts/reverb_replay.py $(REVERB_ARGS)
