"""Rendered frames: depth, NOCS and instance-mask images of category-like objects on a table.

Objects are unions of analytic primitives (boxes, cylinders open or closed, sphere caps),
ray-cast exactly at pixel centres, with a z-buffer for occlusion. Each object's canonical frame
is its NOCS frame: y up, the bounding box centred at 0 with unit diagonal, NOCS = q + 0.5, and

    camera point = rotation @ (scale * (nocs - 0.5)) + translation   (optical frame, metres).

The ray of pixel (u, v) is r = [(u - cx)/f, (v - cy)/f, 1], so its parameter is the z-depth.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.camera import image_centre

# Primitives in design units, y up: ("box", centre, half extents), ("cyl", centre, radius,
# half height, top cap, bottom cap), ("cap", centre, radius, y cut: keep y <= cut).
SHAPES = {
    "can": [("cyl", (0, 0, 0), 1.0, 1.2, True, True)],
    "box": [("box", (0, 0, 0), (1.2, 0.6, 0.8))],
    "bowl": [("cap", (0, 0.7, 0), 1.2, 0.05)],
    "mug": [("cyl", (0, 0, 0), 0.8, 0.95, False, True),
            ("box", (1.05, 0.05, 0), (0.25, 0.55, 0.12))],
    "bottle": [("cyl", (0, -0.35, 0), 0.6, 0.85, True, True),
               ("cyl", (0, 0.85, 0), 0.25, 0.35, True, False)],
    "camera": [("box", (0, -0.1, 0), (1.0, 0.6, 0.5)),
               ("cyl", (0, -0.1, 0.75), 0.45, 0.25, False, False)],
}
CATEGORIES = tuple(SHAPES)


def _prim_bounds(pr):
    kind, c = pr[0], np.asarray(pr[1], float)
    if kind == "box":
        h = np.asarray(pr[2], float)
        return c - h, c + h
    if kind == "cyl":
        r, hh = pr[2], pr[3]
        return c - [r, hh, r], c + [r, hh, r]
    r, cut = pr[2], pr[3]
    return c - [r, r, r], np.array([c[0] + r, min(c[1] + r, cut), c[2] + r])


def _normalise(prims):
    """Scale and shift the primitives so their bounding box is centred with unit diagonal."""
    lo = np.min([_prim_bounds(p)[0] for p in prims], axis=0)
    hi = np.max([_prim_bounds(p)[1] for p in prims], axis=0)
    centre, diag = (lo + hi) / 2, np.linalg.norm(hi - lo)
    out = []
    for p in prims:
        c = (np.asarray(p[1], float) - centre) / diag
        if p[0] == "box":
            out.append(("box", c, np.asarray(p[2], float) / diag))
        elif p[0] == "cyl":
            out.append(("cyl", c, p[2] / diag, p[3] / diag, p[4], p[5]))
        else:
            out.append(("cap", c, p[2] / diag, (p[3] - centre[1]) / diag))
    return out, (hi - lo) / diag


_NORMALISED = {k: _normalise(v) for k, v in SHAPES.items()}


def _hit_box(o, v, c, h):
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (c - h - o) / v
        t2 = (c + h - o) / v
    t1 = np.where(np.isnan(t1), -np.inf, t1)
    t2 = np.where(np.isnan(t2), np.inf, t2)
    near = np.minimum(t1, t2).max(-1)
    far = np.maximum(t1, t2).min(-1)
    return np.where((near <= far) & (near > 0), near, np.inf)


def _quad_roots(a, b, c):
    disc = b * b - 4 * a * c
    ok = (disc >= 0) & (a != 0)
    sq = np.sqrt(np.where(ok, disc, 0))
    a2 = np.where(ok, 2 * a, 1)
    return np.where(ok, (-b - sq) / a2, np.inf), np.where(ok, (-b + sq) / a2, np.inf)


def _hit_cyl(o, v, c, r, hh, top, bottom):
    oc = o - c
    a = v[:, 0] ** 2 + v[:, 2] ** 2
    b = 2 * (oc[:, 0] * v[:, 0] + oc[:, 2] * v[:, 2])
    cc = oc[:, 0] ** 2 + oc[:, 2] ** 2 - r * r
    best = np.full(len(o), np.inf)
    for lam in _quad_roots(a, b, cc):
        y = oc[:, 1] + lam * v[:, 1]
        best = np.where((lam > 0) & (np.abs(y) <= hh) & (lam < best), lam, best)
    for yc, on in ((hh, top), (-hh, bottom)):
        if not on:
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (yc - oc[:, 1]) / v[:, 1]
        px, pz = oc[:, 0] + lam * v[:, 0], oc[:, 2] + lam * v[:, 2]
        good = np.isfinite(lam) & (lam > 0) & (px * px + pz * pz <= r * r) & (lam < best)
        best = np.where(good, lam, best)
    return best


def _hit_cap(o, v, c, r, cut):
    oc = o - c
    a = (v * v).sum(1)
    b = 2 * (oc * v).sum(1)
    cc = (oc * oc).sum(1) - r * r
    best = np.full(len(o), np.inf)
    for lam in _quad_roots(a, b, cc):
        y = o[:, 1] + lam * v[:, 1]
        best = np.where((lam > 0) & (y <= cut) & (lam < best), lam, best)
    return best


def intersect(shape: str, o: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Ray parameter of the first hit of rays o + lam v (canonical units) with a shape; inf if
    none."""
    prims, _ = _NORMALISED[shape]
    best = np.full(len(o), np.inf)
    for p in prims:
        if p[0] == "box":
            lam = _hit_box(o, v, p[1], p[2])
        elif p[0] == "cyl":
            lam = _hit_cyl(o, v, p[1], *p[2:])
        else:
            lam = _hit_cap(o, v, p[1], p[2], p[3])
        best = np.minimum(best, lam)
    return best


