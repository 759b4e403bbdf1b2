"""Sliding window of focal evidence over recent frames, with zoom (focal change) detection.

Each frame contributes its estimate y_t = log f_t, its variance v_t = std_rel_t^2 and the part
of it that pixel noise makes, n_t = std_rel_noise_t^2 (a new frame draws it anew). The rest,
v_t - n_t, is the frame's systematic error budget (shape mismatch, unseen depth error, the
objects' disagreement): it repeats while the same objects are in view, unless the frames show
otherwise. The part the prior between-object spread makes (``std_rel_prior``, which a frame of
one object pays whole) stands for the disagreement other objects would have shown: it counts in
the budget only where fewer than two objects are each in three of the window's kept frames, so
that no disagreement shows (a lone object's error repeated through a tuning orbit: windows
erred +3.5% and -5.8% at a stated 1.4-1.6% with it left out). The window's variance is

    V = max(B - Q, 0) + max(S^2, N) / n_eff

with S^2 the frames' spread about the estimate, N their noise variance, B their systematic
budget (the median of v_t - n_t) and Q = S^2 (1 - sqrt(2 / n_eff)) - N the variation beyond
noise that the spread shows beyond doubt (its one-standard-error lower bound): that much of the
budget varies from frame to frame and averages out; the rest cannot. Errors that drift slowly
(lag-one autocorrelation rho) average out over n_eff = n (1 - rho) / (1 + rho) frames, not n.
A frame without ``std_rel_noise`` counts as all noise. Where two or more objects are each in
three of the window's kept frames, their lasting disagreement shows what of V is theirs: the
lasting part, max(B - Q, 0), beyond the intrinsics' offsets (which all objects share) counts
for two objects, as the prior does in a frame (:mod:`.combine`), against k - 1 for the variance
of the objects' weighted mean that their scatter shows (each object's mean over its frames
weighted by 1 / noise, its squared residual over 1 less its share of the weight). The part that
renews, max(S^2, N) / n_eff, stays whole: a frame's objects may share an error drawn anew in
every frame, which their disagreement cannot show. The frames' budget is sized for the variance
on average; the objects' scatter ranks windows (on 40 tuning `predicted` sequences the windows'
median std_rel went from 8.1% to 5.7%, and of the updates a max_uncertainty of 0.05 lets
through, those beyond 5% error from 19.6% to 12.6%, at 297ab7f; with the renewing part whole,
6.1% and 13.7%, replayed: docs/BENCHMARKS.md).

The newest frame's disagreement with the estimate beyond its own variance (its prior part
included) is added to V: a zoom shows first in the newest frame, before enough frames can tell
it from an error, and until then the window's focal may be the old one (on 48 development zoom
sequences of each preset, the window covered the truth after 80-96% of `predicted` and 88-95%
of `sensor` updates after the zoom without this, 86-100% and 93-100% with it; static windows'
coverage did not move by more than one point).

The estimate weights every frame by 1 / n_t, the information its pixels carry, as the frame
weighs its objects (:mod:`.combine`): the systematic budget is sized for the variance on
average and does not tell frames apart (weights that counted its varying share left the window
further from the truth, docs/BENCHMARKS.md). V is taken about this estimate, with its weights.

Frames further than ``reject_sigma`` robust standard deviations of the frames' own spread (at
least their noise) from the median are left out: a frame whose objects were all wrong.

A zoom is a change point: at the likeliest split of the window into older and newer frames (at
least ``change_frames`` on each side), the difference of the two medians (of an even segment,
its middle frame nearer the other segment) is compared with its standard error from the frames'
spread about the two medians, widened for slow drift (persistent error cancels in the
difference), or from what of the frames' own variance does not cancel, where that is larger:
their noise, their prior part (errors that change with the view: a lone object's frames that
erred +9% for three frames at a stated 3%, nearly all of it prior, were a zoom) and one
segment's systematic budget beyond the other's. When it exceeds both
``change_sigma`` standard errors and ``change_threshold`` (relative), the older frames are
dropped (or kept at the new focal length, below).

Frames that carry their objects' extents (``FocalEstimate.object_extents``: image radius times
depth, the focal length times the object's size) also give the window an image scale: per
frame, the median over its objects of their log extent less that object's median in the window
(matched by instance id). Pixels and depth alone make it, so the frames' focal errors do not
move it; a zoom moves it by the zoom. The objects' image radii (``object_radii``) make a second
image scale the same way: a zoom moves it as much, a depth network that guesses its scale anew
in every frame does not scatter it (it scatters the first), a camera moving towards the objects
moves it (it leaves the first). A scale judges only where no zoom and that zoom lie four of its
standard errors apart (instance ids that do not follow the objects make it scatter). A step in
the focal lengths stands if a scale that can judge it moved the same way by more than half as
much, or if none can judge it. A step in an image scale (the same test, without a floor) that
the focal lengths follow by more than half, and that the newest frame keeps (by more than half:
a zoom persists, masks grown by a pixel for two frames do not), is a zoom at once. Frames
follow only where their step's standard error (at least their own noise) is below the scale's
step: frames that say they err by 77-26000% follow nothing. The split
then moves, by at most ``change_frames`` of that scale's frames, to where the fewest frames lie
on the side whose image scale they are further from (of the scale that tells the zoom best).
Frames without any of the window's objects' sizes (hand-built estimates, or objects that left
the view) are skipped in a scale: it judges a split with ``change_frames`` frames of its own
after it and at least one before it (frames without sizes leave no more; its standard error
counts how few), and a split it finds starts at its first newer frame with
sizes (newer frames without sizes before it go with the older frames).

Where the zoom is measured, the older frames are kept instead, at the new focal length. The
objects' image radii measure it, from the ``change_frames`` frames on either side of the split
(pixels alone; an orbit moves them little that close), where their extents measure the same
step (a camera that moved at the same time moves the radii, not the extents) and it lies four
standard errors from none; where the focal lengths' own step agrees with it (within two
standard errors of their difference: else the frames' errors moved with the view, and the
older frames do not tell the new view's), the two are pooled by their variances. The older
frames' focal lengths and sizes move by the zoom, their systematic budget grows by its
variance, and the part of their budget beyond the newer frames' counts as their noise: it
belongs to the view before the zoom, and they weigh less by it. On 48 development zoom
sequences of the tuning world (x1.25 and x0.8), 39 rather than 36 were within 5% for good in
15 frames (bench/zoom_carry.py, docs/BENCHMARKS.md).

Frames that assume intrinsics (the principal point at the image centre, a lens without
distortion) carry what their objects say of the offsets (``FocalEstimate.intrinsics_evidence``:
dx, dy, k1): each frame corrected its focal length by its own offsets, which its few objects
fix loosely and its prior shrinks towards none. The window pools the frames' evidence
(:func:`~.offsets.pooled_offset`: the objects' errors that renew add up over frames, the
systematic budget that repeats counts once, and frames that disagree beyond what they claim
count for less), moves each frame's focal length by its gradient times its own offsets less
the pooled ones, and puts the pooled offsets' variance in place of its own in the frame's
systematic budget. A lens is the same in every frame, so only this pooling lets a window
average it away (on 40 tuning `sensor` sequences the window's error went from 1.03x to
0.48x the frames' when it did, docs/BENCHMARKS.md).

A change of image size starts a new window. The settings are a :class:`WindowOptions`.
"""

