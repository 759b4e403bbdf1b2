"""Frame-wise focal length estimate (fCOP-IS, refined) and object poses.

Pipeline: per-instance correspondences -> random triplets on every object -> minimal solver
votes -> interval stabbing over the votes of all objects (the paper's frame-wise consistency)
-> least-squares refinement of f over the inlier pixels of the supporting objects -> a robust
Umeyama pose per object. ``method="ransac"`` replaces stabbing by the paper's RANSAC variant.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .correspondences import Instance, check_images, extract_instances
from .pose import ObjectPose, back_project, refine_pose_reprojection, robust_umeyama, umeyama
from .refine import ObjectStats, object_stats, refine_focal
from .solver import sample_triplets, solve_triplets
from .stabbing import focal_intervals, interval_stabbing

DEFAULTS = dict(
    triplets_per_object=1500,   # random triplets drawn on each object
    noise_bound=0.05,           # stabbing half-width: relative (fraction) or pixels
    bound_mode="relative",      # "relative" (log f) or "absolute" (pixels, the paper's 5 px)
    focal_range=(50.0, 20000.0),  # votes outside are discarded (pixels)
    min_object_pixels=50,
    erode_px=1,
    denoise_radius=2,
    outlier_sigma=4.0,
    edge_sigma=2.0,             # drop pixels whose depth gradient exceeds this many robust sigmas (0: off)
    max_pixels=2000,
    min_support=30,             # inlier votes needed before a focal is reported
    min_inlier_ratio=0.05,
    min_object_support=0.1,     # share of an object's votes that must agree to use it in refinement
    refine=True,                # least-squares refinement over the inlier pixels of the supporting objects
    bias_correction=True,       # remove the depth-noise bias of squared differences in the refinement
    poses=True,                 # False: leave poses to FocalEstimate.poses_at (e.g. at a window's focal)
    pose_refinement=True,       # refine each pose's rotation and translation by the reprojection error
    method="stabbing",          # or "ransac"
    ransac_hypotheses=400,
    ransac_threshold=0.005,     # metres
    seed=None,
)


# The paper's fCOP-IS taken literally: uniform triplets on raw pixels, a 5 px bound, the
# interval midpoint, no refinement and no evidence threshold (it always answers).
PAPER_FCOP_IS = dict(bound_mode="absolute", noise_bound=5.0, refine=False, denoise_radius=0, erode_px=0,
                     outlier_sigma=0, edge_sigma=0, min_support=1, min_inlier_ratio=0.0)


@dataclass
class FocalEstimate:
    """Result of :func:`estimate_focal`.

    focal: focal length in pixels (fx = fy), or None when the frame gives no evidence (then
    ``reason`` says why). focal_votes: the stabbed (pre-refinement) value. interval: (lo, hi)
    focal range in pixels of the maximal consensus region. inlier_count / inlier_ratio: votes
    agreeing with it. votes_per_object / inliers_per_object: {instance_id: count}.
    objects: poses of the instances with enough support (see :mod:`fcop_ros.core.pose`).
    std_rel: relative standard error from the refinement (optimistic for correlated noise).
    votes: all valid triplet votes (focal px); stats: refinement statistics of the supporting
    objects, which a sliding window accumulates together with focal and inlier_count.
    """

    focal: float | None
    principal_point: tuple[float, float]
    image_size: tuple[int, int]
    inlier_count: int = 0
    inlier_ratio: float = 0.0
    interval: tuple[float, float] | None = None
    focal_votes: float | None = None
    std_rel: float | None = None
    votes_per_object: dict = field(default_factory=dict)
    inliers_per_object: dict = field(default_factory=dict)
    objects: list = field(default_factory=list)
    votes: np.ndarray = field(default_factory=lambda: np.zeros(0))
    stats: ObjectStats = field(default_factory=ObjectStats.empty)
    method: str = "stabbing"
    reason: str = ""
    instances: list = field(default_factory=list, repr=False)
    inlier_masks: list | None = field(default=None, repr=False)

    def poses_at(self, focal: float, reprojection: bool = True) -> list[ObjectPose]:
        """Poses of this frame's supporting objects at another focal length (e.g. a window's)."""
        if self.objects and self.focal is not None and focal == self.focal:
            return list(self.objects)
        return _poses(self.instances, float(focal), self.inlier_masks, reprojection)


def _options(options: dict) -> dict:
    unknown = set(options) - set(DEFAULTS)
    if unknown:
        raise TypeError(f"estimate_focal: unknown option(s) {sorted(unknown)}; known: {sorted(DEFAULTS)}")
    opt = {**DEFAULTS, **options}
    lo, hi = opt["focal_range"]
    if not (0 < lo < hi):
        raise ValueError(f"focal_range must satisfy 0 < min < max, got {opt['focal_range']}")
    if opt["method"] not in ("stabbing", "ransac"):
        raise ValueError(f"method must be 'stabbing' or 'ransac', got {opt['method']!r}")
    return opt


def _votes(instances: list[Instance], opt: dict, rng: np.random.Generator):
    """Minimal-solver votes of every object, solved in one call: (focal (V,), owner index (V,))."""
    lo, hi = opt["focal_range"]
    sizes = np.array([len(inst.d) for inst in instances])
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    n_tri = int(opt["triplets_per_object"])
    tri = np.concatenate([sample_triplets(int(n), n_tri, rng) + off for n, off in zip(sizes, offsets)])
    owner = np.repeat(np.arange(len(instances)), [n_tri if n >= 3 else 0 for n in sizes])
    x = np.concatenate([inst.x for inst in instances])
    d = np.concatenate([inst.d for inst in instances])
    p = np.concatenate([inst.p for inst in instances])
    f, _, ok = solve_triplets(x, d, p, tri)
    ok &= (f >= lo) & (f <= hi)
    return f[ok], owner[ok]


def _poses(instances, focal: float, init=None, reprojection: bool = True) -> list[ObjectPose]:
    """Robust Umeyama pose of each instance at ``focal`` (init: starting inlier masks), then,
    with ``reprojection``, rotation and translation refined by the reprojection error of the
    inliers (scale from the 3D fit)."""
    poses = []
    for k, inst in enumerate(instances):
        pts = back_project(inst.x, inst.d, focal)
        start = None if init is None else init[k]
        scale, R, t, inl, res = robust_umeyama(inst.p, pts, iterations=1 if start is not None else 3, init=start)
        if scale <= 0 or inl.sum() < 3:
            continue
        if reprojection:
            R, t = refine_pose_reprojection(inst.x[inl], inst.p[inl], focal, scale, R, t)
        rms = float(np.sqrt(np.mean(res[inl] ** 2)))
        poses.append(ObjectPose(inst.instance_id, R, t, scale, float(inl.mean()), rms, int(len(inst.d))))
    return poses


def _refine(instances, focal0: float, opt: dict):
    """Profile refinement on the robust inliers of each object.

    Returns (focal or None, std_rel, stats, inlier masks of every instance at focal0)."""
    stats, masks = [], []
    for inst in instances:
        pts = back_project(inst.x, inst.d, focal0)
        _, _, _, inl, _ = robust_umeyama(inst.p, pts)
        masks.append(inl)
        if inl.sum() < max(opt["min_object_pixels"] // 2, 10):
            continue
        var_d = inst.var_d[inl] if opt["bias_correction"] else None
        stats.append(object_stats(inst.x[inl], inst.d[inl], inst.p[inl], var_d))
    st = ObjectStats.concatenate(stats)
    search = float(np.log1p(max(3 * opt["noise_bound"] if opt["bound_mode"] == "relative"
                                else 3 * opt["noise_bound"] / focal0, 0.05)))
    f, std = refine_focal(st, focal0, search=search)
    return f, std, st, masks


def _ransac(instances, opt, rng):
    """The paper's fCOP-RANSAC: a triplet gives f and, by Umeyama on its three points, a pose;
    the hypothesis with most pixels within ``ransac_threshold`` metres of its object wins."""
    lo, hi = opt["focal_range"]
    nh = int(opt["ransac_hypotheses"])
    owner = rng.integers(0, len(instances), nh)
    counts = np.array([len(i.d) for i in instances])
    nmax = int(min(counts.max(), 1000))
    # Padded per-object arrays (O, nmax) for vectorised scoring.
    X = np.zeros((len(instances), nmax, 2))
    D = np.ones((len(instances), nmax))
    P = np.zeros((len(instances), nmax, 3))
    M = np.zeros((len(instances), nmax), dtype=bool)
    for k, inst in enumerate(instances):
        m = min(len(inst.d), nmax)
        pick = rng.choice(len(inst.d), m, replace=False)
        X[k, :m], D[k, :m], P[k, :m], M[k, :m] = inst.x[pick], inst.d[pick], inst.p[pick], True
    n_o = np.minimum(counts, nmax)
    # Distinct triplet indices per hypothesis within its object's valid range.
    u = rng.random((nh, 3))
    idx = np.floor(u * n_o[owner, None]).astype(int)
    bad = (idx[:, 0] == idx[:, 1]) | (idx[:, 1] == idx[:, 2]) | (idx[:, 0] == idx[:, 2])
    xs, ds, ps = X[owner[:, None], idx], D[owner[:, None], idx], P[owner[:, None], idx]
    f = np.zeros(nh)
    ok = ~bad
    m = int(ok.sum())
    if m:
        # Each hypothesis' three points laid out consecutively, so triplet k is (3k, 3k+1, 3k+2).
        fv, _, okv = solve_triplets(xs[ok].reshape(-1, 2), ds[ok].reshape(-1), ps[ok].reshape(-1, 3),
                                    np.arange(3 * m).reshape(-1, 3))
        f[ok] = fv
        ok[ok] = okv
    ok &= (f >= lo) & (f <= hi)
    if not ok.any():
        return None, 0, np.zeros(nh, dtype=bool)
    h = np.flatnonzero(ok)
    fh = f[h][:, None]
    tri_pts = np.concatenate([xs[h] / fh[..., None] * ds[h][..., None], ds[h][..., None]], axis=-1)
    s, R, t = umeyama(ps[h] - 0.5, tri_pts)
    Xo = X[owner[h]]
    pts = np.concatenate([Xo / fh[..., None] * D[owner[h]][..., None], D[owner[h]][..., None]], axis=-1)
    pred = s[:, None, None] * np.einsum("hij,hnj->hni", R, P[owner[h]] - 0.5) + t[:, None, :]
    res = np.linalg.norm(pts - pred, axis=-1)
    score = ((res < opt["ransac_threshold"]) & M[owner[h]]).sum(1) / np.maximum(n_o[owner[h]], 1)
    best = int(np.argmax(score))
    return float(f[h[best]]), int(round(score[best] * n_o[owner[h[best]]])), owner


def estimate_focal(depth, nocs, mask, principal_point=None, **options) -> FocalEstimate:
    """Estimate the focal length (pixels, fx = fy) of one frame and the poses of its objects.

    Args:
        depth: (H,W) z-depth in metres; NaN, inf and <= 0 are invalid. A global scale error of
            the depth does not change the focal length (it goes into the object scale).
        nocs: (H,W,3) NOCS in [0,1]; all-zero pixels have no prediction.
        mask: (H,W) integer instance ids, 0 = background.
        principal_point: (cx, cy) pixels; default ((W-1)/2, (H-1)/2).
        **options: see ``DEFAULTS`` in this module (unknown names raise TypeError).

    Returns a :class:`FocalEstimate`; ``focal`` is None when there is no evidence, never a
    made-up number. Mismatched or malformed images raise ValueError.
    """
    opt = _options(options)
    depth, nocs, mask = check_images(depth, nocs, mask)
    h, w = depth.shape
    pp = ((w - 1) / 2.0, (h - 1) / 2.0) if principal_point is None else tuple(float(v) for v in principal_point)
    rng = np.random.default_rng(opt["seed"])
    base = dict(principal_point=pp, image_size=(w, h), method=opt["method"])
    instances = extract_instances(depth, nocs, mask, pp, min_object_pixels=opt["min_object_pixels"],
                                  erode_px=opt["erode_px"], denoise_radius=opt["denoise_radius"],
                                  outlier_sigma=opt["outlier_sigma"], edge_sigma=opt["edge_sigma"],
                                  max_pixels=opt["max_pixels"], rng=rng)
    if not instances:
        return FocalEstimate(None, reason=f"no instance with >= {opt['min_object_pixels']} valid pixels", **base)

    if opt["method"] == "ransac":
        f, support, _ = _ransac(instances, opt, rng)
        if f is None:
            return FocalEstimate(None, reason="no valid RANSAC hypothesis", **base)
        return FocalEstimate(f, inlier_count=support, focal_votes=f,
                             objects=_poses(instances, f, reprojection=opt["pose_refinement"]),
                             instances=instances, **base)

    votes, owner = _votes(instances, opt, rng)
    ids = [inst.instance_id for inst in instances]
    per_obj = {i: int((owner == k).sum()) for k, i in enumerate(ids)}
    if votes.size == 0:
        return FocalEstimate(None, votes_per_object=per_obj, reason="no valid triplet (degenerate geometry)", **base)
    lo, hi, back = focal_intervals(votes, opt["noise_bound"], opt["bound_mode"])
    st = interval_stabbing(lo, hi)
    inl = st.inliers
    count = int(inl.sum())
    ratio = count / votes.size
    interval = (float(back(st.region[0])), float(back(st.region[1])))
    inl_obj = {i: int((inl & (owner == k)).sum()) for k, i in enumerate(ids)}
    est = FocalEstimate(None, inlier_count=count, inlier_ratio=ratio, interval=interval,
                        votes_per_object=per_obj, inliers_per_object=inl_obj, votes=votes, **base)
    if count < opt["min_support"] or ratio < opt["min_inlier_ratio"]:
        est.reason = f"too little consensus: {count} agreeing votes ({ratio:.1%}) of {votes.size}"
        return est
    f0 = float(back(st.point))
    est.focal_votes = f0
    support = [inst for k, inst in enumerate(instances)
               if per_obj[inst.instance_id] and inl_obj[inst.instance_id] / per_obj[inst.instance_id]
               >= opt["min_object_support"]]
    focal, masks = f0, None
    if opt["refine"] and support:
        f1, std, stats, masks = _refine(support, f0, opt)
        if f1 is not None:
            focal, est.std_rel, est.stats = f1, std, stats
    est.focal = focal
    est.instances, est.inlier_masks = support, masks
    if opt["poses"]:
        est.objects = _poses(support, focal, masks, opt["pose_refinement"])
    return est
