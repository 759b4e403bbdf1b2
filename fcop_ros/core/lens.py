"""A rectified image's residual radial distortion k1 (prior ``lens_distortion_std``): how far
it moves each object's focal length, by which the objects' disagreement estimates it like an
assumed principal point's offset (:mod:`.offsets`; ``FocalEstimate.lens_k1``, its uncertainty
in ``std_rel_lens``). Objects spread over the image fix it (on 60 `sensor` tuning frames the
estimate follows the world's k1 with a correlation of 0.50, nearly exactly in frames of four to
six objects), one object not at all; a window pools it over its frames. A trial that fitted k1
inside each object's fit instead took the smooth depth errors for it (docs/BENCHMARKS.md).

A distortion x (1 + k1 |x / f|^2) magnifies an object by about 1 + 2 k1 r^2, yet the fit's
answer moves far more where the depth is noisy: the fit weighs the pixels by their residuals and
explains the magnification's change across the object by perspective, trading its distance and
f (on eight `sensor` tuning frames, -0.03 to -1.43% of f per 0.01 of k1, test/test_lens.py,
where without their depth noise it moves +0.01 to +0.12%). So each object's gradient comes
from a refit, as the principal point's does (:func:`~.principal_point.focal_gradients`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .object_fit import refit_log_focal_change


def lens_gradients(support, f0: float, seed: int, k1_std: float, options, logf) -> np.ndarray:
    """(O,) d log f / d k1 of every object: its fit redone on its pixels undistorted by one
    standard deviation ``k1_std`` of k1 (the same pixels as the fit ``logf`` came from), the
    forward difference; zeros where ``k1_std`` is 0 or a refit fails."""
    grads = np.zeros(len(support))
    if k1_std <= 0 or not support:
        return grads
    moved = [replace(inst, x=inst.x * (1.0 - k1_std * np.sum(inst.x * inst.x, axis=1,
                                                              keepdims=True) / f0**2))
             for inst in support]
    return refit_log_focal_change(moved, f0, seed, options, logf, -k1_std)