from __future__ import annotations

import numbers
from collections import Counter, deque
from dataclasses import dataclass, field, replace

import numpy as np

from .camera import is_number
from .estimator import FocalEstimate
from .options import WindowOptions
from .offsets import IntrinsicsEvidence, pooled_offset
from .robust import MAD_TO_SIGMA


@dataclass
class WindowEstimate:
    """The window's current estimate.

    focal: pixels, or None without enough evidence (``reason`` says why). std_rel: relative
    standard error of focal (see the module docstring). support: triplet votes agreeing in the
    window's frames; frames: frames in the window (with or without a focal); used: frames that
    made the estimate; changed: True when this update detected a focal change (or a new image
    size); zoom: on such an update, the ratio of the focal lengths that the objects' image radii
    measured, by which the window kept its older frames (None when it dropped them).
    """

    focal: float | None
    std_rel: float | None = None
    support: int = 0
    frames: int = 0
    used: int = 0
    changed: bool = False
    reason: str = ""
    zoom: float | None = None


#: The reason of a window that has taken no frame since it was made.
NO_FRAMES_YET = "no frames yet"


@dataclass
class _Frame:
    stamp: float
    logf: float | None
    var: float
    noise: float
    prior: float
    support: int
    size: tuple | None
    extents: dict
    radii: dict
    unweighed: bool = False  # a focal without std_rel
    intrinsics: IntrinsicsEvidence | None = None
    objects: dict = field(default_factory=dict)  # {instance_id: (log focal, noise variance)}


