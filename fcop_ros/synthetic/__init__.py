"""Seeded synthetic data for tests, demos and benchmarks: the paper's point simulation and
rendered depth / NOCS / mask frames with the errors of learned predictors (one set of error
mechanisms, world.py: drawn at random per sequence there, at fixed strengths in noise.PRESETS)."""
from .noise import PRESETS, apply_noise
from .points import PointTrial, simulate_points, simulate_triplet_batch
from .render import CATEGORIES, Frame, SceneObject, random_scene, render, render_scene
from .sequence import SequenceSpec, camera_sequence
from .world import ErrorFamilies

__all__ = ["PRESETS", "ErrorFamilies", "apply_noise", "PointTrial", "simulate_points",
           "simulate_triplet_batch", "CATEGORIES", "Frame", "SceneObject",
           "random_scene", "render", "render_scene", "SequenceSpec", "camera_sequence"]