def extents(shape: str) -> np.ndarray:
    """Bounding-box size of a shape in NOCS units (its diagonal is 1)."""
    return _NORMALISED[shape][1]


@dataclass
class SceneObject:
    """Ground truth of one rendered object (pose convention in the module docstring)."""

    instance_id: int
    category: str
    rotation: np.ndarray
    translation: np.ndarray
    scale: float


@dataclass
class Frame:
    """A rendered frame: depth (H,W) metres with NaN where nothing was hit, nocs (H,W,3) in [0,1]
    (0 on background), mask (H,W) uint16 instance ids, focal (px), principal point, objects."""

    depth: np.ndarray
    nocs: np.ndarray
    mask: np.ndarray
    focal: float
    principal_point: tuple[float, float]
    objects: list = field(default_factory=list)

    @property
    def K(self) -> np.ndarray:
        cx, cy = self.principal_point
        return np.array([[self.focal, 0, cx], [0, self.focal, cy], [0, 0, 1.0]])


def render(objects, focal: float, width: int = 640, height: int = 480, principal_point=None,
           table=None) -> Frame:
    """Ray-cast the objects at pixel centres. ``table`` = (point, normal) in the camera frame
    gives the background plane's depth (mask 0, NOCS 0); without it the background is NaN."""
    cx, cy = image_centre(width, height) if principal_point is None else principal_point
    depth = np.full((height, width), np.inf)
    nocs = np.zeros((height, width, 3))
    mask = np.zeros((height, width), np.uint16)
    for ob in objects:
        R, t, s = ob.rotation, np.asarray(ob.translation, float), float(ob.scale)
        if t[2] <= 0.51 * s:
            continue
        # Pixel rectangle of the bounding sphere's cube (all of it is in front of the camera).
        rad = 0.5 * s
        corners = t + rad * np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
        pu = cx + focal * corners[:, 0] / corners[:, 2]
        pv = cy + focal * corners[:, 1] / corners[:, 2]
        u0, u1 = int(np.floor(pu.min())) - 1, int(np.ceil(pu.max())) + 1
        v0, v1 = int(np.floor(pv.min())) - 1, int(np.ceil(pv.max())) + 1
        u0, v0 = max(u0, 0), max(v0, 0)
        u1, v1 = min(u1, width - 1), min(v1, height - 1)
        if u0 > u1 or v0 > v1:
            continue
        vv, uu = np.mgrid[v0:v1 + 1, u0:u1 + 1]
        rays = np.stack(
            [(uu.ravel() - cx) / focal, (vv.ravel() - cy) / focal, np.ones(uu.size)], 1
        )
        o = np.broadcast_to(-R.T @ t / s, rays.shape)
        v = rays @ R / s
        lam = intersect(ob.category, o, v)
        hit = np.isfinite(lam)
        if not hit.any():
            continue
        q = o[hit] + lam[hit, None] * v[hit]
        rr, cc = vv.ravel()[hit], uu.ravel()[hit]
        closer = lam[hit] < depth[rr, cc]
        rr, cc = rr[closer], cc[closer]
        depth[rr, cc] = lam[hit][closer]
        nocs[rr, cc] = np.clip(q[closer] + 0.5, 0.0, 1.0)
        mask[rr, cc] = ob.instance_id
    if table is not None:
        point, normal = (np.asarray(a, float) for a in table)
        vv, uu = np.mgrid[0:height, 0:width]
        rn = ((uu - cx) / focal) * normal[0] + ((vv - cy) / focal) * normal[1] + normal[2]
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = (point @ normal) / rn
        bg = (mask == 0) & (lam > 0) & np.isfinite(lam)
        depth[bg] = lam[bg]
    depth[~np.isfinite(depth)] = np.nan
    return Frame(depth, nocs, mask, float(focal), (float(cx), float(cy)), list(objects))


