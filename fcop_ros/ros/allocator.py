"""A flat memory footprint for a long-running node: glibc's allocator arenas limited to two.

glibc gives a thread that finds the allocator busy an arena of its own, up to eight per core,
and an arena's heap rarely shrinks. The node's executor thread and its estimator thread allocate
at the same time (the estimator's kernels release the GIL), so its resident memory climbed in
steps over 10,000 frames (703 to 717 MB, bench/bench_node.py) though nothing leaked. Two arenas,
one per thread, stop the steps. ``MALLOC_ARENA_MAX`` in the environment, when set, is left to rule;
other C libraries are left alone.
"""
from __future__ import annotations

import ctypes
import os

M_ARENA_MAX = -8  # glibc's malloc.h
ARENAS = 2


def limit_allocator_arenas(arenas: int = ARENAS) -> bool:
    """Limit glibc's malloc arenas to ``arenas`` for the rest of the process; True when applied
    (False under another C library or when ``MALLOC_ARENA_MAX`` is set). Call it before the
    threads that allocate start: arenas already made stay."""
    if "MALLOC_ARENA_MAX" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # glibc only: elsewhere mallopt's codes mean other things
    except (OSError, AttributeError):
        return False
    return bool(libc.mallopt(M_ARENA_MAX, int(arenas)))