class FocalWindow:
    """Accumulates :class:`FocalEstimate` s of successive frames into a stable focal length,
    as its :class:`WindowOptions` say (default: fcop_ros's settings)."""

    def __init__(self, options: WindowOptions | None = None):
        self.options = WindowOptions() if options is None else options
        if not isinstance(self.options, WindowOptions):
            raise TypeError("FocalWindow takes a WindowOptions, e.g. "
                            "FocalWindow(WindowOptions(max_frames=30))")
        self._frames: deque[_Frame] = deque()
        self.current = WindowEstimate(None, reason=NO_FRAMES_YET)
        self.changes = 0

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def rated(self) -> int:
        """Frames in the window with a focal length (the others are kept only as frames)."""
        return sum(f.logf is not None for f in self._frames)

    def reset(self) -> None:
        """Forget every frame (e.g. after a known lens change or a looped bag)."""
        self._frames.clear()
        self.current = WindowEstimate(None, reason="window reset")

    def add(self, estimate: FocalEstimate, stamp: float) -> WindowEstimate:
        """Add one frame's estimate taken at ``stamp`` (seconds); return the window's estimate.

        A frame of another image size starts a new window if it has a focal length; one
        without is not added (one bad frame does not end a window), as in ``fcop_node``.
        Stamps must be finite and must not go back (``reset()`` after a time jump): a raise
        otherwise, since ``max_age`` and the order of the frames rest on them. An estimate
        without ``std_rel`` (``method="ransac"``, ``refine=False``, the paper's method) is
        kept as a frame without evidence: the window weighs frames by it."""
        if isinstance(stamp, bool) or not isinstance(stamp, numbers.Real):
            raise TypeError(f"stamp must be a number of seconds, got {stamp!r}")
        stamp = float(stamp)
        if not np.isfinite(stamp):
            raise ValueError(f"stamp must be finite, got {stamp}")
        if self._frames and stamp < self._frames[-1].stamp:
            raise ValueError(
                f"stamp {stamp} is before the newest frame's ({self._frames[-1].stamp}); "
                "call reset() after a jump back in time"
            )
        if not isinstance(estimate, FocalEstimate):
            raise TypeError(f"estimate must be a FocalEstimate (estimate_focal's result, with "
                            f"focal None when it gave none), got {estimate!r}")
        for name in ("focal", "std_rel"):
            value = getattr(estimate, name)
            if value is not None and not is_number(value):
                raise TypeError(f"the estimate's {name} must be a number or None, got {value!r}")
        if estimate.focal is not None and not (np.isfinite(estimate.focal) and estimate.focal > 0):
            raise ValueError(f"the estimate's focal must be finite and > 0, or None; got "
                             f"{estimate.focal!r}")
        if estimate.std_rel is not None and estimate.std_rel < 0:
            raise ValueError(f"the estimate's std_rel must be >= 0 or None, got "
                             f"{estimate.std_rel!r}")
        size = tuple(estimate.image_size) if estimate.image_size else None
        new_size = (
            bool(self._frames) and size is not None and self._frames[-1].size not in (None, size)
        )
        if new_size and estimate.focal is None and self.rated:
            return replace(self.current, changed=False)
        if new_size:
            self._frames.clear()
        with np.errstate(over="ignore", invalid="ignore"):
            var = np.float64(estimate.std_rel or 0.0) ** 2
        # A frame whose std_rel is 0, infinite or NaN weighs nothing: it is kept without evidence.
        ok = estimate.focal is not None and bool(np.isfinite(var) and var > 0)
        var = float(var) if ok else np.inf
        noise = estimate.std_rel_noise
        noise = min(float(noise) ** 2, var) if ok and noise is not None and noise > 0 else var
        prior = estimate.std_rel_prior
        prior = min(float(prior) ** 2, var - noise) if ok and prior else 0.0
        self._frames.append(
            _Frame(
                float(stamp),
                float(np.log(estimate.focal)) if ok else None,
                var,
                noise,
                prior,
                int(estimate.inlier_count),
                size,
                _log_sizes(estimate.object_extents) if ok else {},
                _log_sizes(estimate.object_radii) if ok else {},
                estimate.focal is not None and not ok,
                estimate.intrinsics_evidence if ok else None,
                _object_evidence(estimate.object_focals) if ok else {},
            )
        )
        while len(self._frames) > self.options.max_frames:
            self._frames.popleft()
        if self.options.max_age is not None:
            while self._frames and stamp - self._frames[0].stamp > self.options.max_age:
                self._frames.popleft()
        rated = self._rated()
        changed, zoom = self._detect_change(rated)
        # A change dropped the older frames or moved them: the window's frames are rated anew.
        self.current = self._estimate(self._rated() if changed else rated)
        self.current.changed = changed or new_size
        self.current.zoom = zoom
        return self.current

    def _rated(self):
        """(the frames with a focal length, their log focal lengths, variances less the prior
        part, noise variances and the pooled offsets' variance), the intrinsics' pooled
        offsets applied."""
        rated = [f for f in self._frames if f.logf is not None]
        y = np.array([f.logf for f in rated])
        v = np.array([f.var - f.prior for f in rated])
        noise = np.array([f.noise for f in rated])
        common = np.zeros(y.size)
        # The intrinsics' offsets, told by all frames together (see the module docstring):
        # each frame's focal length moves from its own offsets to the pooled ones, and its
        # variance of the offsets becomes the pooled offsets'.
        std = next((f.intrinsics.prior_std for f in reversed(rated)
                    if f.intrinsics is not None), None)
        at = [r for r, f in enumerate(rated) if f.intrinsics is not None
              and np.array_equal(f.intrinsics.prior_std, std)]
        if at:
            evidence = [rated[r].intrinsics for r in at]
            delta, cov = pooled_offset(evidence)
            g = np.array([e.gradient for e in evidence])
            own = np.array([e.offset for e in evidence])
            own_cov = np.array([e.covariance for e in evidence])
            y[at] += np.einsum("ni,ni->n", g, own - delta)
            v[at] = np.maximum(v[at] + np.einsum("ni,nij,nj->n", g, cov - own_cov, g), noise[at])
            common[at] = np.minimum(np.einsum("ni,ij,nj->n", g, cov, g), v[at] - noise[at])
        return rated, y, v, noise, common

    def _detect_change(self, rated) -> tuple[bool, float | None]:
        """(True, None) with the older frames dropped, or (True, the zoom) with them carried
        through it, when the newer frames moved away from the older and, where the frames carry
        their objects' extents, the image scale moved with them; (False, None) otherwise.
        ``rated``: :meth:`_rated` of the window's frames."""
        rated, y, v, noise, _ = rated
        k = self.options.change_frames
        n = y.size
        if n < 2 * k:
            return False, None
        sigma, least = self.options.change_sigma, np.log1p(self.options.change_threshold)

        prior = np.array([f.prior for f in rated])

        def floor(c):
            # A few frames that err as much as they say they may are no step. The systematic
            # budget both segments share (the same objects in the same scene) cancels in their
            # difference; their noise, their prior part (errors that change with the view, so
            # the two segments' differ) and one segment's budget beyond the other's do not.
            b_old, b_new = np.median(v[:c] - noise[:c]), np.median(v[c:] - noise[c:])
            return (float(np.median(noise[:c]) + np.median(prior[:c]) + max(b_old - b_new, 0.0)),
                    float(np.median(noise[c:]) + np.median(prior[c:]) + max(b_new - b_old, 0.0)))

        # The image scale, from the objects' extents and from their image radii alone: a zoom
        # moves both; a depth network whose scale changes from frame to frame scatters the
        # first, a camera that moves towards the objects moves the second.
        tracks = [t for t in (_scale_track(rated, "extents"), _scale_track(rated, "radii"))
                  if t is not None and t[0].size >= 2 * k]

        def judged(at, c):
            # The scale's split for the frames' split c, where change_frames frames with a
            # scale lie after it and one at least before it (frames without one, e.g. all
            # objects out of view, are skipped; older ones never come back, and
            # the standard error counts how few there are).
            cs = int(np.searchsorted(at, c))
            return cs if 1 <= cs <= at.size - k else None

        def stands(c, step):
            # Whether the scales let a step of the focal lengths at c stand: yes when one that
            # can tell a zoom of ``step`` from none moved with it by more than half (a zoom
            # moves both scales, but a camera moving at the same time moves the radii's too),
            # no when all that can tell did not, yes when none can tell.
            votes = set()
            for scale, at in tracks:
                cs = judged(at, c)
                if cs is not None and _telling(scale, cs, step):
                    votes.add(_agrees(_difference(scale, cs), step))
            return True in votes or not votes

        hit = None
        # No step exceeds the series' range: a window whose frames all lie within
        # change_threshold of each other needs no split search.
        c, step, z = _step(y, k, floor) if np.ptp(y) > least else (k, 0.0, 0.0)
        if z > sigma and abs(step) > least and stands(c, step):
            # A zoom moves the image scale by as much as the focal length; frames whose errors
            # moved (a new view of the objects) leave it where it was. Judged only where a
            # scale can tell the two apart (instance ids that do not follow the objects make
            # it scatter).
            hit = c
        for scale, at in tracks if hit is None else ():
            # The image scale is told by pixels (and depth) alone, however the frames err: a
            # step in it that the frames' focal lengths follow, and that its newest frame
            # keeps, is a zoom, seen at once. The newer side starts at its first frame with a
            # scale.
            if np.ptp(scale) > least:
                cs, moved, z = _step(scale, k, None)
                c = int(at[cs])
                if (z > sigma and abs(moved) > least and _agrees(_difference(y, c), moved)
                        and _standard_error(y, c, floor) < abs(moved)
                        and _agrees(scale[-1] - np.median(scale[:cs]), moved)):
                    hit = c
                    break
        if hit is None:
            return False, None
        best = None  # the scale that tells the zoom best places the split
        for scale, at in tracks:
            cs = judged(at, hit)
            if cs is not None and _telling(scale, cs, _difference(scale, cs)):
                se = _standard_error(scale, cs)
                if best is None or se < best[0]:
                    best = (se, scale, at, cs)
        if best is not None:
            _, scale, at, cs = best
            hit = int(at[_split_by_scale(scale, cs, k)])
        self.changes += 1
        first = rated[hit]
        zoom, step = _zoom_step(rated, hit, k), _difference(y, hit)
        se = _standard_error(y, hit, floor)
        if zoom is not None and abs(step - zoom[0]) <= 2.0 * np.hypot(se, zoom[1]):
            # Two measures of one zoom that agree: the radii's, and the focal lengths' own step
            # (precise where the frames are, as with sensor depth), weighed by their variances.
            # Where they disagree, the frames' errors moved with the view: the older frames
            # do not tell the new one's.
            w = np.array([zoom[1], se]) ** -2.0
            excess = float(np.median(v[:hit] - noise[:hit]) - np.median(v[hit:] - noise[hit:]))
            return True, self._carry(first, float(w @ [zoom[0], step] / w.sum()),
                                     float(w.sum() ** -0.5), max(excess, 0.0))
        while self._frames[0] is not first:
            self._frames.popleft()
        return True, None

    def _carry(self, first: _Frame, step: float, se: float, excess: float) -> float:
        """Keep the frames before ``first`` as if seen after the zoom: their focal lengths, their
        objects' and their image sizes moved by ``step`` (log), their variance by its variance
        ``se`` squared, and ``excess`` of their systematic budget (what it exceeds the newer
        frames' by) counted as noise (see the module docstring). Returns the zoom, a ratio."""
        for f in self._frames:
            if f is first:
                break
            if f.logf is not None:
                f.logf += step
                f.var += se * se
                f.noise += min(excess, f.var - f.noise - f.prior)
                f.objects = {i: (y + step, n) for i, (y, n) in f.objects.items()}
            f.extents = {i: v + step for i, v in f.extents.items()}
            f.radii = {i: v + step for i, v in f.radii.items()}
        return float(np.exp(step))

    def _estimate(self, rated) -> WindowEstimate:
        """The window's estimate from ``rated``, :meth:`_rated` of its frames."""
        rated, y, v, noise, common = rated
        n_all = len(self._frames)
        support = int(sum(f.support for f in rated))
        # Taken before the frames far from the median are left out: a newest frame left out
        # is the very one that may show a zoom.
        newest = (y[-1], v[-1] + rated[-1].prior) if y.size else None
        if y.size < self.options.min_frames or y.size == 0:
            why = (f"{y.size} frames with focal evidence (min_frames "
                   f"{self.options.min_frames})")
            unweighed = sum(f.unweighed for f in self._frames)
            if unweighed:
                why += (f"; {unweighed} of its frames have a focal but no usable std_rel (none, "
                        "as method='ransac' and refine=False give, 0 or not finite), which the "
                        "window weighs frames by")
            return WindowEstimate(None, frames=n_all, support=support, reason=why)
        if support < self.options.min_window_votes:
            return WindowEstimate(
                None,
                frames=n_all,
                support=support,
                reason=f"too little evidence: {support} agreeing votes",
            )
        if y.size >= 3:
            med = np.median(y)
            spread = max(
                MAD_TO_SIGMA * np.median(np.abs(y - med)), float(np.sqrt(np.median(noise)))
            )
            keep = np.abs(y - med) <= self.options.reject_sigma * spread
            rated = [f for f, kept in zip(rated, keep) if kept]
            y, v, noise, common = y[keep], v[keep], noise[keep], common[keep]
        n = y.size
        objects = _object_means(rated)
        k = objects[0].size
        if k < 2:
            # Fewer than two objects to disagree: nothing shows what the prior between-object
            # spread stands for.
            v = v + np.array([f.prior for f in rated])
        budget = float(np.median(v - noise))
        noise_var = n / float(np.sum(1.0 / noise))
        w = 1.0 / noise
        mean = float(np.sum(w * y) / w.sum())
        lasting, renewed = budget, noise_var / n  # too few frames to see what varies
        if n >= 3:
            lasting, renewed = self._spread(y, w, mean, budget, noise_var)
        if k >= 2:
            # What the objects' lasting disagreement shows, in place of the lasting budget
            # beyond the intrinsics' offsets (which all objects share, so none disagrees by
            # them). Errors that renew from frame to frame stay: a frame's objects may share
            # them.
            shared = min(float(np.median(common)), lasting)
            lasting = shared + (_PRIOR_OBJECTS * (lasting - shared)
                                + (k - 1) * _disagreement(*objects)) / (_PRIOR_OBJECTS + k - 1)
        var = lasting + renewed
        # The newest rated frame's disagreement beyond its own variance: a change not yet
        # detected.
        var += max((newest[0] - mean) ** 2 - newest[1], 0.0)
        return WindowEstimate(float(np.exp(mean)), float(np.sqrt(var)), support, n_all, n)

    @staticmethod
    def _spread(y, w, mean, budget, noise_var):
        """Variance of the weighted mean of frames y with weights w about ``mean``, as (what
        lasts: the budget less what the spread shows to vary, what renews: the spread over
        the effective frames; see the module docstring)."""
        n = y.size
        r = y - mean
        spread2 = float(np.sum(w * r * r) / (n - 1)) * n / float(w.sum())
        rho = _lag_one(r)
        n_eff = max(n * (1.0 - rho) / (1.0 + rho), 1.0)
        varies = max(spread2 * max(1.0 - np.sqrt(2.0 / n_eff), 0.0) - noise_var, 0.0)
        return max(budget - varies, 0.0), max(spread2, noise_var) / n_eff


