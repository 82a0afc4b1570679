# RoboView — `make demo` and `make test` work on a fresh machine: they install what is missing.
SHELL := /bin/bash
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)
# Headless rendering through EGL (Mesa llvmpipe on CPU-only machines).
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
export HF_HUB_OFFLINE ?= 1
DEMO_DIR ?= outputs/demo

.PHONY: install sysdeps demo test bench clean-demo

install: sysdeps $(STAMP)

# System packages: ffmpeg (LeRobot's video decoding needs it) and Mesa EGL for off-screen rendering.
sysdeps:
	@if ! command -v ffmpeg >/dev/null || ! dpkg -s libegl1 libgl1-mesa-dri >/dev/null 2>&1; then \
	  echo "[install] apt-get install ffmpeg libegl1 libgl1-mesa-dri"; \
	  $(SUDO) apt-get update -qq && $(SUDO) apt-get install -y -qq ffmpeg libegl1 libgl1-mesa-dri >/dev/null; \
	fi

$(STAMP): pyproject.toml requirements.lock
	@test -x $(PY) || $(PYTHON) -m venv $(VENV) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q -c requirements.lock -e ".[dev]"
	@touch $(STAMP)

demo: install
	$(PY) -m pipelines.collect --dataset.repo_id=roboview/demo_pick_place \
	  --dataset.root=$(DEMO_DIR)/dataset --dataset.num_episodes=6 --num_workers=2
	$(PY) -m pipelines.build_benchmark --output_dir=$(DEMO_DIR)/benchmark --preset=tiny --num_workers=2
	$(PY) -m pipelines.evaluate --benchmark.path=$(DEMO_DIR)/benchmark --policy.type=vision \
	  --eval.n_repeats=3 --eval.num_workers=2 --eval.rerun=$(DEMO_DIR)/eval/vision.rrd \
	  --output_dir=$(DEMO_DIR)/eval/vision
	$(PY) -m pipelines.report --results=$(DEMO_DIR)/eval/vision/episodes.parquet --output_dir=$(DEMO_DIR)/report
	@echo "Demo dataset:   $(DEMO_DIR)/dataset (load with LeRobotDataset('roboview/demo_pick_place', root='$(DEMO_DIR)/dataset'))"
	@echo "Demo benchmark: $(DEMO_DIR)/benchmark (datasets.load_dataset('$(DEMO_DIR)/benchmark', split='color'))"
	@echo "Contact sheet:  $(DEMO_DIR)/benchmark/contact_sheet/index.html"
	@echo "Evaluation:     $(DEMO_DIR)/eval/vision/episodes.parquet (Rerun: .venv/bin/rerun $(DEMO_DIR)/eval/vision.rrd)"
	@echo "Report:         $(DEMO_DIR)/report/report.md (+ metrics.json and PNG plots)"

test: install
	$(PY) -m pytest -q

# The throughput harness (README "Numbers"): one JSON with every rate, side by side with lerobot-eval.
# BENCH_ARGS=--quick=true for the under-10-minute version; --checkpoint=DIR for another checkpoint.
BENCH_ARGS ?=
bench: install
	$(PY) -m benchmarks.throughput --output=outputs/bench/throughput.json $(BENCH_ARGS)

clean-demo:
	rm -rf $(DEMO_DIR)
