# roadsynth: `make demo` sets up .venv and runs the default pipeline; `make test` sets up and runs the tests.
# Both are idempotent: the install steps rerun only when pyproject.toml changes.

PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
export DVC_NO_ANALYTICS := 1
export PATH := $(abspath $(BIN)):$(PATH)

.PHONY: demo test setup setup-dev system-deps lint bench clean-data paper paper-outputs realism realism-outputs

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
	$(BIN)/python -m pip install --quiet -e '.[dev,ray,nuscenes,cityscapes]'
	$(BIN)/python -m pip install --quiet --no-deps 'nuscenes-devkit==1.2.0'  # not an extra: see pyproject.toml
	$(BIN)/python -m pip install --quiet --no-deps 'trackeval>=1.3,<2'  # not an extra: see pyproject.toml
	$(BIN)/python -m pip install --quiet --no-deps 'cityscapesscripts==2.3.0'  # not an extra: see pyproject.toml
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

# The benchmarks that make their own input; bench_antialias (--sim DIR), bench_detector (--coco DIR) and
# bench_people_scale (--onnx MODEL --photo PHOTO, a control of a detector on real people by height) take one.
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

# ---------------------------------------------------------------------------------------------------
# What the experiments below share: a field of an experiment file ($(1): the file, $(2): the field; a list comes
# out separated by spaces), and the rules that simulate a run ($(1): the output folder, $(2) scenario, $(3) seed,
# $(4) simulate's options, $(5) the experiment file) and render a record ($(1) the output folder, $(2) scenario,
# $(3) seed, $(4) condition, $(5) rig, $(6) frames).
experiment_get = $(shell $(BIN)/python -c "import yaml; v = yaml.safe_load(open('$(1)'))['$(2)']; print(*v) if isinstance(v, list) else print(v)")
empty :=
space := $(empty) $(empty)

define sim_rule
$(1)/sim/$(2)-$(3): $(5)
	roadsynth simulate --scenario $(2) --seed $(3) $(4) --no-progress --out $$@
endef
define record_rule
$(1)/records/$(2)-$(3)-$(4): $(1)/sim/$(2)-$(3)
	roadsynth render --sim $$< --condition $(4) --rig $(5) --frames $(6) --no-progress --out $$@
endef

# ---------------------------------------------------------------------------------------------------
# The paper's experiment (Li, Kusari & LeBlanc, Table 1) as one command:
#
#     make paper ONNX=path/to/detector.onnx
#
# reads $(PAPER) (scenarios, seeds, conditions, rig, vehicles, warm-up, duration, IoU thresholds),
# simulates every (scenario, seed), renders every condition ($(PAPER_FRAMES) frames per run), exports
# COCO with the last seed of each scenario as the test split, trains the baseline detector on the
# others' morning frames, runs the baseline and the ONNX detector (`detect --onnx`: YOLOX / YOLOv5 /
# YOLOv8 raw heads or decoded outputs) on the test split, evaluates both per condition and writes
# $(PAPER_OUT)/report/report.md: Table 1 with the paper's figures beside both detectors, recall by
# distance and by box height, COCO AP. Outputs already made are kept (make's timestamps); every
# stage writes atomically. PAPER_* variables below scale it down (the tests run a 2-frame version).
PAPER ?= configs/experiments/paper_table1.yaml
PAPER_OUT ?= data/paper
PAPER_FRAMES ?= 60
PAPER_TRAIN_CONFIG ?= default
PAPER_TRAIN_CONDITIONS ?= morning
ONNX ?=
ONNX_NAME ?= $(basename $(notdir $(ONNX)))
ONNX_OPTIONS ?=

paper: setup
	$(MAKE) --no-print-directory paper-outputs ONNX="$(ONNX)"

ifneq ($(filter paper-outputs,$(MAKECMDGOALS)),)
ifeq ($(strip $(ONNX)),)
$(error give the ONNX detector: make paper ONNX=path/to/detector.onnx)
endif
paper_get = $(call experiment_get,$(PAPER),$(1))
P_SCENARIOS := $(call paper_get,scenarios)
P_SEEDS := $(call paper_get,seeds)
P_CONDITIONS := $(call paper_get,conditions)
P_IOUS := $(call paper_get,iou_thresholds)
PAPER_RIG ?= $(call paper_get,rig)
P_SIM_ARGS := --vehicles $(call paper_get,vehicles) --warmup $(call paper_get,warmup_s) --duration $(call paper_get,duration_s)
P_SPLITS := test=$(subst $(space),+,$(foreach s,$(P_SCENARIOS),$(s):$(lastword $(P_SEEDS)))),train=*
P_RECORDS := $(foreach s,$(P_SCENARIOS),$(foreach n,$(P_SEEDS),$(foreach c,$(P_CONDITIONS),$(PAPER_OUT)/records/$(s)-$(n)-$(c))))
P_GT := $(PAPER_OUT)/coco/annotations_test.json

$(foreach s,$(P_SCENARIOS),$(foreach n,$(P_SEEDS),$(eval $(call sim_rule,$(PAPER_OUT),$(s),$(n),$(P_SIM_ARGS),$(PAPER)))))
$(foreach s,$(P_SCENARIOS),$(foreach n,$(P_SEEDS),$(foreach c,$(P_CONDITIONS),\
	$(eval $(call record_rule,$(PAPER_OUT),$(s),$(n),$(c),$(PAPER_RIG),$(PAPER_FRAMES))))))

$(PAPER_OUT)/coco: $(P_RECORDS)
	roadsynth export --dataset $(PAPER_OUT)/records --format coco --splits "$(P_SPLITS)" --no-progress --out $@

