"""Seeded test scenes, each rendered once per process, and inputs that carry no focal evidence.

The one place where the tests (and benchmarks) get their rendered frames: rendering dominates
test time, so every frame is cached here by its arguments. Each frame is a pure function of its
arguments (its own seeded generators), so what a test sees never depends on which tests ran
before it. Cached frames are shared: treat them as read-only (:func:`corrupted` copies).
"""
from __future__ import annotations

import functools
from dataclasses import replace

import numpy as np

from .noise import apply_noise
from .render import Frame, render_scene
from .world import world_frame as _world_frame

_cached = functools.lru_cache(maxsize=None)


@_cached
def clean_frame(seed: int, width: int = 640, height: int = 480, focal=None) -> Frame:
    """A seeded random 5-object scene, rendered clean (``focal=None`` draws one per scene)."""
    return render_scene(np.random.default_rng(seed), 5, focal, width, height)


def camera_frame(k: int, focal: float = 600.0) -> Frame:
    """Frame k of one camera: a clean 640x480 5-object scene seen at a fixed focal length."""
    return clean_frame(k, 640, 480, focal)


@_cached
def noisy_frame(seed: int, preset: str) -> Frame:
    """``clean_frame(seed)`` under one of the fixed noise presets."""
    return apply_noise(clean_frame(seed), preset, np.random.default_rng(10_000 + seed))


@_cached
def camera_frames(n: int, focal: float, preset: str = "moderate", first_seed: int = 0) -> tuple:
    """n 5-object 640x480 scenes of one camera (fixed focal) under a fixed noise preset."""
    return tuple(apply_noise(render_scene(np.random.default_rng(first_seed + k), 5, focal), preset,
                             np.random.default_rng(500 + first_seed + k)) for k in range(n))


@_cached
def world_frame(preset: str, seed: int, size=None) -> Frame:
    """One frame of the randomised world (:func:`fcop_ros.synthetic.world.world_frame`)."""
    return _world_frame(preset, seed, size=size)


# Inputs that carry no focal evidence, as (depth, nocs, mask) -> None edits in place.
BAD_CASES = {
    "nan_depth": lambda d, n, m: d.fill(np.nan),
    "zero_depth": lambda d, n, m: d.fill(0.0),
    "inf_depth": lambda d, n, m: d.fill(np.inf),
    "empty_mask": lambda d, n, m: m.fill(0),
    "nocs_zero": lambda d, n, m: n.fill(0.0),
    "nocs_nan": lambda d, n, m: n.fill(np.nan),
    "single_pixel": lambda d, n, m: (m.fill(0), m.__setitem__((200, 300), 1)),
    "tiny_objects": lambda d, n, m: (m.fill(0),
                                     m.__setitem__((slice(100, 105), slice(100, 105)), 1)),
    # every object flat at one depth: all triplets degenerate
    "planar": lambda d, n, m: d.fill(1.0),
}


def corrupted(frame: Frame, case: str) -> Frame:
    """A copy of a rendered frame with one of BAD_CASES applied."""
    depth, nocs, mask = frame.depth.copy(), frame.nocs.copy(), frame.mask.copy()
    BAD_CASES[case](depth, nocs, mask)
    return replace(frame, depth=depth, nocs=nocs, mask=mask)
