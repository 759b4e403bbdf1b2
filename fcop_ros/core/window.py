"""Sliding window of focal evidence over recent frames, with zoom (focal change) detection.

Each frame contributes its own estimate (the frame's stabbed and refined focal length), its
support (the triplet votes that agree with it) and the refinement statistics of its supporting
objects. The window stabs the frames' estimates, each an interval of +-noise_bound weighted by
its support, to find the frames that agree (a noisy or wrong frame is outvoted), then refines f
over the statistics of those frames' objects, so each frame counts by how well it constrains f.
When the last ``change_frames`` frame estimates all lie on the same side of the window estimate
and their mean deviation is beyond both ``change_threshold`` and four standard errors of the
frames before them, the camera's focal length has changed: older frames are dropped so the
window re-converges to the new value instead of averaging old and new.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .estimator import FocalEstimate
from .refine import ObjectStats, refine_focal
from .stabbing import focal_intervals, interval_stabbing


@dataclass
class WindowEstimate:
    """The window's current estimate.

    focal: pixels, or None without enough evidence (``reason`` says why). support: triplet votes
    agreeing in the frames that agree with the estimate; confidence: the support-weighted share
    of the window's frames that agree (0..1); spread: robust relative spread of the per-frame
    estimates (None below 2 frames); std_rel: relative standard error of the refined value
    (optimistic for correlated noise); frames: frames in the window; changed: True when this
    update detected a focal change and restarted the window.
    """

    focal: float | None
    support: int = 0
    confidence: float = 0.0
    spread: float | None = None
    std_rel: float | None = None
    frames: int = 0
    changed: bool = False
    reason: str = ""


@dataclass
class _Frame:
    stamp: float
    focal: float | None
    support: int
    stats: ObjectStats


class FocalWindow:
    """Accumulates :class:`FocalEstimate` s of successive frames into a stable focal length.

    Args:
        max_frames: frames kept (the window length); max_age: seconds kept (None: no limit).
        noise_bound, bound_mode: half-width of each frame's interval, as in :func:`estimate_focal`.
        min_frames, min_support, min_confidence: evidence needed before a focal is reported.
        change_threshold (relative) and change_frames: zoom detection, see the module docstring.
        refine: refine over the agreeing frames' object statistics (else their weighted mean).
    """

    def __init__(self, max_frames: int = 30, max_age: float | None = None, noise_bound: float = 0.05,
                 bound_mode: str = "relative", min_frames: int = 1, min_support: int = 30,
                 min_confidence: float = 0.0, change_threshold: float = 0.12, change_frames: int = 3,
                 refine: bool = True):
        if max_frames < 1:
            raise ValueError("max_frames must be >= 1")
        if max_age is not None and not max_age > 0:
            raise ValueError("max_age must be > 0 seconds or None")
        if change_frames < 1:
            raise ValueError("change_frames must be >= 1")
        focal_intervals(np.ones(1), noise_bound, bound_mode)  # validates the bound
        self.max_frames, self.max_age = int(max_frames), max_age
        self.noise_bound, self.bound_mode = float(noise_bound), bound_mode
        self.min_frames, self.min_support = int(min_frames), int(min_support)
        self.min_confidence = float(min_confidence)
        self.change_threshold, self.change_frames = float(change_threshold), int(change_frames)
        self.refine = bool(refine)
        self._frames: deque[_Frame] = deque()
        self.current = WindowEstimate(None, reason="no frames yet")
        self.changes = 0

    def __len__(self) -> int:
        return len(self._frames)

    def reset(self) -> None:
        """Forget every frame (e.g. after a known lens change or a looped bag)."""
        self._frames.clear()
        self.current = WindowEstimate(None, reason="window reset")

    def add(self, estimate: FocalEstimate, stamp: float) -> WindowEstimate:
        """Add one frame's estimate taken at ``stamp`` (seconds) and return the new window estimate."""
        self._frames.append(_Frame(float(stamp), estimate.focal, int(estimate.inlier_count), estimate.stats))
        while len(self._frames) > self.max_frames:
            self._frames.popleft()
        if self.max_age is not None:
            while self._frames and stamp - self._frames[0].stamp > self.max_age:
                self._frames.popleft()
        changed = self._detect_change()
        self.current = self._estimate()
        self.current.changed = changed
        return self.current

    def _detect_change(self) -> bool:
        """True (and the older frames dropped) when the last ``change_frames`` frames moved away.

        The test: all of them on one side of the window estimate and their mean log deviation
        beyond max(log(1 + change_threshold), 4 sigma / sqrt(k)), sigma being the robust spread
        of the frames before them (about 1e-4 false alarms per frame for Gaussian errors)."""
        prev = self.current.focal
        k = self.change_frames
        frames = list(self._frames)
        recent = [f.focal for f in frames[-k:]]
        # The frames before them must be at least as many: a baseline, and no second alarm
        # while the window refills after a change.
        if prev is None or len(frames) < 2 * k or any(f is None for f in recent):
            return False
        dev = np.log(np.asarray(recent) / prev)
        spread = _robust_spread([f.focal for f in frames[:-k] if f.focal is not None]) or 0.0
        thr = max(np.log1p(self.change_threshold), 4.0 * spread / np.sqrt(k))
        if not (np.all(dev > 0) or np.all(dev < 0)) or abs(dev.mean()) <= thr:
            return False
        # Keep the trailing run of frames that each moved by more than half the threshold: the
        # oldest of the k may still show the old focal length.
        keep = 0
        for d in dev[::-1]:
            if abs(d) <= thr / 2:
                break
            keep += 1
        for _ in range(len(frames) - max(keep, 1)):
            self._frames.popleft()
        self.changes += 1
        return True

    def _estimate(self) -> WindowEstimate:
        frames = list(self._frames)
        n = len(frames)
        if n < self.min_frames:
            return WindowEstimate(None, frames=n, reason=f"{n} of {self.min_frames} frames")
        rated = [f for f in frames if f.focal is not None]
        if not rated:
            return WindowEstimate(None, frames=n, reason="no frame with focal evidence in the window")
        focals = np.array([f.focal for f in rated])
        weights = np.array([max(f.support, 1) for f in rated], dtype=np.float64)
        lo, hi, back = focal_intervals(focals, self.noise_bound, self.bound_mode)
        st = interval_stabbing(lo, hi, weights)
        agree = [f for f, ok in zip(rated, st.inliers) if ok]
        support = int(sum(f.support for f in agree))
        confidence = float(st.count / (weights.sum() + sum(1.0 for f in frames if f.focal is None)))
        if support < self.min_support or confidence < self.min_confidence:
            return WindowEstimate(None, support, confidence, frames=n,
                                  reason=f"too little consensus: {support} agreeing votes, confidence {confidence:.2f}")
        w_in = weights[st.inliers]
        f0 = float(np.exp(np.sum(w_in * np.log(focals[st.inliers])) / w_in.sum()))
        focal, std = f0, None
        if self.refine:
            stats = ObjectStats.concatenate([f.stats for f in agree])
            if len(stats):
                band = np.log1p(self.noise_bound if self.bound_mode == "relative" else self.noise_bound / f0)
                f1, std = refine_focal(stats, f0, search=float(2 * band), grid=7, tol=1e-6)
                if f1 is not None:
                    focal = f1
        spread = _robust_spread([f.focal for f in rated])
        return WindowEstimate(focal, support, confidence, spread, std, n)


def _robust_spread(focals) -> float | None:
    """1.4826 * MAD of log focal: a relative standard deviation robust to outlying frames."""
    if len(focals) < 2:
        return None
    lf = np.log(np.asarray(focals, dtype=np.float64))
    return float(1.4826 * np.median(np.abs(lf - np.median(lf))))
