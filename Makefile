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

bench: $(STAMP)
	$(PY) bench/bench_core.py

clean:
	rm -rf .venv-* build install log *.egg-info
