"""Noise models that imitate learned depth, NOCS and instance-mask predictors.

Each effect is one field of :class:`NoiseModel`; ``PRESETS`` names combinations from clean to
harsh. Noise is applied to a rendered :class:`~fcop_ros.synthetic.render.Frame` and returns a new
frame with the same ground truth (focal, objects).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from .render import Frame


@dataclass(frozen=True)
class NoiseModel:
    """Predictor errors; depths are relative (fractions of the depth), sizes in pixels.

    depth_scale: sigma of a global log-scale error (cancels in the focal by construction);
    depth_smooth: amplitude of a smooth relative error field (a few cells across the image);
    depth_pixel: sigma of independent per-pixel relative noise;
    edge_px: width of the band around depth discontinuities where depth bleeds across the edge;
    nocs_sigma: sigma of per-pixel NOCS noise;
    nocs_outliers: share of object pixels with random NOCS;
    mask_px: each instance mask is eroded or dilated by up to this many pixels (dilated pixels
    take the background depth and the nearest NOCS, like a real predictor);
    blobs: number of spurious instances with random NOCS.
    """

    depth_scale: float = 0.0
    depth_smooth: float = 0.0
    depth_pixel: float = 0.0
    edge_px: int = 0
    nocs_sigma: float = 0.0
    nocs_outliers: float = 0.0
    mask_px: int = 0
    blobs: int = 0


PRESETS = {
    "clean": NoiseModel(),
    "mild": NoiseModel(depth_scale=0.05, depth_smooth=0.003, depth_pixel=0.002, edge_px=1,
                       nocs_sigma=0.01, nocs_outliers=0.01, mask_px=1),
    "moderate": NoiseModel(depth_scale=0.1, depth_smooth=0.006, depth_pixel=0.005, edge_px=2,
                           nocs_sigma=0.02, nocs_outliers=0.05, mask_px=2, blobs=1),
    "harsh": NoiseModel(depth_scale=0.2, depth_smooth=0.012, depth_pixel=0.01, edge_px=3,
                        nocs_sigma=0.04, nocs_outliers=0.1, mask_px=3, blobs=2),
}


def _smooth_field(rng, h, w, cells=4):
    coarse = rng.normal(size=(cells, cells + 1)).astype(np.float32)
    return cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC).astype(np.float64)


def apply_noise(frame: Frame, model: NoiseModel | str, rng: np.random.Generator) -> Frame:
    """Return a noisy copy of ``frame`` under ``model`` (a NoiseModel or a preset name)."""
    if isinstance(model, str):
        if model not in PRESETS:
            raise ValueError(f"unknown noise preset {model!r}; known: {sorted(PRESETS)}")
        model = PRESETS[model]
    depth, nocs, mask = frame.depth.copy(), frame.nocs.copy(), frame.mask.copy()
    h, w = depth.shape
    finite = np.isfinite(depth)
    far = np.nanmax(depth) if finite.any() else 1.0
    if model.edge_px > 0:
        filled = np.where(finite, depth, far).astype(np.float32)
        k = 2 * model.edge_px + 1
        blurred = cv2.GaussianBlur(filled, (2 * k + 1, 2 * k + 1), 0).astype(np.float64)
        grad = np.abs(cv2.Laplacian(filled, cv2.CV_32F))
        edges = (grad > 0.02 * filled).astype(np.uint8)
        band = cv2.dilate(edges, np.ones((k, k), np.uint8)).astype(bool) & finite
        depth[band] = blurred[band]
    if model.mask_px > 0:
        new = np.zeros_like(mask)
        ids = np.unique(mask[mask > 0])
        near_nocs = np.stack(
            [
                cv2.dilate(
                    nocs[..., c].astype(np.float32),
                    np.ones((2 * model.mask_px + 1,) * 2, np.uint8),
                )
                for c in range(3)
            ],
            -1,
        )
        for iid in ids:
            m = (mask == iid).astype(np.uint8)
            r = int(rng.integers(-model.mask_px, model.mask_px + 1))
            kern = np.ones((2 * abs(r) + 1,) * 2, np.uint8)
            m2 = cv2.dilate(m, kern) if r > 0 else cv2.erode(m, kern) if r < 0 else m
            grow = m2.astype(bool) & (mask != iid) & (new == 0)
            nocs[grow & (mask == 0)] = near_nocs[grow & (mask == 0)]
            new[m2.astype(bool) & ((new == 0) | (mask == iid))] = iid
        mask = new
    if model.depth_scale > 0:
        depth *= np.exp(rng.normal(0, model.depth_scale))
    if model.depth_smooth > 0:
        depth *= 1.0 + model.depth_smooth * _smooth_field(rng, h, w)
    if model.depth_pixel > 0:
        depth *= 1.0 + model.depth_pixel * rng.normal(size=(h, w))
    obj = mask > 0
    if model.nocs_sigma > 0:
        nocs[obj] += rng.normal(0, model.nocs_sigma, (int(obj.sum()), 3))
    if model.nocs_outliers > 0:
        out = obj & (rng.random((h, w)) < model.nocs_outliers)
        nocs[out] = rng.random((int(out.sum()), 3))
    for b in range(model.blobs):
        cy, cx = rng.integers(0, h), rng.integers(0, w)
        ax = (int(rng.integers(10, max(11, w // 12))), int(rng.integers(10, max(11, h // 12))))
        blob = np.zeros((h, w), np.uint8)
        cv2.ellipse(blob, (int(cx), int(cy)), ax, float(rng.uniform(0, 180)), 0, 360, 1, -1)
        blob = blob.astype(bool) & (mask == 0) & np.isfinite(depth)
        mask[blob] = int(mask.max()) + 1
        field = np.stack([_smooth_field(rng, h, w, 2) for _ in range(3)], -1)
        nocs[blob] = np.clip(0.5 + 0.3 * field[blob], 0.01, 1.0)
    nocs[mask > 0] = np.clip(nocs[mask > 0], 0.0, 1.0)
    nocs[mask == 0] = 0.0
    return replace(frame, depth=depth, nocs=nocs, mask=mask)