#: What the frames' variance counts for against the objects' disagreement, in objects (as
#: ``EstimatorOptions.object_tau_weight`` in a frame).
_PRIOR_OBJECTS = 2.0


def _object_evidence(object_focals: dict) -> dict:
    """{instance_id: (log focal, noise variance)} of a frame's combined objects with a finite,
    positive focal length and noise."""
    out = {}
    for i, (f, _, n) in object_focals.items():
        with np.errstate(over="ignore", invalid="ignore"):
            var = np.float64(n) ** 2 if is_number(n) and n > 0 else np.nan
        # A noise below 1e-12 is none a fit gives; its information would overflow.
        if is_number(f) and np.isfinite(f) and f > 0 and 1e-24 <= var < np.inf:
            out[i] = (float(np.log(f)), float(var))
    return out


def _object_means(frames) -> tuple[np.ndarray, np.ndarray]:
    """(log focal, information) per object seen in at least three of ``frames``: its focal
    lengths' mean over them weighted by their information 1 / noise, and that information's
    sum."""
    seen = {}
    for f in frames:
        for i, (y, n) in f.objects.items():
            seen.setdefault(i, []).append((y, 1.0 / n))
    tracks = [np.array(t) for t in seen.values() if len(t) >= 3]
    info = np.array([t[:, 1].sum() for t in tracks])
    # _object_evidence keeps noise variances of 1e-24 and more: info is finite and > 0.
    means = np.array([t[:, 0] @ t[:, 1] for t in tracks]) / info
    return means, info


