"""ruff over the package, the tests, the benchmarks, the launch file and setup.py, with the
rules of ruff.toml (99 columns; pycodestyle and pyflakes, as ament_flake8 checks)."""
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PATHS = ["fcop_ros", "msg_adapters", "test", "bench", "launch", "setup.py"]


def test_ruff_finds_nothing():
    pytest.importorskip("ruff", reason="ruff is in the [test] extra (pip install -e '.[test]')")
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "--output-format",
                          "concise",
                          *PATHS], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
