# Two entry points that work on a fresh machine with nothing but Python:
#   make demo   a short skill-chaining run on Pinball: TensorBoard logs and figures under runs/demo
#   make test   the whole test suite
# Both create .venv on first use. torch is pinned first so pip takes the local CPU build
# instead of pulling several GB of CUDA wheels. --no-cache-dir: a CI machine once ran out of
# disk mid-install (ENOSPC), and the cache only doubles the wheels on a one-off install. -qq:
# errors only (setuptools prints a notice on every editable install, which is not one).
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
TORCH_PIN := torch==2.13.0

# What running needs (make demo), then what testing adds (make test: pytest, ruff, Ray, ...).
$(VENV)/.installed-run: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -qq --no-cache-dir --upgrade pip
	$(PY) -m pip install -qq --no-cache-dir $(TORCH_PIN)
	$(PY) -m pip install -qq --no-cache-dir -e .
	touch $@

$(VENV)/.installed: $(VENV)/.installed-run
	$(PY) -m pip install -qq --no-cache-dir -e ".[dev,bench]"
	touch $@

.PHONY: install test demo lint bench docs
install: $(VENV)/.installed

# -n auto: one pytest worker per core (pytest-xdist, each worker's torch at one thread:
# tests/conftest.py); --dist worksteal: an idle worker takes tests queued on the other. The
# suite took 18 minutes on one core of CI's two.
test: $(VENV)/.installed
	$(PY) -m pytest -n auto --dist worksteal

lint: $(VENV)/.installed
	$(VENV)/bin/ruff check .

# The API reference from the docstrings (Sphinx), warnings as errors: docs/_build/html/index.html
docs: $(VENV)/.installed
	$(VENV)/bin/sphinx-build -W --keep-going -b html docs docs/_build/html

demo: $(VENV)/.installed-run
	$(VENV)/bin/skillchain train --agent skill-chaining --map pinball_simple_single --runs 4 --episodes 30 --seed 0 --out runs/demo --overwrite
	@echo "TensorBoard: $(VENV)/bin/tensorboard --logdir runs/demo/tb ; figures: runs/demo/learning_curve.png runs/demo/option_tree.png runs/demo/option_trajectory.png"

bench: $(VENV)/.installed
	$(PY) benchmarks/env_throughput.py
	$(PY) benchmarks/train_throughput.py