def _disagreement(means: np.ndarray, info: np.ndarray) -> float:
    """Variance of the objects' information-weighted mean from their own scatter about it:
    each object's squared residual stands for its variance, over 1 less its share of the
    weight (it pulls the mean towards itself). An object that carries nearly all the weight
    shows little of its own error: the frames' budget, mixed in, speaks for it."""
    share = info / info.sum()
    r = means - share @ means
    return float(np.sum(share**2 * r**2 / np.maximum(1.0 - share, 1e-12)))


def _log_sizes(sizes: dict) -> dict:
    """{instance_id: log size} of the positive, finite sizes (extents or radii)."""
    return {i: float(np.log(e)) for i, e in sizes.items() if np.isfinite(e) and e > 0}


def _size_matrix(rated, attr: str) -> tuple[np.ndarray, np.ndarray] | None:
    """Log sizes (``attr``: the frames' ``extents`` or ``radii``) of the frames' objects,
    (frames with any, objects) with NaN where a frame lacks one, and those frames' indices in
    ``rated``. Objects are matched by instance id and kept if seen in at least half the frames
    that carry sizes; frames with none of them are left out. None without any."""
    carry = [getattr(f, attr) for f in rated]
    seen = Counter(i for x in carry for i in x)
    ids = sorted(i for i, m in seen.items() if 2 * m >= sum(1 for x in carry if x))
    at = np.array([r for r, x in enumerate(carry) if any(i in x for i in ids)], dtype=int)
    if not at.size:
        return None
    col = {i: j for j, i in enumerate(ids)}
    e = np.full((at.size, len(ids)), np.nan)
    for row, r in enumerate(at):
        for i, value in carry[r].items():
            if i in col:
                e[row, col[i]] = value
    return e, at


