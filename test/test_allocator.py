"""fcop_node's allocator limit: glibc's malloc arenas stay at two however many threads allocate
at once (so the node's memory does not grow in steps over long runs; fcop_ros/ros/allocator.py)."""
import os
import subprocess
import sys

import pytest

from fcop_ros.ros.allocator import limit_allocator_arenas

# Eight threads malloc at once (ctypes releases the GIL around each call), then glibc's
# malloc_stats lists every arena on stderr. Without a limit this machine made 5 to 9 arenas.
SCRIPT = r"""
import ctypes, sys, threading
from fcop_ros.ros.allocator import limit_allocator_arenas
print(limit_allocator_arenas(), flush=True)
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
def work():
    for _ in range(20000):
        libc.free(libc.malloc(1000))
threads = [threading.Thread(target=work) for _ in range(8)]
for t in threads:
    t.start()
for t in threads:
    t.join()
libc.malloc_stats()
"""


def _run(env):
    return subprocess.run([sys.executable, "-c", SCRIPT], env=env, capture_output=True,
                          text=True, timeout=60, check=True)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator")
def test_two_arenas_however_many_threads_allocate():
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    out = _run(env)
    assert out.stdout.strip() == "True"
    arenas = [line for line in out.stderr.splitlines() if line.startswith("Arena")]
    assert 1 <= len(arenas) <= 2


def test_the_environment_rules_when_it_says(monkeypatch):
    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    assert limit_allocator_arenas() is False
