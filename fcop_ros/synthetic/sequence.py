"""Synthetic camera sequences: one table-top scene seen by a slowly orbiting camera, with an
optional zoom (a focal length change) at a given frame."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from ..core.options import FOCAL_LIMITS
from .noise import PRESETS, apply_noise
from .render import Frame, SceneObject, random_scene, render


@dataclass
class SequenceSpec:
    """What a sequence shows: frames, size, focal (px), zoom, noise preset, objects and orbit
    speed."""

    frames: int = 60
    width: int = 640
    height: int = 480
    focal: float = 600.0
    zoom_frame: int | None = None
    zoom_focal: float | None = None
    preset: str = "moderate"
    objects: int = 5
    orbit_deg_per_frame: float = 0.5

    def __post_init__(self):
        if self.frames < 1 or self.width < 8 or self.height < 8 or self.objects < 1:
            raise ValueError("need at least one frame, one object and an image of 8x8 or more")
        for name in ("focal", "zoom_focal"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and FOCAL_LIMITS[0] <= v <= FOCAL_LIMITS[1]):
                raise ValueError(f"{name.replace('_', ' ')} must be a number of pixels in "
                                 f"[{FOCAL_LIMITS[0]:g}, {FOCAL_LIMITS[1]:g}] (the node's "
                                 f"focal range), got {v}")
        if (self.zoom_frame is None) != (self.zoom_focal is None):
            raise ValueError("a zoom needs both its frame and its focal length")
        if self.zoom_frame is not None and not 0 <= self.zoom_frame < self.frames:
            raise ValueError(f"the zoom frame {self.zoom_frame} is not one of the "
                             f"{self.frames} frames")
        if self.preset not in PRESETS:
            raise ValueError(f"unknown noise preset {self.preset!r}: one of {sorted(PRESETS)}")

    def focal_at(self, k: int) -> float:
        if self.zoom_frame is not None and self.zoom_focal is not None and k >= self.zoom_frame:
            return float(self.zoom_focal)
        return float(self.focal)


def camera_sequence(spec: SequenceSpec, seed: int = 0):
    """Yield (k, frame) for every frame of the sequence; frames carry their true focal and
    poses."""
    rng = np.random.default_rng(seed)
    # Lay the scene out for the narrowest field of view so a zoom keeps the objects in view.
    layout = max(spec.focal, spec.zoom_focal or 0.0)
    objs, _, table = random_scene(rng, spec.objects, layout, spec.width, spec.height)
    centre, up = table
    for k in range(spec.frames):
        R = Rotation.from_rotvec(np.radians(spec.orbit_deg_per_frame * k) * up).as_matrix()
        moved = [SceneObject(o.instance_id, o.category, R @ o.rotation,
                             R @ (o.translation - centre) + centre, o.scale)
                 for o in objs]
        frame: Frame = render(moved, spec.focal_at(k), spec.width, spec.height, table=table)
        yield k, apply_noise(frame, spec.preset, rng)
