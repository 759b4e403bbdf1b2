"""The package, the tests, the benchmarks, the launch file and setup.py against the 99 columns
and the pycodestyle and pyflakes checks ROS 2 Python packages get from ament_flake8: with ruff
(the [test] extra; rules in ruff.toml), or else with flake8 (a ROS machine's python3-flake8)."""
import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PATHS = ["fcop_ros", "msg_adapters", "test", "bench", "launch", "setup.py"]


def test_lint_finds_nothing():
    if importlib.util.find_spec("ruff") is not None:
        cmd = ["ruff", "check", "--no-cache", "--output-format", "concise"]
    elif importlib.util.find_spec("flake8") is not None:
        cmd = ["flake8", "--max-line-length", "99"]
    else:
        pytest.skip("neither ruff (pip install -e '.[test]') nor flake8 is installed")
    run = subprocess.run([sys.executable, "-m", *cmd, *PATHS], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
