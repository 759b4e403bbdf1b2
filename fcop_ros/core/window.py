"""Sliding window of focal evidence over recent frames, with zoom (focal change) detection.

Each frame contributes its estimate y_t = log f_t and its variance v_t = std_rel_t^2. The
window's estimate weights every frame by 1 / v_t. Its uncertainty separates what the frames
share from what varies between them: the spread s^2 of the frames about the window estimate is
error that averaging removes (transient, T = min(s^2 + one standard error, mean v)); the rest of a frame's stated
variance, P = mean v - T, is error every frame repeats (the same objects with the same shape
mismatch) and averaging cannot remove. So V = P + T / n: frames that disagree as much as their
uncertainty says make the window n times surer; frames that agree far more closely than it
says reveal persistent error and the window stays as unsure as one frame.

When the frames disagree more than their stated variances, their spread is the frame variance
instead; and errors that drift slowly between frames (lag-one autocorrelation rho) average out
over n (1 - rho) / (1 + rho) frames, not n.

A zoom is a change point: for every split of the window into older and newer frames (at least
``change_frames`` newer), the difference of the two medians is compared with its standard error
from the transient spread (persistent error cancels in the difference). When the largest
difference exceeds both ``change_sigma`` standard errors and ``change_threshold`` (relative),
the older frames are dropped. A change of image size starts a new window.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from .estimator import FocalEstimate
from .robust import MAD_TO_SIGMA



@dataclass
class WindowEstimate:
    """The window's current estimate.

    focal: pixels, or None without enough evidence (``reason`` says why). std_rel: relative
    standard error of focal (see the module docstring). support: triplet votes agreeing in the
    window's frames; frames: frames in the window (with or without a focal); used: frames that
    made the estimate; changed: True when this update detected a focal change (or a new image
    size) and restarted the window.
    """

    focal: float | None
    std_rel: float | None = None
    support: int = 0
    frames: int = 0
    used: int = 0
    changed: bool = False
    reason: str = ""


@dataclass
class _Frame:
    stamp: float
    logf: float | None
    var: float
    support: int
    size: tuple | None


class FocalWindow:
    """Accumulates :class:`FocalEstimate` s of successive frames into a stable focal length.

    Args:
        max_frames: frames kept (the window length); max_age: seconds kept (None: no limit).
        min_frames, min_support: evidence needed before a focal is reported (frames with a
            focal; agreeing triplet votes over the window).
        change_threshold (relative), change_sigma and change_frames: zoom detection, see the
            module docstring.
        reject_sigma: frames further than this many standard deviations from the others are
            left out of the estimate (a frame whose objects were all wrong).
    """

    def __init__(self, max_frames: int = 30, max_age: float | None = None, min_frames: int = 1,
                 min_support: int = 30, change_threshold: float = 0.08, change_sigma: float = 5.0,
                 change_frames: int = 3, reject_sigma: float = 4.0):
        if max_frames < 1:
            raise ValueError("max_frames must be >= 1")
        if max_age is not None and not max_age > 0:
            raise ValueError("max_age must be > 0 seconds or None")
        if change_frames < 1:
            raise ValueError("change_frames must be >= 1")
        if not change_threshold > 0 or not change_sigma > 0 or not reject_sigma > 0:
            raise ValueError("change_threshold, change_sigma and reject_sigma must be > 0")
        self.max_frames, self.max_age = int(max_frames), max_age
        self.min_frames, self.min_support = int(min_frames), int(min_support)
        self.change_threshold, self.change_sigma = float(change_threshold), float(change_sigma)
        self.change_frames, self.reject_sigma = int(change_frames), float(reject_sigma)
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
        size = tuple(estimate.image_size) if estimate.image_size else None
        new_size = bool(self._frames) and size is not None and self._frames[-1].size not in (None, size)
        if new_size:
            self._frames.clear()
        ok = estimate.focal is not None and estimate.std_rel is not None and estimate.std_rel > 0
        self._frames.append(_Frame(float(stamp), float(np.log(estimate.focal)) if ok else None,
                                   float(estimate.std_rel) ** 2 if ok else np.inf,
                                   int(estimate.inlier_count), size))
        while len(self._frames) > self.max_frames:
            self._frames.popleft()
        if self.max_age is not None:
            while self._frames and stamp - self._frames[0].stamp > self.max_age:
                self._frames.popleft()
        changed = self._detect_change() or new_size
        self.current = self._estimate()
        self.current.changed = changed
        return self.current

    def _rated(self):
        rated = [f for f in self._frames if f.logf is not None]
        return rated, np.array([f.logf for f in rated]), np.array([f.var for f in rated])

    def _detect_change(self) -> bool:
        """True (and the older frames dropped) when the newer frames moved away from the older."""
        rated, y, v = self._rated()
        k = self.change_frames
        n = y.size
        if n < 2 * k:
            return False
        # Transient spread: from successive differences (a single step barely moves their median)
        # and from the spread about the median (slowly drifting errors, which successive
        # differences miss; a step in a minority of frames barely moves it), the larger.
        t = max((MAD_TO_SIGMA * np.median(np.abs(np.diff(y)))) ** 2 / 2.0,
                (MAD_TO_SIGMA * np.median(np.abs(y - np.median(y)))) ** 2, 1e-6)
        # Medians of the older and newer frames (a lone wild frame moves neither), their standard
        # errors sqrt(pi / 2) times those of means.
        cut = np.arange(k, n - k + 1)  # the first newer frame
        old = np.array([np.median(y[:c]) for c in cut])
        new = np.array([np.median(y[c:]) for c in cut])
        diff = new - old
        # Slowly drifting errors make neighbouring frames alike: each segment holds fewer
        # independent frames (lag-one autocorrelation of the older half, before a recent step).
        r = y[: n // 2] - np.median(y[: n // 2])
        rho = _lag_one(r) if r.size > 3 else 0.0
        t *= (1.0 + rho) / (1.0 - rho)
        z = np.abs(diff) / np.sqrt(np.pi / 2 * (t / cut + t / (n - cut)))
        hit = (z > self.change_sigma) & (np.abs(diff) > np.log1p(self.change_threshold))
        if not hit.any():
            return False
        first = rated[int(cut[np.flatnonzero(hit)[np.argmax(z[hit])]])]
        while self._frames[0] is not first:
            self._frames.popleft()
        self.changes += 1
        return True

    def _estimate(self) -> WindowEstimate:
        frames = list(self._frames)
        rated, y, v = self._rated()
        n_all = len(frames)
        support = int(sum(f.support for f in rated))
        if y.size < self.min_frames:
            return WindowEstimate(None, frames=n_all, support=support,
                                  reason=f"{y.size} of {self.min_frames} frames with focal evidence")
        if support < self.min_support:
            return WindowEstimate(None, frames=n_all, support=support,
                                  reason=f"too little evidence: {support} agreeing votes")
        keep = np.ones(y.size, dtype=bool)
        if y.size >= 3:
            med = np.median(y)
            keep = np.abs(y - med) <= self.reject_sigma * np.sqrt(v)
            if not keep.any():
                keep[:] = True
        y, v = y[keep], v[keep]
        w = 1.0 / v
        mean = float(np.sum(w * y) / w.sum())
        n = y.size
        var = 1.0 / w.sum()  # independent frames that are as uncertain as they say
        if n >= 3:
            r = y - mean
            # Dispersion: 1 when the frames disagree as much as their std_rel say. Above it, their
            # spread is the truth (variances scaled up); clearly below it (beyond one standard
            # error), the frames share error that no averaging removes (the persistent part).
            phi = float(np.sum(w * r * r) / (n - 1))
            v_frame = n * var  # the harmonic mean of the frames' variances
            # The shared part, judged against a typical frame (the median: one very unsure frame
            # must not inflate it, nor the most confident frames shrink it).
            persistent = max(1.0 - phi - np.sqrt(2.0 / (n - 1)), 0.0) * float(np.median(v))
            # Errors that drift slowly from frame to frame average out over fewer frames.
            rho = _lag_one(r)
            n_eff = max(n * (1.0 - rho) / (1.0 + rho), 1.0)
            var = persistent + max(max(phi, 1.0) * v_frame - persistent, 0.0) / n_eff
        return WindowEstimate(float(np.exp(mean)), float(np.sqrt(var)), support, n_all, n)


def _lag_one(r: np.ndarray) -> float:
    """Lag-one autocorrelation of residuals r, corrected for its small-sample bias
    (E[rho_hat] ~ rho - (1 + 3 rho) / n, Kendall), clipped to [0, 0.95]."""
    n = r.size
    rho = float(np.sum(r[1:] * r[:-1]) / max(np.sum(r * r), 1e-300))
    return float(np.clip((n * rho + 1.0) / max(n - 3.0, 1.0), 0.0, 0.95))
