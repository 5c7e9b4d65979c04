# roadsynth: `make demo` sets up .venv and runs the default pipeline; `make test` sets up and runs the tests.
# Both are idempotent: the install steps rerun only when pyproject.toml changes.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
export DVC_NO_ANALYTICS := 1
export PATH := $(abspath $(BIN)):$(PATH)

.PHONY: demo test setup setup-dev system-deps lint bench clean-data

demo: setup
	$(BIN)/dvc repro
	@echo
	@echo "Outputs (README.md, 'Where outputs go'):"
	@echo "  data/sim/<scenario>-<seed>/              simulated runs"
	@echo "  data/records/<scenario>-<seed>-<cond>/   rendered dataset records; previews/*.png contact sheets"
	@echo "  data/exports/{coco,kitti,mcap}           exports (open mcap/runs.mcap in Foxglove, layout mcap/runs.layout.json)"
	@echo "  data/models/baseline/                    the trained baseline detector"
	@echo "  reports/report.md, reports/examples.png  precision/recall per condition and IoU, COCO AP"
	@echo "  $(BIN)/dvc metrics show | $(BIN)/dvc plots show"

test: setup-dev
	$(BIN)/python -m pytest

lint: setup-dev
	$(BIN)/ruff check .
	$(BIN)/lint-imports

setup: system-deps $(VENV)/.installed
setup-dev: system-deps $(VENV)/.installed-dev

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

# torch is pinned to 2.13.0 in pyproject.toml so pip takes the CPU build instead of CUDA packages.
$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-dev: pyproject.toml $(VENV)/.installed
	$(BIN)/python -m pip install --quiet -e '.[dev]'
	touch $@

# Open3D needs the system library libusb-1.0.
system-deps:
	@if ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then :; \
	elif [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
		echo "installing libusb-1.0 (needed by Open3D)"; \
		apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null; \
	else \
		echo "Open3D needs the system library libusb-1.0. Install it, then rerun make:"; \
		echo "    sudo apt-get install libusb-1.0-0      (Debian/Ubuntu)"; \
		echo "    sudo dnf install libusb1               (Fedora)"; \
		echo "    brew install libusb                    (macOS)"; \
		exit 1; \
	fi

# The benchmarks that make their own input; bench_antialias (--sim DIR) and bench_detector (--coco DIR) take one.
bench: setup-dev
	$(BIN)/python bench/bench_simulate.py
	$(BIN)/python bench/bench_render_core.py
	$(BIN)/python bench/bench_render.py
	$(BIN)/python bench/bench_png.py
	$(BIN)/python bench/bench_export.py
	$(BIN)/python bench/bench_coco_eval.py
	$(BIN)/python bench/bench_kitti_eval.py

clean-data:
	rm -rf data