$(PAPER_OUT)/models/baseline: $(PAPER_OUT)/coco
	roadsynth train --coco $< --split train --conditions $(PAPER_TRAIN_CONDITIONS) --config $(PAPER_TRAIN_CONFIG) \
		--seed 0 --no-progress --out $@

$(PAPER_OUT)/detections/baseline.json: $(PAPER_OUT)/models/baseline $(PAPER_OUT)/coco
	roadsynth detect --model $< --coco $(PAPER_OUT)/coco --split test --no-progress --out $@

$(PAPER_OUT)/detections/$(ONNX_NAME).json: $(ONNX) $(PAPER_OUT)/coco
	roadsynth detect --onnx $(ONNX) --coco $(PAPER_OUT)/coco --split test --no-progress $(ONNX_OPTIONS) --out $@

$(PAPER_OUT)/eval/%: $(PAPER_OUT)/detections/%.json
	roadsynth evaluate --gt $(P_GT) --detections $< --group-by condition --iou $(P_IOUS) \
		--metrics table,coco,errors --out $@

$(PAPER_OUT)/report: $(PAPER_OUT)/eval/baseline $(PAPER_OUT)/eval/$(ONNX_NAME)
	roadsynth report --gt $(P_GT) --paper --out $@ \
		--eval baseline=$(PAPER_OUT)/eval/baseline --detections baseline=$(PAPER_OUT)/detections/baseline.json \
		--eval $(ONNX_NAME)=$(PAPER_OUT)/eval/$(ONNX_NAME) \
		--detections $(ONNX_NAME)=$(PAPER_OUT)/detections/$(ONNX_NAME).json
	@echo "Table 1, ours beside the paper's: $@/report.md"

paper-outputs: $(PAPER_OUT)/report
endif

# ---------------------------------------------------------------------------------------------------
# The realism gauge (issue 39, docs/realism.md) as one command:
#
#     make realism ONNX=path/to/detector.onnx
#
# reads $(REALISM) (scenarios, held-out seeds, the six conditions, rig, vehicles, warm-up, duration, frames per
# record, the detector's score threshold), simulates every (scenario, seed), renders every condition, exports COCO,
# runs the ONNX detector (`detect --onnx`, COCO classes mapped by the 80-class table) on every frame and scores it
# with `roadsynth evaluate --task realism` into $(REALISM_OUT)/report/$(ONNX_NAME)/: realism.md (AP50, recall,
# precision and recall per object by class group, condition and box height; recall by distance beside the fog's
# transmittance; mean luma; objects per frame), metrics.json, missed_<group>.png (contact sheets of the objects it
# missed) and recall_by_distance.png. REALISM_FRAMES overrides the frames per record (a small run: REALISM_FRAMES=10
# REALISM_OUT=data/realism-small); REALISM_SEEDS, REALISM_CONDITIONS and REALISM_SCENARIOS the matrix.
REALISM ?= configs/experiments/realism.yaml
REALISM_OUT ?= data/realism
REALISM_FRAMES ?=
REALISM_RIG ?=
REALISM_SEEDS ?=
REALISM_CONDITIONS ?=
REALISM_SCENARIOS ?=

realism: setup
	$(MAKE) --no-print-directory realism-outputs ONNX="$(ONNX)"

ifneq ($(filter realism-outputs,$(MAKECMDGOALS)),)
ifeq ($(strip $(ONNX)),)
$(error give the ONNX detector: make realism ONNX=path/to/detector.onnx)
endif
realism_get = $(call experiment_get,$(REALISM),$(1))
R_SCENARIOS := $(or $(REALISM_SCENARIOS),$(call realism_get,scenarios))
R_SEEDS := $(or $(REALISM_SEEDS),$(call realism_get,seeds))
R_CONDITIONS := $(or $(REALISM_CONDITIONS),$(call realism_get,conditions))
R_FRAMES := $(or $(REALISM_FRAMES),$(call realism_get,frames))
R_RIG := $(or $(REALISM_RIG),$(call realism_get,rig))
R_SCORE := $(call realism_get,score_threshold)
R_SIM_ARGS := --vehicles $(call realism_get,vehicles) --warmup $(call realism_get,warmup_s) \
	--duration $(call realism_get,duration_s)
R_RECORDS := $(foreach s,$(R_SCENARIOS),$(foreach n,$(R_SEEDS),$(foreach c,$(R_CONDITIONS),$(REALISM_OUT)/records/$(s)-$(n)-$(c))))
R_REPORT := $(REALISM_OUT)/report/$(ONNX_NAME)

$(foreach s,$(R_SCENARIOS),$(foreach n,$(R_SEEDS),$(eval $(call sim_rule,$(REALISM_OUT),$(s),$(n),$(R_SIM_ARGS),$(REALISM)))))
$(foreach s,$(R_SCENARIOS),$(foreach n,$(R_SEEDS),$(foreach c,$(R_CONDITIONS),\
	$(eval $(call record_rule,$(REALISM_OUT),$(s),$(n),$(c),$(R_RIG),$(R_FRAMES))))))

$(REALISM_OUT)/coco: $(R_RECORDS)
	roadsynth export $(foreach r,$(R_RECORDS),--dataset $(r)) --format coco --no-progress --out $@

$(REALISM_OUT)/detections/$(ONNX_NAME).json: $(ONNX) $(REALISM_OUT)/coco
	roadsynth detect --onnx $(ONNX) --coco $(REALISM_OUT)/coco --no-progress $(ONNX_OPTIONS) --out $@

$(R_REPORT): $(REALISM_OUT)/detections/$(ONNX_NAME).json
	roadsynth evaluate --task realism --gt $(REALISM_OUT)/coco/annotations.json --detections $< \
		--score-threshold $(R_SCORE) --group-by condition --group-order $(R_CONDITIONS) --out $@
	@echo "The realism report: $@/realism.md"

realism-outputs: $(R_REPORT)
endif
