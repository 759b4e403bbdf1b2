"""Shared fixtures: rendered frames are cached per session because rendering dominates test time."""
import functools

import numpy as np
import pytest

from fcop_ros.ros.dds import keep_on_this_machine, use_large_image_profile

from fcop_ros.synthetic import apply_noise, render_scene

# Keep DDS traffic of every test on this machine and out of other runs' way, and use the
# shipped Fast DDS profile (large images across processes) in this process and its children.
# Set before any test initialises rclpy: Fast DDS reads the profile file once per process.
keep_on_this_machine()
use_large_image_profile()


@functools.lru_cache(maxsize=None)
def clean_frame(seed: int, width: int = 640, height: int = 480, focal=None):
    """A seeded random 5-object scene, rendered clean."""
    return render_scene(np.random.default_rng(seed), 5, focal, width, height)


@functools.lru_cache(maxsize=None)
def noisy_frame(seed: int, preset: str):
    return apply_noise(clean_frame(seed), preset, np.random.default_rng(10_000 + seed))


# Inputs that carry no focal evidence, as (depth, nocs, mask) -> None edits in place.
BAD_CASES = {
    "nan_depth": lambda d, n, m: d.fill(np.nan),
    "zero_depth": lambda d, n, m: d.fill(0.0),
    "inf_depth": lambda d, n, m: d.fill(np.inf),
    "empty_mask": lambda d, n, m: m.fill(0),
    "nocs_zero": lambda d, n, m: n.fill(0.0),
    "nocs_nan": lambda d, n, m: n.fill(np.nan),
    "single_pixel": lambda d, n, m: (m.fill(0), m.__setitem__((200, 300), 1)),
    "tiny_objects": lambda d, n, m: (m.fill(0), m.__setitem__((slice(100, 105), slice(100, 105)), 1)),
    "planar": lambda d, n, m: d.fill(1.0),  # every object flat at one depth: all triplets degenerate
}


def corrupted(frame, case):
    """A copy of a rendered frame with one of BAD_CASES applied."""
    from dataclasses import replace
    depth, nocs, mask = frame.depth.copy(), frame.nocs.copy(), frame.mask.copy()
    BAD_CASES[case](depth, nocs, mask)
    return replace(frame, depth=depth, nocs=nocs, mask=mask)


@pytest.fixture
def frames():
    return clean_frame, noisy_frame
