"""Seeded synthetic data for tests, demos and benchmarks: the paper's point simulation and
rendered depth / NOCS / mask frames with noise models that imitate learned predictors."""
from .noise import PRESETS, NoiseModel, apply_noise
from .points import PointTrial, simulate_points, simulate_triplet_batch
from .render import CATEGORIES, Frame, SceneObject, random_scene, render, render_scene
from .sequence import SequenceSpec, camera_sequence

__all__ = ["PRESETS", "NoiseModel", "apply_noise", "PointTrial", "simulate_points",
           "simulate_triplet_batch", "CATEGORIES", "Frame", "SceneObject",
           "random_scene", "render", "render_scene", "SequenceSpec", "camera_sequence"]
