# Two commands on a fresh machine: `make demo` and `make test`. Both create (or reuse) the
# virtual environment of the chosen ROS 2 distribution's PyPI wheels: ROS=kilted (default) or
# ROS=jazzy. The two distributions cannot share one environment.
ROS ?= kilted
VENV ?= .venv-$(ROS)
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed
PYTHON ?= python3

.PHONY: venv demo test test-all bench clean

$(STAMP): setup.py setup.cfg package.xml
	$(PYTHON) -m venv $(VENV)
	$(VENV)/bin/pip install -q --upgrade pip 'setuptools<80' wheel
	$(VENV)/bin/pip install -q -e '.[$(ROS),test]'
	touch $@

venv: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/fcop_demo

test: $(STAMP)
	$(PY) -m pytest -q test

test-all:
	$(MAKE) test ROS=kilted
	$(MAKE) test ROS=jazzy

# The main figures of docs/BENCHMARKS.md and the README (about two hours; P4Pf needs the [bench]
# extra: pycolmap). Prints them; the committed docs and plots are left as they are.
bench: $(STAMP)
	$(VENV)/bin/pip install -q -e '.[$(ROS),test,bench]'
	$(PY) bench/bench_core.py
	$(PY) bench/bench_node.py --frames 10000 --closed-loop-frames 200
	$(PY) bench/bench_node.py --frames 300 --closed-loop-frames 30 --slow-ms 100
	$(PY) bench/world_calibration.py --frames 300 --presets sensor --gains 1.0
	$(PY) bench/world_calibration.py --frames 1000 --presets predicted --gains 0.55
	for set in "" --heldout10 --heldout11 --heldout12 --heldout13; do \
	  $(PY) bench/world_accuracy.py --frames 60 --parts single window zoom $$set || exit 1; done
	$(PY) bench/world_accuracy.py --parts bias preset_bias --bias-frames 1000
	$(PY) bench/world_accuracy.py --parts preset_bias --bias-frames 1000 --heldout11
	$(PY) bench/paper_simulation.py --out out/bench

clean:
	rm -rf .venv-* build install log *.egg-info