def random_scene(rng: np.random.Generator, n_objects: int = 5, focal: float | None = None,
                 width: int = 640, height: int = 480, focal_range=(450.0, 800.0),
                 distance_range=(0.6, 1.2), scale_range=(0.12, 0.3), elevation_deg=(25.0, 60.0),
                 categories=CATEGORIES, upright: bool = True):
    """Random table-top scene in the camera frame: returns (objects, focal, table plane).

    The camera looks down at a table at ``elevation_deg``; objects stand upright on it with a
    random yaw (or take any rotation when ``upright`` is False), without overlapping.
    """
    from scipy.spatial.transform import Rotation

    f = float(rng.uniform(*focal_range)) if focal is None else float(focal)
    phi = np.radians(rng.uniform(*elevation_deg))
    up = np.array([0.0, -np.cos(phi), -np.sin(phi)])
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.array([0.0, -np.sin(phi), np.cos(phi)])
    dist = rng.uniform(*distance_range)
    centre = np.array([0.0, 0.0, dist])
    objs, spots = [], []
    half_w = 0.8 * dist * (width / 2) / f
    half_h = 0.6 * dist * (height / 2) / f
    for k in range(n_objects):
        cat = categories[rng.integers(len(categories))]
        s = float(rng.uniform(*scale_range))
        ext = extents(cat)
        radius = 0.5 * s * np.hypot(ext[0], ext[2])
        for _ in range(50):
            a, b = (
                rng.uniform(-half_w, half_w),
                rng.uniform(-half_h, half_h) / max(np.sin(phi), 0.3),
            )
            pos = centre + a * e1 + b * e2
            if all(np.linalg.norm(pos - p) > radius + r + 0.01 for p, r in spots):
                break
        else:
            continue
        spots.append((pos, radius))
        if upright:
            yaw = rng.uniform(0, 2 * np.pi)
            xo = np.cos(yaw) * e1 + np.sin(yaw) * e2
            zo = np.cross(xo, up)
            R = np.column_stack([xo, up, zo])
        else:
            R = Rotation.random(random_state=rng).as_matrix()
        t = pos + up * (0.5 * s * ext[1])
        objs.append(SceneObject(k + 1, cat, R, t, s))
    return objs, f, (centre, up)


def render_scene(rng: np.random.Generator, n_objects: int = 5, focal: float | None = None,
                 width: int = 640, height: int = 480, **scene_options) -> Frame:
    """A random scene rendered clean (see :func:`random_scene`)."""
    objs, f, table = random_scene(rng, n_objects, focal, width, height, **scene_options)
    return render(objs, f, width, height, table=table)
