"""The fixed noise presets of the demo, fcop_make_bag and the tests.

Each preset is a fixed setting of the error mechanisms of :mod:`fcop_ros.synthetic.world` (an
:class:`~fcop_ros.synthetic.world.ErrorFamilies` used as it is, not drawn at random): a global
depth scale, a smooth depth error field, per-pixel depth noise, depth bleeding at edges,
per-pixel NOCS noise and outliers, eroded or dilated masks and spurious blobs. Every mechanism is
written once, in ``world.apply_errors``. Noise is applied to a rendered
:class:`~fcop_ros.synthetic.render.Frame` and returns a new frame with the same ground truth.
"""
from __future__ import annotations

import numpy as np

from .render import Frame
from .world import ErrorFamilies, ErrorState, apply_errors

# The smooth depth field of these presets: one spatial scale, interpolated from a 4x5 grid of
# random values as before the merge (its std is now exactly the nominal amplitude; it was about
# 0.85 of it).
_FIELD = {"field_cells": (3,)}

PRESETS = {
    "clean": ErrorFamilies(),
    "mild": ErrorFamilies(depth_scale=0.05, field=0.003, **_FIELD, depth_pixel=0.002, edge_px=1,
                          nocs_pixel=0.01, nocs_outliers=0.01, mask_px=1),
    "moderate": ErrorFamilies(depth_scale=0.1, field=0.006, **_FIELD, depth_pixel=0.005, edge_px=2,
                              nocs_pixel=0.02, nocs_outliers=0.05, mask_px=2, blobs=1),
    "harsh": ErrorFamilies(depth_scale=0.2, field=0.012, **_FIELD, depth_pixel=0.01, edge_px=3,
                           nocs_pixel=0.04, nocs_outliers=0.1, mask_px=3, blobs=2),
}


def apply_noise(frame: Frame, model: ErrorFamilies | str, rng: np.random.Generator) -> Frame:
    """Return a noisy copy of ``frame`` under ``model`` (fixed strengths, or a preset name)."""
    if isinstance(model, str):
        if model not in PRESETS:
            raise ValueError(f"unknown noise preset {model!r}; known: {sorted(PRESETS)}")
        model = PRESETS[model]
    return apply_errors(frame, ErrorState.start(model, rng), rng)