def _scale_track(rated, attr: str) -> tuple[np.ndarray, np.ndarray] | None:
    """The frames' image scale against the window's, in log, from their objects' ``attr``
    (``extents`` or ``radii``), and the indices in ``rated`` of the frames it has: per frame,
    the median over its objects of their log size less that object's median over the window.
    None without sizes."""
    m = _size_matrix(rated, attr)
    if m is None:
        return None
    e, at = m
    return _nanmedian(e - _nanmedian(e, 0)[None, :], 1), at


def _nanmedian(a: np.ndarray, axis: int) -> np.ndarray:
    """``np.nanmedian(a, axis)`` of a 2-D array, to the bit, by one sort (NaN sort last): numpy's
    goes through masked arrays at many times the cost. NaN where a line has no finite value."""
    s = np.sort(a, axis=axis)
    n = np.sum(~np.isnan(a), axis=axis)
    lo = np.take_along_axis(s, np.expand_dims(np.maximum(n - 1, 0) // 2, axis), axis)
    hi = np.take_along_axis(s, np.expand_dims(n // 2, axis), axis)
    return np.where(n > 0, (lo + hi).squeeze(axis) / 2.0, np.nan)


def _step(y: np.ndarray, k: int, floor):
    """The likeliest split of series y into older and newer values (at least k on each side):
    (first newer index, signed step, step in standard errors, see :func:`_standard_error`)."""
    n = y.size
    # Medians of the older and newer values for every split (a lone wild value moves neither);
    # the most likely split is the one whose difference stands out most. An even segment's
    # median is taken as whichever middle value lies nearer the other segment: a step needs
    # most of a segment's values, not two wild ones among four.
    cut = np.arange(k, n - k + 1)  # the first newer index
    # All splits sorted at once is quicker for a window of the usual size; its cost grows as
    # n^2 log n (the node allows 1000 frames), split by split as n log n per split.
    diff = (_differences(y, cut) if n <= 256
            else np.array([_difference(y, int(c)) for c in cut]))
    best = int(np.argmax(np.abs(diff) * np.sqrt(cut * (n - cut))))
    c = int(cut[best])
    return c, float(diff[best]), float(abs(diff[best]) / _standard_error(y, c, floor))


def _standard_error(y: np.ndarray, c: int, floor=None) -> float:
    """Standard error of the step of y at split c, from y's spread about the two segments'
    medians, at least ``floor(c)`` (older, newer) per value when a floor is given."""
    n = y.size
    old, new = np.mean(_middle(y[:c])), np.mean(_middle(y[c:]))
    # The transient spread about the two segments' medians (a step must not count as spread),
    # and from successive differences, the larger. Slowly drifting errors make neighbouring
    # values alike: each segment holds fewer independent values (lag-one autocorrelation of
    # those residuals). The medians' standard errors are sqrt(pi / 2) times those of means.
    r = y - np.where(np.arange(n) < c, old, new)
    t = max(
        (MAD_TO_SIGMA * np.median(np.abs(np.diff(y)))) ** 2 / 2.0,
        (MAD_TO_SIGMA * np.median(np.abs(r))) ** 2,
        1e-6,
    )
    rho = _lag_one(r) if n > 3 else 0.0
    t *= (1.0 + rho) / (1.0 - rho)
    t_old, t_new = (max(t, f) for f in floor(c)) if floor is not None else (t, t)
    return float(np.sqrt(np.pi / 2 * (t_old / c + t_new / (n - c))))


def _zoom_step(rated, c: int, k: int) -> tuple[float, float] | None:
    """The zoom at split c, (log step, standard error), as the objects' image radii measure it
    (see :func:`_size_step`; pixels alone, no depth error), where their extents (radius times
    depth) measure the same step: a camera that moved at the same time moves the radii but
    not the extents. None where the two differ by more than two standard errors of their
    difference, or either cannot tell the step from no zoom."""
    radii, extents = _size_step(rated, c, k, "radii"), _size_step(rated, c, k, "extents")
    if radii is None or extents is None:
        return None
    return radii if abs(radii[0] - extents[0]) <= 2.0 * np.hypot(radii[1], extents[1]) else None


def _size_step(rated, c: int, k: int, attr: str) -> tuple[float, float] | None:
    """The step at split c of the objects' log sizes (``attr``: ``radii`` or ``extents``), from
    the k frames on either side (an orbit or a drift moves them little that close): per object
    seen on both sides the difference of its medians, their median over the objects, and its
    standard error, from the frames' scatter about their segments and the objects'
    disagreement, the larger. None without an object on both sides, or where the step does
    not lie four standard errors from no zoom."""
    old = [getattr(f, attr) for f in rated[max(0, c - k):c]]
    new = [getattr(f, attr) for f in rated[c:c + k]]
    ids = sorted(set().union(*old) & set().union(*new))
    if not ids:
        return None
    d, jumps, terms = [], [], []
    for i in ids:
        a = np.array([x[i] for x in old if i in x])
        b = np.array([x[i] for x in new if i in x])
        d.append(np.median(b) - np.median(a))
        jumps.extend(np.abs(np.diff(a)))
        jumps.extend(np.abs(np.diff(b)))
        terms.append(1.0 / a.size + 1.0 / b.size)
    d = np.array(d)
    step = float(np.median(d))
    # One frame's scatter from successive differences (a drift counts little), per object
    # step; the objects' disagreement, robustly from three on.
    scatter = (MAD_TO_SIGMA * float(np.median(jumps))) ** 2 / 2.0 * float(np.mean(terms)) \
        if jumps else 0.0
    disagree = (0.0 if d.size < 2 else float(np.var(d, ddof=1)) if d.size == 2
                else (MAD_TO_SIGMA * float(np.median(np.abs(d - step)))) ** 2)
    se = float(np.sqrt(np.pi / 2 * max(scatter, disagree, 1e-6) / d.size))
    return (step, se) if se < abs(step) / 4.0 else None


def _telling(scale: np.ndarray, c: int, step: float) -> bool:
    """True when the image scale at split c tells no zoom from a zoom of ``step``: the two lie
    at least four of its standard errors apart, so the midpoint between them errs in few
    cases either way."""
    return _standard_error(scale, c) < abs(step) / 4.0


def _difference(y: np.ndarray, c: int) -> float:
    """The step of y at split c: its newer median less its older (of an even segment, the
    middle value nearer the other segment)."""
    old, new = _middle(y[:c]), _middle(y[c:])
    return max(new[0] - old[1], 0.0) - max(old[0] - new[1], 0.0)


def _differences(y: np.ndarray, cut: np.ndarray) -> np.ndarray:
    """:func:`_difference` of y at every split in ``cut``, to the bit: each split's older and
    newer values sorted at once, padded with +inf."""
    n = y.size
    j = np.arange(n)
    older = np.sort(np.where(j < cut[:, None], y, np.inf), axis=1)
    newer = np.sort(np.where(j >= cut[:, None], y, np.inf), axis=1)
    rows, m = np.arange(cut.size), n - cut
    old_lo, old_hi = older[rows, (cut - 1) // 2], older[rows, cut // 2]
    new_lo, new_hi = newer[rows, (m - 1) // 2], newer[rows, m // 2]
    return np.maximum(new_lo - old_hi, 0.0) - np.maximum(old_lo - new_hi, 0.0)


def _agrees(other: float, step: float) -> bool:
    """True when ``other`` moved the way ``step`` did by more than half as much: nearer a zoom
    of that size than no zoom at all."""
    return other * np.sign(step) > abs(step) / 2.0


def _split_by_scale(scale: np.ndarray, c: int, k: int) -> int:
    """The split within k frames of c that leaves the fewest frames on the side whose image
    scale they are further from (the nearest to c among equals): a median-based split may
    leave an older frame on the newer side, and a clean scale says which, while one wild
    frame cannot move the split far."""
    n = scale.size
    old, new = np.median(scale[:c]), np.median(scale[c:])
    newer = (np.abs(scale - new) < np.abs(scale - old)).astype(int)
    cuts = np.arange(max(1, c - k), min(n - 1, c + k) + 1)
    before = np.concatenate([[0], np.cumsum(newer)])  # newer-looking frames before each cut
    wrong = before[cuts] + (n - cuts) - (before[n] - before[cuts])
    best = cuts[wrong == wrong.min()]
    return int(best[np.argmin(np.abs(best - c))])


def _middle(y: np.ndarray) -> tuple[float, float]:
    """The lower and upper medians of y (equal for an odd count)."""
    s = np.sort(y)
    return float(s[(y.size - 1) // 2]), float(s[y.size // 2])


def _lag_one(r: np.ndarray) -> float:
    """Lag-one autocorrelation of residuals r, corrected for its small-sample bias
    (E[rho_hat] ~ rho - (1 + 3 rho) / n, Kendall), clipped to [0, 0.95]."""
    n = r.size
    rho = float(np.sum(r[1:] * r[:-1]) / max(np.sum(r * r), 1e-300))
    return float(np.clip((n * rho + 1.0) / max(n - 3.0, 1.0), 0.0, 0.95))
