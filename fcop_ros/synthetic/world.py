"""A randomised synthetic world for judging the estimator: error families of learned predictors
whose parameters are drawn at random per sequence, scenes of 1-6 objects at two image sizes.

Each family is an upper bound in :class:`ErrorFamilies`; :meth:`ErrorFamilies.draw` picks the
actual strength of every family for one sequence (uniform between 0 and the bound), and
:class:`ErrorState` carries what persists across the frames of a sequence: each object's shape
mismatch and relief error, and the smooth depth and NOCS fields, which drift from frame to frame.
Every family is zero-mean except the global depth scale, which cancels in the focal length.

Named presets (``WORLD_PRESETS``):
- ``sensor``: sensor-like depth (fine noise, flying pixels, mild low-frequency error),
  ground-truth NOCS, slightly wrong masks. Calibrated so that the paper's method taken literally
  scores near the paper's 3.15% (REAL275, sensor depth, ground-truth NOCS).
- ``predicted``: every family, as from a monocular depth network and a NOCS network.
  Calibrated so that the paper's method taken literally scores near the paper's 6.87% (REAL275).
- ``only_<family>``: one zero-mean mechanism alone, for bias tests.
- ``only_nocs_jpeg``, ``predicted_nocs_jpeg``: the NOCS image through JPEG (a pipe, not a
  predictor: not zero-mean, in no other preset), alone and on top of ``predicted``, so that
  what a compressed image transport does is measured on tuning frames.
- ``only_principal_point``: the camera's principal point off the image centre alone (both
  presets above have it too: a camera whose intrinsics are unknown has an unknown principal
  point as well).

The older fixed presets of :mod:`fcop_ros.synthetic.noise` (``mild``, ``moderate``, ``harsh``)
are fixed settings of these same mechanisms: each is written once, in :func:`apply_errors`.

The held-out variant (``variant="heldout"``) builds its smooth fields from random sinusoids
instead of interpolated grids, its NOCS distortion from a quadratic warp instead of a field and
its mask errors with an elliptic kernel: a different error model with the same strengths.
After several rounds of development had looked at it, a second one (``variant="heldout2"``,
first evaluated on 22 Nov 2026) builds its depth fields from Gaussian bumps, twists each
object's NOCS about a random axis and shifts each instance's mask (a misregistered
segmentation) instead of eroding or dilating it. After two more rounds, a third
(``variant="heldout3"``, fixed on 23 Nov 2026 before any of that round's choices and first
evaluated at its end) errs as monocular depth networks do in ways the others do not: part of
its depth field follows depth rather than the image (an error affine in disparity), the rest is
a random polynomial of the image coordinates; the global depth scale is redrawn in every frame
about the sequence's; each object's NOCS bulge or shrink radially; and each instance's boundary
is ragged (pixels on either side of it flipped at random) rather than moved as a whole.
A fourth (``variant="heldout4"``, fixed on 23 Nov 2026 before that round's runs) errs in ways
that follow the objects rather than the image: the coarsest depth field is a smooth function of
each object's own surface (a quadratic in its true NOCS, so it moves with the object, as large
as the field's strength times the object's size), the rest rings about a random centre of the
image; each object's distance is misjudged anew in every frame; each object's NOCS are
stretched or flattened by up to 3 times the NOCS field's strength along the direction they
share with depth (the viewing axis), so the error turns with the view; masks are polygons with
holes, as a detector's outlines are; and, with per-pixel NOCS noise, the NOCS are quantised to 8
bits, as an rgb8 NOCS image holds them.
A fifth (``variant="heldout5"``, fixed on 24 Nov 2026 before that round's choices) errs as
networks that work on patches and parts do: its depth fields are piecewise constant over a
random grid of tiles, softened at their seams (a network run tile by tile); its edge bleeding
is a halo that decays away from each depth edge rather than a band; each object's NOCS are
split by a random plane through the object and one side is displaced (a part, such as a
handle, put a little off); and each instance's mask is its convex hull (what a box-prompted
segmenter fills in: the concavities between handle and body, the background between parts).
A sixth (``variant="heldout6"``, fixed on 24 Nov 2026 before that round's evaluation and run
once, at its end, on an estimator that round did not change) errs as a network trained on other
cameras does: its coarsest depth field grows with the squared distance from the image centre
(a field-of-view prior: the error a focal length would make), the finer ones vary along the
image rows only (a ground-plane prior); at depth edges the nearer surface spreads over the
farther one (foreground fattening) instead of blending; each object's NOCS shrink towards
(or swell from) its centre near its silhouette, where a network regresses to the mean; and
each instance's mask is what a 28x28 mask head gives, its box resampled to 28x28 and back and
thresholded at a level drawn per instance.
A seventh (``variant="heldout7"``, fixed on 24 Nov 2026 before that round's evaluation) errs as
networks that read the image rather than the geometry do: its coarsest depth field is the
image's brightness, a Lambertian shading of the true surface under a light drawn for the
sequence times an albedo per object and for the table (so it turns with each surface's
orientation and is one value over a plane of one colour, such as the table), the finer ones are
drawn anew for each object and for the table (the error jumps at every silhouette rather than
running smoothly across it); each object's NOCS are stretched or squashed along the longer
image axis of its box, by a share that grows with the box's aspect (a NOCS head that sees each
crop resized to a square), a direction fixed in the camera frame, across the viewing axis; and
where two instances touch, one of them (kept for the sequence) takes a band of the other's
pixels, as wide as a width drawn anew in every frame, with its own NOCS carried over (the
neighbour's surface, labelled and coordinated as the wrong object), while each instance's
border with the background is eroded or dilated by a width kept for the sequence.
An eighth (``variant="heldout8"``, fixed on 24 Nov 2026 before any evaluation on it) errs as
networks whose outputs pass through priors and pipes the others leave out: its coarsest depth
field is the familiar-size cue, each object's distance judged partly from its size against a
typical one (a larger object put nearer, a smaller one farther, by a reliance kept for the
sequence: one value over each object, none on the table), the finer ones are image fields whose
relative error grows with the true depth (up to 3 times the objects' median depth); with
per-pixel depth noise, the depth passes through an 8-bit image of disparity normalised over the
frame (a relative-depth network's output written and read back: terraces that deepen with
depth); each object's NOCS are spread over too wide or too narrow an angle about the vertical
axis of its main part, about the direction it is seen from (a category model's ambiguity about
the symmetry axis: on a can, bowl or bottle the NOCS stay on the shape, only the azimuth is
wrong); with per-pixel NOCS noise, the NOCS image goes through JPEG at a quality kept for the
sequence (a ROS compressed image transport: 8 bits, 8x8 blocks, chroma halved); and each
instance's mask leaks into the background by up to the mask width and is cut by its detection
box, each side of which misses the true box's by up to that width (straight truncations).
A ninth (``variant="heldout9"``, fixed on 24 Nov 2026 before any evaluation on it) errs as a
robot's pipeline around the networks does: its depth fields are fixed in the scene rather than
in the image, an error in metres on the surface of a fused map that stays where it is as the
camera moves (every scale, kept for the sequence); with per-pixel depth noise, the depth is
predicted at a half or a quarter of the image's size (kept for the sequence) and brought back
up bilinearly, mixed across every silhouette over a band that wide; each object's NOCS are
pulled towards (or pushed from) their best affine function of the image coordinates, by a share
of 3 times the NOCS field's strength (a network's spectral bias: the curvature of the NOCS
across the image, which carries relief and perspective, under- or overestimated; its ramp
kept); with per-pixel NOCS noise (a NOCS network in the loop: not the ``sensor`` preset's
ground truth), the NOCS and masks arrive one frame late, the last frame's truth beside this
frame's depth (the first frame's its own); its masks are eroded or dilated as the tuning
model's; and, with mask errors, the camera's principal point is off the image centre that the
estimator assumes by up to 1% of the image's size per axis times the mask width over 3 (whole
pixels, kept for the sequence: the images are moved, the frame's ``principal_point`` says where
it truly is). Every mechanism is zero-mean as the families are except two, which model a
mismatch in the pipeline rather than a predictor's error: the late NOCS (a latency, whose error
follows the camera's motion) and the principal point (a camera model taken for granted; its
direction is random, its size is not zero-mean).
A tenth (``variant="heldout10"``, fixed on 24 Nov 2026 before any evaluation on it) errs as a
camera, a depth network, a category prior and a tracker do in ways the others leave out: with
mask errors, the images are taken through a lens whose rectification left a radial distortion,
x (1 + k1 r^2 + k2 r^4) in coordinates normalised by the true focal length about the true
principal point, k1 uniform in +-0.02 times the mask width over 3 and k2 = -k1 / 4, kept for the
sequence, where the estimator assumes a pinhole; in the same resampling, the principal point is
off the image centre by a Gaussian of 0.6% of the image's size per axis times the mask width
over 3 (sub-pixel, kept for the sequence; the frame's ``principal_point`` says where it truly
is); each object's relief finer than a third of its radius is sharpened or flattened, depth +
a (depth - its Gaussian blur over the object), a drawn per object for the sequence in +-3 times
the relief family's strength (a network that over- or understates detail; none without relief
errors, so none in ``sensor``, whose depth is a sensor's); with per-pixel depth noise (a
sensor's or a network's), each object's depth has one to three holes (a specular or dark
surface: NaN), together up to 10% of its pixels, drawn anew in every frame; each object's NOCS
bend along its own up axis and taper (x += b (y - 0.5)^2; x and z about 0.5 times
1 + c (y - 0.5)), b and c drawn per object for the sequence so that either moves the object's
ends by up to 3 times the NOCS field's strength (a category prior whose shape bends, in place of
the tuning model's NOCS field, sized as heldout4's stretch); and, with mask errors, each
instance's mask is eroded or dilated by a width drawn anew in every frame (a flickering
segmentation, as the tuning model's), and at a probability of 5% per frame two instances
exchange their ids for that frame only (a tracker's id switch). Its smooth depth fields are the
tuning model's. Every mechanism is zero-mean as the families are except three: the lens and the
principal point (a camera model taken for granted: the distortion's sign and the point's
direction are random, their sizes are not zero-mean) and the holes (which remove depth and
never change it).
An eleventh (``variant="heldout11"``, fixed on 25 Nov 2026 before the tuning world's lens family
was judged by any estimator) differs from the tuning model only in its camera: the tuning
world's lens is a Brown polynomial (``lens``, below), heldout11's a division model, x = xd /
(1 + l rd^2), with decentering (tangential) terms p1, p2, l up to 1.2 times the tuning bound and
p1, p2 up to 0.2 times it (a lens model the polynomial is not, and a stronger one: at the
objects' radii the decentering moves points up to 0.43 px off a pinhole, the tuning lens 0.04
px, and it magnifies an object in proportion to its radius, not its square); its
principal point and predictor errors are the tuning model's. It judges a term for the lens's
residual distortion on a lens that term was not shaped on.
A thirteenth (``variant="heldout12"``, fixed on 25 Nov 2026 before any evaluation on it) errs
as a depth sensor or network that sees surfaces obliquely, a NOCS head that works on regions of
interest and a segmenter unsure where an object meets what it stands on, with the tuning
model's camera (its principal point and its lens): its depth field, in place of every scale of
the tuning grid, is a relative error proportional to 1 - cos(theta), theta the angle between
each pixel's true surface normal and its viewing ray (0 facing the camera, 1 edge-on: it grows
towards each object's rims and is large on the obliquely seen table), scaled to unit rms over
the objects times a coefficient that drifts as the fields do (random sign; the field's
strength times that, as the tuning field's); each object's NOCS map is misregistered within its
mask by a shift of its box's diagonal times half the NOCS field's strength per image axis, a
Gaussian that drifts as the fields do (a NOCS head pasted into a box a little off the one it
saw, the mask from elsewhere; sub-pixel to a few pixels, bilinear, the NOCS carried past the
outline by the nearest pixel's); with per-pixel NOCS noise (a NOCS network: not the ``sensor``
preset's ground truth), each object's NOCS are what a head that predicts them on a 28x28 grid
over its box gives, pasted back by nearest neighbour (blocks of the box's size over 28 pixels,
each the mean of the object's NOCS in it), before the per-pixel noise; and, with mask errors,
each instance's mask is eroded or dilated by a width drawn anew in every frame in -2..2 times
the mask width, only where its outline meets the background at its own depth (within 2%: its
base on the table), not at its occluding contours. Every mechanism is zero-mean as the families
are (the field's and the shift's signs, the contact width's) except the 28x28 grid, a
resolution of the pipeline (its error is symmetric within each block).
A fourteenth (``variant="heldout13"``, fixed on 25 Nov 2026 before any evaluation on it, at an
estimator and window the round had not changed) errs as a stereo sensor, an affine-invariant
depth network and a category prior do in ways the others leave out, with the tuning model's
camera, depth fields and masks: the per-pixel depth noise grows with the square of the depth,
not with the depth (relative noise times the true depth over 1 m, as a stereo pair's
disparity error); the additive depth offset is drawn anew in every frame from the sequence's
strength (a network whose depth is known up to a shift, fitted frame by frame); with per-pixel
depth noise, each object is see-through with a probability of 0.15, kept for the sequence: over
an ellipse of about a share in 0.2..0.5 of its pixels (kept), at a place drawn anew in every
frame, the depth reads the table behind it (glass or a specular surface that a sensor or
network sees through; not zero-mean: it only ever moves depth back); and, in place of the
tuning model's NOCS field, each object's NOCS are moved by a smooth warp of NOCS space kept for
the sequence, four Gaussian bumps of random centre, width and direction scaled to the NOCS
field's strength per axis over the unit cube (the category's typical shape in place of the
instance's, a deformation that turns with the object, not one fixed in the image).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import cv2
import numpy as np
from scipy import ndimage

from ..core.camera import image_centre
from .render import Frame, random_scene, render


@dataclass(frozen=True)
class ErrorFamilies:
    """Upper bounds of each error family (relative to depth unless said otherwise).

    depth_scale: sigma of a global log-scale error; field: amplitude (std) of the smooth
    multiplicative depth field, summed over ``field_cells`` spatial scales; field_drift: largest
    share of the field renewed per frame; relief: per-object relief flattening or exaggeration
    (z about the object's median scaled by 1 +- relief); offset: additive depth offset (metres,
    sigma); depth_pixel: per-pixel relative noise; edge_px: depth bleeding band (pixels) at
    discontinuities; flying: share of that band turned into flying pixels; nocs_pixel: per-pixel
    NOCS noise (NOCS units); nocs_field: smooth NOCS distortion; nocs_outliers: share of object
    pixels with random NOCS; nocs_blur_px: NOCS blur across object boundaries; shape: per-object
    anisotropic scale of the NOCS axes (category prior mismatch); mask_px: mask erosion or
    dilation; blobs: spurious instances with random NOCS; nocs_jpeg: the NOCS image sent as JPEG
    (ROS's compressed image transport) at a quality drawn in 75..95 per sequence, a switch that
    no preset turns on (its error is not zero-mean: at the silhouettes the NOCS ring and are
    pulled towards the black background), for choosing a defence on tuning frames;
    principal_point: the camera's principal point off the image centre the estimator assumes,
    per axis by up to this share of the image's size (a strength uniform in [0, bound] times a
    uniform direction in [-1, 1] per axis, kept for the sequence, sub-pixel: the scene is
    rendered through that camera and the frame's ``principal_point`` says where it is). It is
    drawn from a generator of its own, so that the other families' draws stay as they were, and
    only in the tuning model, ``heldout11`` and ``heldout12`` (``heldout9`` and ``heldout10``
    move it their own ways). lens: the camera's residual
    radial distortion after rectification, x (1 + k1 r^2 + k2 r^4) in coordinates normalised by
    the focal length about the principal point, k1 uniform in +-lens and k2 in +-lens / 2, kept
    for the sequence (zero-mean in sign; drawn from a generator of its own, as the principal
    point; only in the tuning model and ``heldout12``, which keeps the tuning camera;
    ``heldout10`` and ``heldout11`` have lenses of their own).
    """

    depth_scale: float = 0.0
    field: float = 0.0
    field_cells: tuple = (1, 2, 4)
    field_drift: float = 0.0
    relief: float = 0.0
    offset: float = 0.0
    depth_pixel: float = 0.0
    edge_px: int = 0
    flying: float = 0.0
    nocs_pixel: float = 0.0
    nocs_field: float = 0.0
    nocs_outliers: float = 0.0
    nocs_blur_px: int = 0
    shape: float = 0.0
    mask_px: int = 0
    blobs: int = 0
    nocs_jpeg: bool = False
    principal_point: float = 0.0
    lens: float = 0.0

    def scaled(self, k: float) -> "ErrorFamilies":
        """Every continuous strength times k (integers and the field scales unchanged)."""
        return replace(self, **{f.name: getattr(self, f.name) * k for f in fields(self)
                                if isinstance(getattr(self, f.name), float)
                                and f.name not in ("field_drift", "principal_point", "lens")})

    def draw(self, rng: np.random.Generator) -> "ErrorFamilies":
        """The strengths of one sequence: each family uniform in [0, bound] (integers inclusive;
        the field drift in [bound / 3, bound])."""
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, (bool, tuple)) or f.name in ("principal_point", "lens"):
                out[f.name] = v  # the camera's own generator draws these
            elif f.name == "field_drift":  # a depth network errs anew in every view, more or less
                out[f.name] = float(rng.uniform(v / 3, v))
            elif isinstance(v, int):
                out[f.name] = int(rng.integers(0, v + 1))
            else:
                out[f.name] = float(rng.uniform(0, v))
        return ErrorFamilies(**out)


ZERO_MEAN_FAMILIES = ("field", "relief", "offset", "depth_pixel", "nocs_pixel",
                      "nocs_field", "shape", "lens")

# A camera's principal point is rarely exactly at the image centre (REAL275's: 0.5% and 1.0%
# of width and height off it); no gain scales it.
_PRINCIPAL_POINT = 0.02
# Nor is a rectified image free of distortion: a calibration's residual k1 up to +-0.01 moves the
# corners of a 640x480 image at f = 600 px by up to 1.8 px.
_LENS = 0.01
_SENSOR = ErrorFamilies(depth_scale=0.0, field=0.01, field_drift=0.6, relief=0.0, offset=0.004,
                        depth_pixel=0.004, edge_px=2, flying=0.5, mask_px=2,
                        principal_point=_PRINCIPAL_POINT, lens=_LENS)
_PREDICTED = ErrorFamilies(depth_scale=0.15, field=0.05, field_drift=0.6, relief=0.10, offset=0.02,
                           depth_pixel=0.005, edge_px=3, flying=0.3, nocs_pixel=0.04,
                           nocs_field=0.03, nocs_outliers=0.05, nocs_blur_px=3, shape=0.10,
                           mask_px=3, blobs=2, principal_point=_PRINCIPAL_POINT, lens=_LENS)
# Scale factors of the two presets, calibrated so that the paper's method taken literally scores
# near the paper's REAL275 figures (bench/world_calibration.py prints the fit).
SENSOR_GAIN = 1.0
PREDICTED_GAIN = 0.55

BASE_PRESETS = {"sensor": _SENSOR, "predicted": _PREDICTED}
WORLD_PRESETS = {
    "sensor": _SENSOR.scaled(SENSOR_GAIN),
    "predicted": _PREDICTED.scaled(PREDICTED_GAIN),
}
for _name in ZERO_MEAN_FAMILIES:
    _bound = getattr(_PREDICTED, _name)
    WORLD_PRESETS[f"only_{_name}"] = ErrorFamilies(
        **{_name: _bound}, **({"field_drift": 0.6} if _name == "field" else {})
    )
WORLD_PRESETS["only_principal_point"] = ErrorFamilies(principal_point=_PRINCIPAL_POINT)
# Errors of the pipes between the predictors and the estimator, not zero-mean and in no preset:
# each alone, and the `predicted` preset with it.
PIPE_FAMILIES = ("nocs_jpeg",)
for _name in PIPE_FAMILIES:
    WORLD_PRESETS[f"only_{_name}"] = ErrorFamilies(**{_name: True})
    WORLD_PRESETS[f"predicted_{_name}"] = replace(WORLD_PRESETS["predicted"], **{_name: True})


@dataclass
class SceneSpec:
    """What a random scene may be: object count, image sizes, focal (px), distance and object
    size (bounding-box diagonal) ranges (m)."""

    objects: tuple = (1, 6)
    sizes: tuple = ((640, 480), (320, 240))
    focal_range: tuple = (400.0, 1500.0)
    distance_range: tuple = (0.4, 2.0)
    object_size: tuple = (0.1, 0.3)


def _grid_field(rng, h, w, cells):
    coarse = rng.normal(size=(cells + 1, cells + 2)).astype(np.float32)
    f = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC).astype(np.float64)
    return f / max(f.std(), 1e-9)


def _sine_field(rng, h, w, cells):
    yy, xx = np.mgrid[0:h, 0:w]
    out = np.zeros((h, w))
    for _ in range(4):
        k = rng.normal(size=2) * cells * np.pi / max(h, w)
        out += np.cos(k[0] * xx + k[1] * yy + rng.uniform(0, 2 * np.pi))
    return out / max(out.std(), 1e-9)


def _bump_field(rng, h, w, cells):
    """A sum of cells^2 + 2 Gaussian bumps of random sign, about 1 / cells of the image wide."""
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    out = np.zeros((h, w))
    for _ in range(cells * cells + 2):
        cy, cx = rng.uniform(0, h / max(h, w)), rng.uniform(0, w / max(h, w))
        r = rng.uniform(0.5, 1.0) / cells
        out += rng.normal() * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * r * r))
    return (out - out.mean()) / max(out.std(), 1e-9)


def _poly_field(rng, h, w, cells):
    """A random polynomial of degree cells + 1 in the image coordinates (Legendre products,
    aspect kept), zero mean and unit std."""
    deg = cells + 1
    c = rng.normal(size=(deg + 1, deg + 1))
    c[np.add.outer(np.arange(deg + 1), np.arange(deg + 1)) > deg] = 0.0
    c[0, 0] = 0.0
    y = np.linspace(-1, 1, h) * h / max(h, w)
    x = np.linspace(-1, 1, w) * w / max(h, w)
    out = np.polynomial.legendre.leggrid2d(y, x, c)
    return (out - out.mean()) / max(out.std(), 1e-9)


def _ring_field(rng, h, w, cells):
    """Rings about a random centre of the image (a sum of cells + 1 radial cosines, of about
    cells / 2 periods across the image), zero mean and unit std."""
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    cy, cx = rng.uniform(0, h / max(h, w)), rng.uniform(0, w / max(h, w))
    r = np.hypot(yy - cy, xx - cx)
    out = sum(rng.normal() * np.cos(np.pi * cells * rng.uniform(0.5, 1.5) * r
                                    + rng.uniform(0, 2 * np.pi)) for _ in range(cells + 1))
    return (out - out.mean()) / max(out.std(), 1e-9)


def _tile_field(rng, h, w, cells):
    """Piecewise constant over a grid of about (cells + 1)^2 tiles of random sizes, each tile a
    random level, softened over a few pixels at the seams; zero mean and unit std."""
    n = cells + 1
    ys = np.sort(rng.uniform(0, h, n - 1)).astype(int)
    xs = np.sort(rng.uniform(0, w, n - 1)).astype(int)
    levels = rng.normal(size=(n, n))
    iy = np.searchsorted(ys, np.arange(h), side="right")
    ix = np.searchsorted(xs, np.arange(w), side="right")
    out = levels[iy][:, ix].astype(np.float32)
    k = 2 * max(1, max(h, w) // 160) + 1
    out = cv2.GaussianBlur(out, (k, k), 0).astype(np.float64)
    return (out - out.mean()) / max(out.std(), 1e-9)


def _lens_row_field(rng, h, w, cells):
    """The coarsest scale (cells 1): the squared distance from the image centre, of random
    sign; finer ones: a function of the image row alone (cells + 2 random levels down the
    image, cubic between them). Zero mean and unit std."""
    if cells <= 1:
        yy, xx = np.mgrid[0:h, 0:w]
        out = ((yy - (h - 1) / 2) ** 2 + (xx - (w - 1) / 2) ** 2) * rng.choice([-1.0, 1.0])
    else:
        levels = rng.normal(size=(cells + 2, 1)).astype(np.float32)
        rows = cv2.resize(levels, (1, h), interpolation=cv2.INTER_CUBIC).astype(np.float64)
        out = np.broadcast_to(rows, (h, w)).copy()
    return (out - out.mean()) / max(out.std(), 1e-9)


VARIANTS = ("tuning", "heldout", "heldout2", "heldout3", "heldout4", "heldout5", "heldout6",
            "heldout7", "heldout8", "heldout9", "heldout10", "heldout11", "heldout12",
            "heldout13")
# heldout7's image fields are the tuning grid's, drawn per segment (ErrorState._segments);
# heldout8's finer ones are the tuning grid's, grown with depth (ErrorState._grown);
# heldout9 has no image field: its depth fields are sinusoids fixed in the scene
# (ErrorState._scene_field), its NOCS distortion a pull towards a ramp (_ramp_pull);
# heldout10's depth fields are the tuning grid's, its NOCS distortion a bend (_bend);
# heldout12 has no image field: its depth field follows the grazing angle
# (ErrorState._grazing_field), its NOCS distortion a misregistration of each object's
# NOCS map (_roi_shift); heldout13's depth fields are the tuning grid's, its NOCS distortion a
# warp of NOCS space (_shape_warp).
_FIELDS = {"tuning": _grid_field, "heldout": _sine_field, "heldout2": _bump_field,
           "heldout3": _poly_field, "heldout4": _ring_field, "heldout5": _tile_field,
           "heldout6": _lens_row_field, "heldout7": _grid_field, "heldout8": _grid_field,
           "heldout9": _grid_field, "heldout10": _grid_field, "heldout11": _grid_field,
           "heldout12": _grid_field, "heldout13": _grid_field}
# heldout8's familiar-size cue: the typical size (bounding-box diagonal, m; the geometric mean
# of SceneSpec's range) and the spread of log sizes that one unit of the field stands for.
_TYPICAL_SIZE = 0.17
_SIZE_SPREAD = 0.3


# Errors that persist over a sequence, which ``renew`` can draw anew in every frame instead.
RENEWABLE = ("field", "shape", "relief", "offset")


@dataclass
class ErrorState:
    """What persists across the frames of one sequence under one draw of the error families."""

    err: ErrorFamilies
    variant: str = "tuning"
    rho: float = 1.0
    scale: float = 1.0
    offset: float = 0.0
    fields: dict = field(default_factory=dict)
    renew: frozenset = frozenset()
    objects: dict = field(default_factory=dict)

    @staticmethod
    def start(err: ErrorFamilies, rng: np.random.Generator,
              variant: str = "tuning", renew=()) -> "ErrorState":
        """``renew``: families among RENEWABLE that this state draws anew in every frame
        instead of keeping (a diagnostic of what a window can average)."""
        if variant not in VARIANTS:
            raise ValueError(f"unknown error-model variant {variant!r}: one of {VARIANTS}")
        if set(renew) - set(RENEWABLE):
            raise ValueError(f"cannot renew {sorted(set(renew) - set(RENEWABLE))}: "
                             f"one of {RENEWABLE}")
        st = ErrorState(err, variant, renew=frozenset(renew))
        st.rho = (0.0 if "field" in st.renew
                  else float(np.sqrt(1.0 - err.field_drift)) if err.field_drift > 0 else 1.0)
        st.scale = float(np.exp(rng.normal(0, err.depth_scale))) if err.depth_scale > 0 else 1.0
        st.offset = float(rng.normal(0, err.offset)) if err.offset > 0 else 0.0
        return st

    def _drift(self, key, new):
        """``new`` blended with what ``key`` held before (if of its shape), so that it renews a
        share 1 - rho^2 of itself per frame at the same variance; kept under ``key``."""
        old = self.fields.get(key)
        if old is not None and np.shape(old) == np.shape(new):
            new = self.rho * old + np.sqrt(1 - self.rho ** 2) * new
        self.fields[key] = new
        return new

    def _kept(self, key, draw):
        """What ``key`` holds, drawn by ``draw()`` the first time it is asked for: an error
        that persists for the whole sequence."""
        if key not in self.fields:
            self.fields[key] = draw()
        return self.fields[key]

    def _sign(self, key, rng):
        """A sign of +-1 drawn once for ``key`` and kept for the sequence."""
        return self._kept(key, lambda: float(rng.choice([-1.0, 1.0])))

    def _field(self, key, rng, h, w, cells):
        return self._drift(key, _FIELDS[self.variant](rng, h, w, cells))

    def _disparity(self, rng, depth):
        """A relative depth error linear in depth over the frame (the first-order effect of a
        shift of inverse depth), unit std over the finite pixels times a coefficient that
        drifts as the fields do (unit variance)."""
        b = self._drift("disparity", rng.normal())
        ok = np.isfinite(depth)
        g = np.zeros_like(depth)
        if ok.sum() > 1:
            d = depth[ok]
            g[ok] = (d - d.mean()) / max(d.std(), 1e-9)
        return b * g

    def _surface(self, rng, frame):
        """Per object of ``frame`` (its truth), a quadratic in its NOCS (zero mean and unit std
        over its pixels, coefficients drifting as the fields do) times the object's size over
        its depth: a relative depth error attached to the object's surface, which moves with
        it, as large in metres as the field's strength times the object's size (as the relief
        family's error is relative to the object, not to its distance); 0 off the objects."""
        g = np.zeros(frame.mask.shape)
        size = {o.instance_id: o.scale for o in frame.objects}
        for iid in np.unique(frame.mask[frame.mask > 0]):
            m = (frame.mask == iid) & np.isfinite(frame.depth)
            coef = self._drift(("surface", int(iid)), rng.normal(size=9))
            if not m.any():
                continue
            q = frame.nocs[m] - 0.5
            x, y, z = q.T
            v = np.stack([x, y, z, x * x, y * y, z * z, x * y, y * z, z * x], 1) @ coef
            g[m] = (v - v.mean()) / max(v.std(), 1e-9) * size[int(iid)] / frame.depth[m]
        return g

    def _shading(self, rng, frame):
        """The image's brightness from ``frame``'s truth: each pixel's albedo (one per object
        and one for the table, kept for the sequence) times its Lambertian shading, 0.3 + 0.7
        max(0, n.l), under a light from the camera's side (kept for the sequence); zero mean
        and unit std over the objects' pixels (the table off that mean by its own brightness),
        times a coefficient that drifts as the fields do (unit variance). A relative depth error
        that follows each surface's orientation and colour, one value over a plane of one
        albedo."""
        b = self._drift("shade", rng.normal())
        light = self._kept("light", lambda: (v := rng.normal(size=3) * [1.0, 1.0, 0.0]
                                             + [0.0, 0.0, -1.5]) / np.linalg.norm(v))
        n = _normals(frame)
        shade = 0.3 + 0.7 * np.clip(np.nan_to_num(n @ light, nan=0.5), 0.0, 1.0)
        ok = np.isfinite(frame.depth)
        albedo = np.zeros(frame.mask.shape)
        for sid in np.unique(frame.mask[ok]):
            albedo[frame.mask == sid] = self._kept(("albedo", int(sid)),
                                                   lambda: float(rng.uniform(0.2, 1.0)))
        on = ok & (frame.mask > 0) if np.sum(ok & (frame.mask > 0)) > 1 else ok
        g = np.zeros(frame.mask.shape)
        if on.sum() > 1:
            v = albedo * shade
            g[ok] = (v[ok] - v[on].mean()) / max(v[on].std(), 1e-9)
        return b * g

    def _segments(self, rng, frame, cells):
        """A field of ``cells`` drawn for each segment of ``frame``'s truth (each object, and
        the table) on its own, each drifting as the fields do: the error jumps at every
        silhouette."""
        h, w = frame.mask.shape
        out = np.zeros((h, w))
        for sid in np.unique(frame.mask):
            m = frame.mask == sid
            out[m] = self._drift(("segment", cells, int(sid)), _grid_field(rng, h, w, cells))[m]
        return out

    def _familiar(self, rng, frame):
        """Per object of ``frame``'s truth, -ln(size / typical size) / 0.3 (about unit std over
        the world's sizes) times a reliance drawn in 0.3..1 and kept for the sequence: the
        familiar-size cue of a network that judges distance partly from apparent size, so a
        larger object than typical is put nearer and a smaller one farther, by one relative
        error over each object (its relief with it); 0 off the objects."""
        k = self._kept("familiar", lambda: float(rng.uniform(0.3, 1.0)))
        size = {o.instance_id: o.scale for o in frame.objects}
        g = np.zeros(frame.mask.shape)
        for iid in np.unique(frame.mask[frame.mask > 0]):
            g[frame.mask == iid] = -k * np.log(size[int(iid)] / _TYPICAL_SIZE) / _SIZE_SPREAD
        return g

    def _grown(self, rng, frame, cells):
        """An image field of ``cells`` (drifting as the fields do) times each pixel's true
        depth over the objects' median true depth, up to 3: a relative error that grows with
        distance, as a monocular network's does."""
        h, w = frame.mask.shape
        return self._field(("depth", cells), rng, h, w, cells) * _depth_growth(frame)

    def _scene_field(self, rng, frame, cells):
        """A field fixed in the scene, as the surface of a fused map is wrong (a depth image
        rendered from a TSDF or mesh that the robot built over the sequence): four random
        sinusoids of the 3D point each pixel of ``frame``'s truth sees, in the first frame's
        camera coordinates (the scene's motion since then, from any object's true pose, undone),
        about ``cells`` periods across the view at the objects' median distance, unit std over
        the first frame's objects (over its finite pixels if it has none); kept for the
        sequence (a map's error does not renew with the view, so ``field_drift`` does not act
        on it). Returned as the relative error of an additive one in metres: the field times
        the first frame's median object depth over each pixel's true depth; 0 where the depth
        is not finite."""
        h, w = frame.mask.shape
        depth = frame.depth
        ok = np.isfinite(depth)
        cx, cy = frame.principal_point
        vv, uu = np.mgrid[0:h, 0:w]
        z = np.where(ok, depth, 0.0)
        pts = np.stack([z * (uu - cx) / frame.focal, z * (vv - cy) / frame.focal, z], -1)
        ref = min(frame.objects, key=lambda o: o.instance_id) if frame.objects else None
        first = self._kept("scene", lambda: (
            None if ref is None else (ref.instance_id, np.array(ref.rotation),
                                      np.array(ref.translation, float)),
            float(np.median(depth[ok & (frame.mask > 0)])) if np.any(ok & (frame.mask > 0))
            else float(np.median(depth[ok])) if ok.any() else 1.0))
        (anchor, zref) = first
        if anchor is not None:
            now = {o.instance_id: o for o in frame.objects}.get(anchor[0])
            if now is not None:  # x0 = R0 Rk^T (x - tk) + t0
                rel = anchor[1] @ np.asarray(now.rotation).T
                pts = (pts - np.asarray(now.translation, float)) @ rel.T + anchor[2]

        def draw():
            extent = zref * max(h, w) / frame.focal
            k = rng.normal(size=(4, 3)) * cells * np.pi / extent
            phase = rng.uniform(0, 2 * np.pi, 4)
            amp = rng.normal(size=4)
            on = ok & (frame.mask > 0) if np.sum(ok & (frame.mask > 0)) > 1 else ok
            v = np.cos(pts[on] @ k.T + phase) @ amp
            return k, phase, amp, max(float(v.std()), 1e-9) if on.sum() > 1 else 1.0

        k, phase, amp, norm = self._kept(("scene", cells), draw)
        g = np.zeros((h, w))
        g[ok] = (np.cos(pts[ok] @ k.T + phase) @ amp) / norm * zref / depth[ok]
        return g

    def _grazing_field(self, rng, frame):
        """A relative depth error that grows with the grazing angle: 1 - cos(theta), theta the
        angle between each pixel's true surface normal (from ``frame``'s truth) and its viewing
        ray (0 where the surface faces the camera, 1 edge-on), over its rms on the objects'
        pixels, times a coefficient that drifts as the fields do (unit variance; its sign
        random, so zero-mean over sequences): a depth network or sensor that errs more, and in
        one direction, the more obliquely it sees a surface (at an object's rims, on the
        table). Pixels without a normal (a segment one pixel wide) take the objects' median."""
        b = self._drift("grazing", rng.normal())
        s = _grazing(frame)
        ok = np.isfinite(frame.depth)
        on = ok & (frame.mask > 0) & np.isfinite(s)
        if on.sum() < 2:
            on = ok & np.isfinite(s)
        if on.sum() < 2:
            return np.zeros(frame.mask.shape)
        s = np.where(np.isfinite(s), s, np.median(s[on]))
        return b * np.where(ok, s, 0.0) / max(float(np.sqrt(np.mean(s[on] ** 2))), 1e-9)

    def _object(self, iid, rng):
        """Per-object errors: the shape mismatch persists, the relief error drifts slowly."""
        e = self.err
        ob = self.objects.get(iid)
        if ob is None:
            ob = {"shape": 1.0 + rng.uniform(-e.shape, e.shape, 3) if e.shape > 0 else np.ones(3),
                  "relief": float(rng.uniform(-e.relief, e.relief)) if e.relief > 0 else 0.0}
            self.objects[iid] = ob
            return ob
        if "shape" in self.renew and e.shape > 0:
            ob["shape"] = 1.0 + rng.uniform(-e.shape, e.shape, 3)
        if "relief" in self.renew and e.relief > 0:
            ob["relief"] = float(rng.uniform(-e.relief, e.relief))
        elif e.relief > 0:
            ob["relief"] = float(np.clip(ob["relief"] + rng.normal(0, 0.3 * e.relief),
                                         -e.relief, e.relief))
        return ob


def apply_errors(frame: Frame, state: ErrorState, rng: np.random.Generator) -> Frame:
    """The frame as the predictors would see it under ``state`` (which this call advances)."""
    e = state.err
    if ("offset" in state.renew or state.variant == "heldout13") and e.offset > 0:
        state.offset = float(rng.normal(0, e.offset))
    depth, nocs, mask = frame.depth.copy(), frame.nocs.copy(), frame.mask.copy()
    h, w = depth.shape
    finite = np.isfinite(depth)
    if state.variant == "heldout9" and e.nocs_pixel > 0:
        # The NOCS network a frame behind the depth: its NOCS and masks are the last frame's.
        last = state.fields.get("late")
        state.fields["late"] = (frame.nocs, frame.mask)
        if last is not None and last[1].shape == mask.shape:
            nocs, mask = last[0].copy(), last[1].copy()
    obj = mask > 0
    # Per-object geometry errors first: relief about the object's median (true) depth, NOCS
    # shape mismatch (over the instance's mask, which only heldout9's lag makes another).
    for iid in np.union1d(np.unique(frame.mask[frame.mask > 0]), np.unique(mask[obj])):
        m = mask == iid
        ob = state._object(int(iid), rng)
        if ob["relief"] and np.any(t := frame.mask == iid):
            zc = np.median(depth[t])
            depth[t] = zc + (1.0 + ob["relief"]) * (depth[t] - zc)
        if e.shape > 0:
            nocs[m] = 0.5 + (nocs[m] - 0.5) * ob["shape"]
    if state.variant == "heldout10" and e.relief > 0:
        depth = _sharpened(depth, frame.mask, state, rng, e.relief)
    if state.variant == "heldout13" and e.depth_pixel > 0:
        depth = _see_through(depth, frame, state, rng)
    if e.edge_px > 0:
        far = np.nanmax(depth) if finite.any() else 1.0
        filled = np.where(finite, depth, far).astype(np.float32)
        k = 2 * e.edge_px + 1
        blurred = cv2.GaussianBlur(filled, (2 * k + 1, 2 * k + 1), 0).astype(np.float64)
        grad = np.abs(cv2.Laplacian(filled, cv2.CV_32F))
        edges = (grad > 0.02 * filled).astype(np.uint8)
        band = cv2.dilate(edges, np.ones((k, k), np.uint8)).astype(bool) & finite
        if state.variant == "heldout5":
            # A halo: the blend towards the blurred depth decays with the distance from the edge.
            dist = cv2.distanceTransform((1 - edges).astype(np.uint8), cv2.DIST_L2, 3)
            share = np.exp(-dist / max(e.edge_px, 1)).astype(np.float64)
            halo = finite & (share > 0.02)
            depth[halo] = (1 - share[halo]) * depth[halo] + share[halo] * blurred[halo]
        elif state.variant == "heldout6":
            # The nearer surface spreads over the farther: the band takes its nearest depth.
            near = cv2.erode(filled, np.ones((k, k), np.uint8)).astype(np.float64)
            depth[band] = near[band]
        else:
            depth[band] = blurred[band]
        if e.flying > 0:
            lo = cv2.erode(filled, np.ones((k, k), np.uint8)).astype(np.float64)
            hi = cv2.dilate(filled, np.ones((k, k), np.uint8)).astype(np.float64)
            fly = band & (rng.random((h, w)) < e.flying)
            lam = rng.random(int(fly.sum()))
            depth[fly] = lo[fly] + lam * (hi[fly] - lo[fly])
    if e.nocs_blur_px > 0:
        k = 2 * e.nocs_blur_px + 1
        edge = cv2.morphologyEx(mask.astype(np.float32), cv2.MORPH_GRADIENT,
                                np.ones((3, 3), np.uint8)) > 0
        band = cv2.dilate(edge.astype(np.uint8), np.ones((k, k), np.uint8)).astype(bool) & obj
        blurred = cv2.GaussianBlur(nocs.astype(np.float32), (k, k), 0).astype(np.float64)
        nocs[band] = blurred[band]
    if e.mask_px > 0 and state.variant == "heldout12":
        mask, nocs = _contact_errors(mask, nocs, frame.depth, e.mask_px, rng)
        obj = mask > 0
    elif e.mask_px > 0:
        mask, nocs = _mask_errors(mask, nocs, e.mask_px, rng, state.variant, state)
        obj = mask > 0
    scale = state.scale
    if state.variant == "heldout3" and e.depth_scale > 0:
        scale *= float(np.exp(rng.normal(0, e.depth_scale)))
    depth = depth * scale + state.offset
    if state.variant == "heldout4" and e.depth_scale > 0:
        # Each object's distance misjudged anew in every frame (its relief with it).
        for iid in np.unique(frame.mask[frame.mask > 0]):
            depth[frame.mask == iid] *= float(np.exp(rng.normal(0, e.depth_scale / 5)))
    if e.field > 0:
        if state.variant == "heldout3":
            # The coarsest scale follows depth (an error affine in disparity), the rest the
            # image.
            total = state._disparity(rng, depth) + sum(
                state._field(("depth", c), rng, h, w, c) for c in e.field_cells[1:])
        elif state.variant == "heldout4":
            # The coarsest scale follows each object's surface, the rest the image.
            total = state._surface(rng, frame) + sum(
                state._field(("depth", c), rng, h, w, c) for c in e.field_cells[1:])
        elif state.variant == "heldout7":
            # The coarsest scale follows the image's brightness, the rest each segment.
            total = state._shading(rng, frame) + sum(
                state._segments(rng, frame, c) for c in e.field_cells[1:])
        elif state.variant == "heldout8":
            # The coarsest scale is the familiar-size cue, the rest grow with depth.
            total = state._familiar(rng, frame) + sum(
                state._grown(rng, frame, c) for c in e.field_cells[1:])
        elif state.variant == "heldout9":
            # Every scale fixed in the scene, additive in metres.
            total = sum(state._scene_field(rng, frame, c) for c in e.field_cells)
        elif state.variant == "heldout12":
            # One relative error for every scale, following the grazing angle.
            total = state._grazing_field(rng, frame) * np.sqrt(len(e.field_cells))
        else:
            total = sum(state._field(("depth", c), rng, h, w, c) for c in e.field_cells)
        depth *= 1.0 + e.field * total / np.sqrt(len(e.field_cells))
    if e.depth_pixel > 0:
        # heldout13's stereo noise: relative noise times the true depth over 1 m.
        grows = (np.nan_to_num(frame.depth, nan=1.0) if state.variant == "heldout13" else 1.0)
        depth *= 1.0 + e.depth_pixel * grows * rng.normal(size=(h, w))
    if e.nocs_field > 0:
        if state.variant == "heldout2":
            nocs = _twist(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout3":
            nocs = _bulge(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout4":
            nocs = _view_stretch(nocs, frame, state, rng, e.nocs_field)
        elif state.variant == "heldout5":
            nocs = _part_shift(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout6":
            nocs = _rim_shrink(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout7":
            nocs = _crop_stretch(nocs, frame, state, rng, e.nocs_field)
        elif state.variant == "heldout8":
            nocs = _azimuth_stretch(nocs, mask, frame, state, rng, e.nocs_field)
        elif state.variant == "heldout9":
            nocs = _ramp_pull(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout10":
            nocs = _bend(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout12":
            nocs = _roi_shift(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout13":
            nocs = _shape_warp(nocs, mask, state, rng, e.nocs_field)
        elif state.variant == "heldout":
            # Scaled to ``nocs_field`` rms on the objects, as the other variants' distortions:
            # unscaled, q^T W q with |q| < 0.5 moved the NOCS 8x less than the tuning field.
            warp = state.fields.setdefault("nocs_warp", rng.normal(0, 1, (3, 3)))
            q = nocs - 0.5
            bend = np.einsum("hwi,ij,hwj->hw", q, warp, q)
            rms = float(np.sqrt(np.mean(bend[obj] ** 2))) if obj.any() else 0.0
            bend *= e.nocs_field / max(rms, 1e-9)
            nocs = nocs + bend[..., None]
        else:
            for c in range(3):
                nocs[..., c] += e.nocs_field * state._field(("nocs", c), rng, h, w, 3)
    if state.variant == "heldout12" and e.nocs_pixel > 0:
        nocs = _roi_paste(nocs, mask)  # a 28x28 NOCS head's output pasted into each box
    if e.nocs_pixel > 0:
        nocs[obj] += rng.normal(0, e.nocs_pixel, (int(obj.sum()), 3))
    if e.nocs_outliers > 0:
        out = obj & (rng.random((h, w)) < e.nocs_outliers)
        nocs[out] = rng.random((int(out.sum()), 3))
    for _ in range(e.blobs):
        cy, cx = rng.integers(0, h), rng.integers(0, w)
        ax = (int(rng.integers(5, max(6, w // 12))), int(rng.integers(5, max(6, h // 12))))
        blob = np.zeros((h, w), np.uint8)
        cv2.ellipse(blob, (int(cx), int(cy)), ax, float(rng.uniform(0, 180)), 0, 360, 1, -1)
        blob = blob.astype(bool) & (mask == 0) & np.isfinite(depth)
        mask[blob] = int(mask.max()) + 1
        nocs[blob] = np.clip(
            0.5 + 0.3 * np.stack([_grid_field(rng, h, w, 2)[blob] for _ in range(3)], -1), 0, 1
        )
    depth[~np.isfinite(depth) | (depth <= 0)] = np.nan
    if state.variant == "heldout8" and e.depth_pixel > 0:
        depth = _disparity8(depth)
    if state.variant == "heldout9" and e.depth_pixel > 0:
        depth = _low_res(depth, state._kept("low_res", lambda: int(rng.choice([2, 4]))))
    if state.variant == "heldout10" and e.depth_pixel > 0:
        depth = _holes(depth, frame.mask, rng)
    nocs[mask > 0] = np.clip(nocs[mask > 0], 0.0, 1.0)
    if state.variant == "heldout4" and e.nocs_pixel > 0:
        nocs = np.round(nocs * 255.0) / 255.0  # as an rgb8 NOCS image holds them
    # The NOCS image through JPEG: heldout8's at a quality in 80..95, the opt-in family's in
    # 75..95 (kept for the sequence).
    lowest = (80 if state.variant == "heldout8" and e.nocs_pixel > 0
              else 75 if e.nocs_jpeg else None)
    if lowest is not None:
        nocs[mask == 0] = 0.0
        nocs = _jpeg(nocs, state._kept("jpeg", lambda: int(rng.integers(lowest, 96))))
    nocs[mask == 0] = 0.0
    if state.variant == "heldout9" and e.mask_px > 0:
        # The camera's principal point is not the image centre the estimator assumes.
        dx, dy = state._kept("principal", lambda: tuple(
            int(v) for v in np.round(rng.uniform(-1, 1, 2) * 0.01 * e.mask_px / 3 * [w, h])))
        depth, nocs, mask = (_shifted(depth, dx, dy, np.nan), _shifted(nocs, dx, dy, 0.0),
                             _shifted(mask, dx, dy, 0))
        cx, cy = frame.principal_point
        return replace(frame, depth=depth, nocs=nocs, mask=mask, principal_point=(cx + dx,
                                                                                 cy + dy))
    if state.variant == "heldout10" and e.mask_px > 0:
        # A tracker's id switch, then a camera that is no pinhole centred on the image.
        mask = _id_switch(mask, [o.instance_id for o in frame.objects], rng)
        return _through_lens(replace(frame, depth=depth, nocs=nocs, mask=mask), frame.mask,
                             state, rng, e.mask_px)
    return replace(frame, depth=depth, nocs=nocs, mask=mask)


def _twist(nocs, mask, state, rng, rms):
    """Each object's NOCS twisted about a random axis through the centre (the angle grows along
    the axis), scaled to ``rms`` per NOCS axis (as the tuning variant's field per channel): a
    smooth distortion that persists across a sequence. Linearised: each point moves
    perpendicular to its position, so it also moves outward at second order."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        axis = state._kept(("twist", int(iid)),
                           lambda: (v := rng.normal(size=3)) / np.linalg.norm(v))
        q = nocs[m] - 0.5
        move = np.cross(axis, q) * (q @ axis)[:, None]
        out[m] = nocs[m] + rms * move / max(np.sqrt(np.mean(move ** 2)), 1e-9)
    return out


def _bulge(nocs, mask, state, rng, rms):
    """Each object's NOCS moved radially from the centre, outward where they are far from it
    and inward where near (or the reverse, per object, for the whole sequence), scaled to
    ``rms`` per NOCS axis: a NOCS network that stretches or squashes the extremes of the shape."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        sign = state._sign(("bulge", int(iid)), rng)
        q = nocs[m] - 0.5
        r2 = np.sum(q * q, axis=1)
        move = q * (r2 / max(r2.mean(), 1e-12) - 1.0)[:, None]
        out[m] = nocs[m] + sign * rms * move / max(np.sqrt(np.mean(move ** 2)), 1e-9)
    return out


def _part_shift(nocs, mask, state, rng, rms):
    """Each object's NOCS on one side of a random plane through its centre displaced by a
    vector (both drawn once per object for the sequence), scaled so that the displacement is
    ``rms`` per NOCS axis over the object: a part of the shape put a little off."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        normal, shift = state._kept(
            ("part", int(iid)),
            lambda: ((v := rng.normal(size=3)) / np.linalg.norm(v), rng.normal(size=3)))
        q = nocs[m] - 0.5
        side = q @ normal > 0
        move = np.where(side[:, None], shift[None, :], 0.0)
        out[m] = nocs[m] + rms * move / max(np.sqrt(np.mean(move ** 2)), 1e-9)
    return out


def _rim_shrink(nocs, mask, state, rng, rms):
    """Each object's NOCS moved towards its centre (or away from it: a sign per object for the
    sequence) by a share that decays with the distance from its silhouette over a few pixels,
    scaled to ``rms`` per NOCS axis over the object: a network that regresses to the mean where
    its view of the object ends."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        sign = state._sign(("rim", int(iid)), rng)
        reach = state._kept(("rim_px", int(iid)), lambda: float(rng.uniform(2.0, 6.0)))
        dist = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, 3)[m]
        q = nocs[m] - nocs[m].mean(0)
        move = -q * np.exp(-(dist - 1.0) / reach)[:, None]
        out[m] = nocs[m] + sign * rms * move / max(np.sqrt(np.mean(move ** 2)), 1e-9)
    return out


def _mask_head(m, rng):
    """Instance mask m as a 28x28 mask head gives it: its box resampled to 28x28 (area) and
    back (bilinear), thresholded at a level drawn in 0.3-0.7 (the head's bias, per instance)."""
    box = _box(m)
    if box is None:
        return m.astype(np.uint8)
    y0, y1, x0, x1 = box
    crop = m[y0:y1, x0:x1].astype(np.float32)
    small = cv2.resize(crop, (28, 28), interpolation=cv2.INTER_AREA)
    back = cv2.resize(small, (x1 - x0, y1 - y0), interpolation=cv2.INTER_LINEAR)
    out = np.zeros(m.shape, np.uint8)
    out[y0:y1, x0:x1] = back > rng.uniform(0.3, 0.7)
    return out


def _normals(frame):
    """Unit surface normals (H, W, 3) of ``frame``'s truth in the camera frame, facing the
    camera, from differences between neighbouring pixels of one segment (forward, else
    backward); NaN where a pixel has no such neighbour along a row or a column."""
    h, w = frame.depth.shape
    cx, cy = frame.principal_point
    vv, uu = np.mgrid[0:h, 0:w]
    z = frame.depth
    p = np.stack([z * (uu - cx) / frame.focal, z * (vv - cy) / frame.focal, z], -1)
    seg = np.where(np.isfinite(z), frame.mask.astype(np.int64), -1)

    def tangent(axis):
        d = np.diff(p, axis=axis)
        same = (np.diff(seg, axis=axis) == 0) & (np.take(seg, range(1, seg.shape[axis]),
                                                         axis=axis) >= 0)
        d[~same] = np.nan
        pad = [(0, 0)] * 3
        pad[axis] = (0, 1)
        fwd = np.pad(d, pad, constant_values=np.nan)
        pad[axis] = (1, 0)
        bwd = np.pad(d, pad, constant_values=np.nan)
        return np.where(np.isfinite(fwd), fwd, bwd)

    n = np.cross(tangent(1), tangent(0))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return n * -np.sign(np.sum(n * p, axis=-1, keepdims=True))


def _crop_stretch(nocs, frame, state, rng, rms):
    """Each object's NOCS stretched or squashed (a sign per object, for the whole sequence)
    along the longer image axis of its (true) box, mapped into the object's frame, by a factor
    1 +- 3 ``rms`` min(1, long / short - 1) (+-9% at the base bound for a box twice as long as
    wide, as the relief and shape families' +-10%): a NOCS head that sees each crop resized to
    a square. The direction is fixed in the camera frame, across the viewing axis."""
    out = nocs.copy()
    rot = {o.instance_id: o.rotation for o in frame.objects}
    for iid in np.unique(frame.mask[frame.mask > 0]):
        m = frame.mask == iid
        ys, xs = np.nonzero(m)
        long, short = sorted((np.ptp(xs) + 1, np.ptp(ys) + 1), reverse=True)
        axis = rot[int(iid)][0 if np.ptp(xs) >= np.ptp(ys) else 1]  # image axis, object frame
        axis = axis / np.linalg.norm(axis)
        sign = state._sign(("crop", int(iid)), rng)
        q = nocs[m] - nocs[m].mean(0)
        move = (q @ axis)[:, None] * axis
        out[m] = nocs[m] + sign * 3.0 * rms * min(1.0, long / short - 1.0) * move
    return out


def _bleed(mask, new, nocs, px, state, rng):
    """Where two instances of the true ``mask`` touch, one of them (drawn once per pair and
    kept for the sequence) takes the other's pixels within a width of 1..``px`` drawn anew in
    every frame, with the NOCS of its own nearest pixel: the neighbour's surface labelled, and
    coordinated, as the wrong object."""
    ids = [int(i) for i in np.unique(mask[mask > 0])]
    for a in ids:
        dist, (iy, ix) = ndimage.distance_transform_edt(mask != a, return_indices=True)
        for b in ids:
            if b == a or not np.any((mask == b) & (dist <= 1.5)):
                continue
            if state._kept(("bleed", min(a, b), max(a, b)),
                           lambda: int(rng.choice([a, b]))) != a:
                continue
            stolen = (mask == b) & (new == b) & (dist <= int(rng.integers(1, px + 1)))
            new[stolen] = a
            nocs[stolen] = nocs[iy[stolen], ix[stolen]]
    return new, nocs


def _depth_growth(frame):
    """Each pixel's true depth over the median true depth of ``frame``'s objects (of its
    finite pixels if it has none), at most 3; 1 where the depth is not finite."""
    ok = np.isfinite(frame.depth)
    on = ok & (frame.mask > 0)
    ref = np.median(frame.depth[on if on.any() else ok]) if ok.any() else 1.0
    return np.where(ok, np.minimum(np.nan_to_num(frame.depth, nan=ref) / ref, 3.0), 1.0)


def _disparity8(depth):
    """``depth`` as read back from an 8-bit image of its disparity normalised over the frame's
    finite pixels (0 at the farthest, 255 at the nearest): 1 / depth rounded to 256 levels."""
    ok = np.isfinite(depth)
    if ok.sum() < 2:
        return depth
    inv = 1.0 / depth[ok]
    lo, hi = inv.min(), inv.max()
    if not hi > lo:
        return depth
    step = (hi - lo) / 255.0
    out = depth.copy()
    out[ok] = 1.0 / (lo + np.round((inv - lo) / step) * step)
    return out


def _jpeg(nocs, quality, full_chroma=False):
    """The NOCS image (H, W, 3 in [0, 1]) as an rgb8 image sent through JPEG at ``quality``
    (OpenCV's encoder, as ROS's compressed image transport uses: 8 bits, 8x8 blocks, chroma
    subsampled 2x2, or kept whole with ``full_chroma``) and decoded."""
    img = np.round(np.clip(nocs, 0.0, 1.0) * 255.0).astype(np.uint8)[..., ::-1]
    how = [cv2.IMWRITE_JPEG_QUALITY, int(quality)]
    if full_chroma:
        how += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img), how)
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1].astype(np.float64) / 255.0


def _symmetry_axis(category):
    """(x, z) NOCS of the vertical axis of a category's main part (its first primitive): the
    symmetry axis of a can, bowl or bottle, of a mug's body."""
    from .render import _NORMALISED

    c = _NORMALISED[category][0][0][1]
    return 0.5 + float(c[0]), 0.5 + float(c[2])


def _azimuth_stretch(nocs, mask, frame, state, rng, rms):
    """Each object's NOCS turned about the vertical axis of its main part by k sin(phi), phi
    their azimuth from the direction the object is seen from (in its frame, from ``frame``'s
    truth), k = +-2 ``rms`` (a sign per object for the sequence): the azimuth stretched by 1 + k
    where the object faces the camera and squeezed by 1 - k on its far side, smoothly all
    round (a top's or a bowl's inside has no seam). The seen side is spread over too wide or
    too narrow an angle, as by a category model unsure where it is about the symmetry axis.
    Height and distance from the axis are kept, so on a can, bowl or bottle the NOCS stay on
    the shape. (+-6% at the base bound: 0.003 per axis, as heldout4's and heldout7's stretches
    move them; a first version, the azimuth times 1 +- 3 ``rms`` as their factor, moved them
    0.009, three times as much, and had a seam behind the axis.)"""
    out = nocs.copy()
    obs = {o.instance_id: o for o in frame.objects}
    for iid in np.unique(mask[mask > 0]):
        ob = obs.get(int(iid))
        if ob is None:
            continue
        m = mask == iid
        ax, az = _symmetry_axis(ob.category)
        view = ob.rotation.T @ -np.asarray(ob.translation, float)  # camera, object frame
        seen = np.arctan2(view[2], view[0])
        dx, dz = nocs[m, 0] - ax, nocs[m, 2] - az
        r = np.hypot(dx, dz)
        phi = np.angle(np.exp(1j * (np.arctan2(dz, dx) - seen)))
        k = state._sign(("azimuth", int(iid)), rng) * 2.0 * rms
        turned = seen + phi + k * np.sin(phi)
        out[m, 0] = ax + r * np.cos(turned)
        out[m, 2] = az + r * np.sin(turned)
    return out


def _low_res(depth, k):
    """``depth`` as a network run at 1 / ``k`` of the image's size gives it: area-averaged down
    to that size over the finite pixels, then brought back up bilinearly (NaN where under half
    of what is interpolated was finite): depth mixed across every silhouette over a band about
    ``k`` pixels wide, relief finer than ``k`` pixels smoothed away."""
    h, w = depth.shape
    ok = np.isfinite(depth)
    small = (max(w // k, 1), max(h // k, 1))
    num = cv2.resize(np.where(ok, depth, 0.0), small, interpolation=cv2.INTER_AREA)
    den = cv2.resize(ok.astype(np.float64), small, interpolation=cv2.INTER_AREA)
    num = cv2.resize(num, (w, h), interpolation=cv2.INTER_LINEAR)
    den = cv2.resize(den, (w, h), interpolation=cv2.INTER_LINEAR)
    return np.where(den >= 0.5, num / np.maximum(den, 1e-12), np.nan)


def _ramp_pull(nocs, mask, state, rng, rms):
    """Each object's NOCS pulled towards (or pushed from: a sign per object for the sequence)
    their best affine function of the image coordinates over its mask, by a share 3 ``rms``
    (+-9% at the base bound, as the relief and shape families' +-10%): a NOCS network with a
    spectral bias, which under- or overestimates how the NOCS curve across the image (the
    curvature that carries the object's relief and the perspective), while the ramp across
    the object, its extent and its tilt, stay."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        ys, xs = np.nonzero(m)
        if len(ys) < 4:
            continue
        a = np.column_stack([np.ones(len(ys)), xs - xs.mean(), ys - ys.mean()])
        ramp = a @ np.linalg.lstsq(a, nocs[m], rcond=None)[0]
        out[m] = nocs[m] - state._sign(("ramp", int(iid)), rng) * 3.0 * rms * (nocs[m] - ramp)
    return out


def _shifted(img, dx, dy, fill):
    """``img`` moved by ``dx`` pixels right and ``dy`` down (integers), ``fill`` where it
    uncovers: what a camera whose principal point is off the image centre by (dx, dy) sees,
    against one whose is on it."""
    out = np.full_like(img, fill)
    h, w = img.shape[:2]
    src = img[max(-dy, 0):h - max(dy, 0), max(-dx, 0):w - max(dx, 0)]
    out[max(dy, 0):max(dy, 0) + src.shape[0], max(dx, 0):max(dx, 0) + src.shape[1]] = src
    return out


def _sharpened(depth, truth, state, rng, bound):
    """Each object's (of the true mask ``truth``) depth + a (depth - its blur over the
    object's finite pixels, so that the background does not leak in), a uniform in +-3
    ``bound`` per object, kept for the sequence: a depth network that sharpens (a > 0) or
    flattens (a < 0) relief."""
    out = depth.copy()
    for iid in np.unique(truth[truth > 0]):
        m = (truth == iid) & np.isfinite(depth)
        a = state._kept(("sharpen", int(iid)), lambda: float(rng.uniform(-3 * bound, 3 * bound)))
        if m.sum() < 4:
            continue
        out[m] = depth[m] + a * (depth[m] - _masked_blur(depth, m))
    return out


def _masked_blur(depth, m):
    """``depth``'s Gaussian blur over the pixels ``m`` alone (sigma a third of their radius;
    the blur of ``m`` divides it), at those pixels: computed over their box widened by the
    kernel's reach, which is what a blur of the whole image gives there."""
    sigma = max(np.sqrt(m.sum() / np.pi) / 3.0, 0.5)
    ys, xs = np.nonzero(m)
    pad = int(np.ceil(4 * sigma)) + 2
    box = (slice(max(ys.min() - pad, 0), ys.max() + pad + 1),
           slice(max(xs.min() - pad, 0), xs.max() + pad + 1))
    num = cv2.GaussianBlur(np.where(m, depth, 0.0)[box], (0, 0), sigma)
    den = cv2.GaussianBlur(m[box].astype(np.float64), (0, 0), sigma)
    return num[m[box]] / den[m[box]]


def _holes(depth, truth, rng):
    """``depth`` with one to three elliptic holes (NaN) on each object of the true mask
    ``truth``, together up to a share drawn in 0..10% of its pixels, drawn anew in every call:
    a specular or dark surface that a sensor or network returns no depth for."""
    out = depth.copy()
    for iid in np.unique(truth[truth > 0]):
        m = truth == iid
        n, share = int(rng.integers(1, 4)), float(rng.uniform(0.0, 0.1))
        ys, xs = np.nonzero(m)
        holes = np.zeros(m.shape, np.uint8)
        for _ in range(n):
            k, aspect, angle = rng.integers(len(ys)), rng.uniform(0.5, 2.0), rng.uniform(0, 180)
            r = np.sqrt(share * len(ys) / n / np.pi) - 0.5  # a drawn ellipse's rim, added
            axes = (int(round(r * np.sqrt(aspect))), int(round(r / np.sqrt(aspect))))
            if min(axes) > 0:
                cv2.ellipse(holes, (int(xs[k]), int(ys[k])), axes, float(angle), 0, 360, 1, -1)
        out[(holes > 0) & m] = np.nan
    return out


def _see_through(depth, frame, state, rng):
    """``depth`` where the see-through objects (each with a probability of 0.15, kept for the
    sequence) read the table behind them, over an ellipse of about a share in 0.2..0.5 of their
    pixels (kept) centred at one of their pixels drawn anew in every frame: glass or a specular
    surface that a sensor or network sees through. The table is the plane through the truth's
    background; only pixels whose ray meets it behind the object change."""
    bg = (frame.mask == 0) & np.isfinite(frame.depth)
    if bg.sum() < 3:
        return depth
    behind = None  # the table's depth, fitted once a frame has a see-through object
    out = depth.copy()
    for iid in np.unique(frame.mask[frame.mask > 0]):
        if not state._kept(("see_through", int(iid)), lambda: bool(rng.random() < 0.15)):
            continue
        if behind is None:
            behind = _table_depth(frame, bg)
        share = state._kept(("see_share", int(iid)), lambda: float(rng.uniform(0.2, 0.5)))
        m = frame.mask == iid
        ys, xs = np.nonzero(m)
        k, aspect, angle = rng.integers(len(ys)), rng.uniform(0.5, 2.0), rng.uniform(0, 180)
        r = np.sqrt(share * len(ys) / np.pi)
        axes = (max(1, int(round(r * np.sqrt(aspect)))), max(1, int(round(r / np.sqrt(aspect)))))
        ellipse = np.zeros(m.shape, np.uint8)
        cv2.ellipse(ellipse, (int(xs[k]), int(ys[k])), axes, float(angle), 0, 360, 1, -1)
        through = (ellipse > 0) & m & np.isfinite(behind) & (behind > frame.depth)
        out[through] = behind[through]
    return out


def _table_depth(frame, bg):
    """(H, W): the depth at which each pixel's ray meets the plane fitted to the truth's
    background pixels ``bg`` (the table), inf or negative where it does not meet it ahead."""
    h, w = frame.mask.shape
    cx, cy = frame.principal_point
    vv, uu = np.mgrid[0:h, 0:w]
    rays = np.stack([(uu - cx) / frame.focal, (vv - cy) / frame.focal, np.ones((h, w))], -1)
    pts = rays[bg] * frame.depth[bg][:, None]
    centre = pts.mean(0)
    normal = np.linalg.svd(pts - centre, full_matrices=False)[2][-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return (centre @ normal) / (rays @ normal)


def _shape_warp(nocs, mask, state, rng, rms):
    """Each object's NOCS moved by a smooth warp of NOCS space kept for the sequence: four
    Gaussian bumps of random centre in the unit cube, width in 0.25..0.5 and direction, scaled
    to ``rms`` per axis over the cube. The category's typical shape in place of the instance's:
    a deformation that turns with the object, not one fixed in the image."""
    def draw():
        centres, widths = rng.random((4, 3)), rng.uniform(0.25, 0.5, 4)
        grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 9)] * 3), -1).reshape(-1, 3)
        amp = rng.normal(size=(4, 3))
        amp /= max(float(np.sqrt(np.mean(_bumps(grid, centres, widths, amp) ** 2))), 1e-9)
        return centres, widths, amp

    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        out[m] = nocs[m] + rms * _bumps(nocs[m], *state._kept(("warp", int(iid)), draw))
    return out


def _bumps(p, centres, widths, amp):
    """(n, 3): the displacement at NOCS points ``p`` of Gaussian bumps at ``centres`` of
    ``widths`` and vector amplitudes ``amp``."""
    d2 = ((p[:, None, :] - centres[None]) ** 2).sum(-1)
    return np.exp(-d2 / (2 * widths ** 2)) @ amp


def _bend(nocs, mask, state, rng, rms):
    """Each object's NOCS bent along its up axis (x += b (y - 0.5)^2) and tapered (x and z
    about 0.5 times 1 + c (y - 0.5)), b in +-12 ``rms`` and c in +-6 ``rms`` (uniform, per
    object for the sequence), so that either moves the ends (y - 0.5 = +-0.5) by up to 3 ``rms``
    (+-9% at the base bound, as heldout4's stretch): a category prior whose shape bends and
    narrows where the instance's does not."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        b, c = state._kept(("bend", int(iid)),
                           lambda: tuple(rng.uniform(-1, 1, 2) * [12 * rms, 6 * rms]))
        q = nocs[m] - 0.5
        out[m, 0] = 0.5 + q[:, 0] * (1.0 + c * q[:, 1]) + b * q[:, 1] ** 2
        out[m, 2] = 0.5 + q[:, 2] * (1.0 + c * q[:, 1])
    return out


def _grazing(frame):
    """1 - cos(theta) at each pixel of ``frame``'s truth, theta the angle between its surface
    normal (:func:`_normals`) and its viewing ray: 0 facing the camera, 1 edge-on; NaN where
    the normal is."""
    h, w = frame.depth.shape
    cx, cy = frame.principal_point
    vv, uu = np.mgrid[0:h, 0:w]
    ray = np.stack([(uu - cx) / frame.focal, (vv - cy) / frame.focal, np.ones((h, w))], -1)
    ray /= np.linalg.norm(ray, axis=-1, keepdims=True)
    return 1.0 - np.abs(np.sum(_normals(frame) * ray, axis=-1))


def _box(m):
    """(y0, y1, x0, x1) of the pixels ``m``, ends exclusive; None if there are none."""
    ys, xs = np.nonzero(m)
    if len(ys) == 0:
        return None
    return ys.min(), ys.max() + 1, xs.min(), xs.max() + 1


def _roi_shift(nocs, mask, state, rng, rms):
    """Each object's NOCS map moved within its mask by a shift of its box's diagonal times
    ``rms`` / 2 per image axis (a Gaussian that drifts as the fields do, kept for the sequence
    without drift): pixel u takes the NOCS of u + shift, bilinearly, the object's NOCS carried
    out past its outline by the nearest pixel's; the mask stays. A NOCS head that predicts in
    its region of interest's frame and is pasted into a box a little off the one it saw (box
    regression jitter), while the mask comes from another head or segmenter: each object's
    NOCS misregistered against its depth by a few pixels in a random direction."""
    out = nocs.copy()
    h, w = mask.shape
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        y0, y1, x0, x1 = _box(m)
        shift = state._drift(("roi_shift", int(iid)), rng.normal(size=2)) * 0.5 * rms * np.hypot(
            y1 - y0, x1 - x0)
        pad = int(np.ceil(np.abs(shift).max())) + 2
        sy, sx = slice(max(y0 - pad, 0), min(y1 + pad, h)), slice(max(x0 - pad, 0),
                                                                  min(x1 + pad, w))
        sub = m[sy, sx]
        _, (iy, ix) = ndimage.distance_transform_edt(~sub, return_indices=True)
        filled = nocs[sy, sx][iy, ix].astype(np.float32)
        vv, uu = np.mgrid[0:sub.shape[0], 0:sub.shape[1]].astype(np.float32)
        moved = cv2.remap(filled, uu + np.float32(shift[0]), vv + np.float32(shift[1]),
                          cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        out[sy, sx][sub] = moved[sub]
    return out


def _roi_paste(nocs, mask, cells=28):
    """Each object's NOCS as a NOCS head gives them that predicts them on a ``cells`` x
    ``cells`` grid over the object's box (each cell the mean over the object's pixels in it,
    a cell without any the nearest cell's) and is pasted back into the box by nearest
    neighbour: blocks of the box's size over ``cells`` pixels (none where the box is under
    ``cells`` pixels across)."""
    out = nocs.copy()
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        y0, y1, x0, x1 = _box(m)
        sub = m[y0:y1, x0:x1].astype(np.float32)
        grid = (cells, cells)
        den = cv2.resize(sub, grid, interpolation=cv2.INTER_AREA)
        num = cv2.resize(nocs[y0:y1, x0:x1].astype(np.float32) * sub[..., None], grid,
                         interpolation=cv2.INTER_AREA)
        has = den > 1e-6
        small = num / np.maximum(den, 1e-6)[..., None]
        _, (iy, ix) = ndimage.distance_transform_edt(~has, return_indices=True)
        small = small[iy, ix]
        back = cv2.resize(small, (x1 - x0, y1 - y0), interpolation=cv2.INTER_NEAREST)
        out[y0:y1, x0:x1][m[y0:y1, x0:x1]] = back[m[y0:y1, x0:x1]]
    return out


def _contact_errors(mask, nocs, depth, px, rng, tol=0.02):
    """Each instance's mask eroded or dilated by a width drawn anew in every frame in
    -2 ``px``..2 ``px``, but only where its outline meets the background at about its own
    depth (within ``tol`` of it, from the true ``depth``): where the object stands on the
    table. Its outline against a farther background stays. Grown pixels keep the table's
    depth and take the NOCS of the object's nearest pixel; eroded ones leave the instance. A
    segmenter unsure where an object ends and the surface it touches begins (a base, a
    contact shadow), sure at an occluding contour."""
    new = mask.copy()
    finite = np.isfinite(depth)
    z = np.where(finite, depth, np.inf)
    background = (mask == 0) & finite
    dist_bg, (by, bx) = ndimage.distance_transform_edt(~background, return_indices=True)
    for iid in np.unique(mask[mask > 0]):
        m = mask == iid
        r = int(rng.integers(-2 * px, 2 * px + 1))
        if r > 0:
            dist, (iy, ix) = ndimage.distance_transform_edt(~m, return_indices=True)
            near = z[iy, ix]
            grow = background & (new == 0) & (dist <= r) & (np.abs(z - near) <= tol * near)
            new[grow] = iid
            nocs[grow] = nocs[iy[grow], ix[grow]]
        elif r < 0:
            near = z[by, bx]
            cut = m & finite & (dist_bg <= -r) & (np.abs(near - z) <= tol * z)
            new[cut] = 0
    return new, nocs


def _id_switch(mask, ids, rng, p=0.05):
    """``mask`` with, at probability ``p``, two of the instances ``ids`` that it shows
    exchanging their ids (a tracker's id switch, for this frame only)."""
    shown = [i for i in ids if np.any(mask == i)]
    if rng.random() >= p or len(shown) < 2:
        return mask
    a, b = rng.choice(shown, 2, replace=False)
    out = mask.copy()
    out[mask == a], out[mask == b] = b, a
    return out


def _undistort(xd, yd, k1, k2):
    """The normalised point (x, y) that the radial distortion x (1 + k1 r^2 + k2 r^4) takes
    to (xd, yd), by fixed-point iteration (a contraction for the small k1, k2 drawn here)."""
    x, y = xd, yd
    for _ in range(10):
        r2 = x * x + y * y
        g = 1.0 + k1 * r2 + k2 * r2 * r2
        x, y = xd / g, yd / g
    return x, y


def _lens_maps(shape, focal, centre, true_centre, k1, k2):
    """For each pixel of an image taken through a lens of radial distortion (k1, k2) about
    ``true_centre``, where a pinhole image rendered about ``centre`` holds what it sees
    (float32 maps for cv2.remap)."""
    vv, uu = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    x, y = _undistort((uu - true_centre[0]) / focal, (vv - true_centre[1]) / focal, k1, k2)
    return ((centre[0] + focal * x).astype(np.float32),
            (centre[1] + focal * y).astype(np.float32))


def _one_segment(label, mx, my):
    """Whether the four pixels about each point (mx, my) are in the image and share one
    ``label`` that is not negative."""
    h, w = label.shape
    x0, y0 = np.floor(mx).astype(np.int64), np.floor(my).astype(np.int64)
    inside = (x0 >= 0) & (x0 < w - 1) & (y0 >= 0) & (y0 < h - 1)
    x0, y0 = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
    first = label[y0, x0]
    same = [label[y0 + dy, x0 + dx] == first for dy, dx in ((0, 1), (1, 0), (1, 1))]
    return inside & (first >= 0) & same[0] & same[1] & same[2]


def _remapped(depth, nocs, mask, segments, mx, my, exact=False):
    """depth, NOCS and mask resampled at (mx, my): bilinearly where the four pixels about a
    point are of one of ``segments`` and of finite depth, else from the nearest one (the mask
    always); outside the image NaN depth, NOCS 0 and mask 0. OpenCV's bilinear weights are
    quantised to 1/32 pixel, which leaves points that move less than 1/64 where they were;
    ``exact`` weighs in float64 instead (heldout10 keeps OpenCV's, as it was evaluated)."""
    def at(img, how, fill=0.0):
        if exact and how == cv2.INTER_LINEAR:
            return _bilinear(img, mx, my)
        return cv2.remap(img, mx.astype(np.float32), my.astype(np.float32), how,
                         borderMode=cv2.BORDER_CONSTANT, borderValue=fill)

    ok = np.isfinite(depth)
    smooth = _one_segment(np.where(ok, segments, -1.0), mx, my)
    depth = np.where(smooth, at(np.where(ok, depth, 0.0), cv2.INTER_LINEAR),
                     at(depth, cv2.INTER_NEAREST, np.nan))
    nocs = np.where(smooth[..., None], at(nocs, cv2.INTER_LINEAR), at(nocs, cv2.INTER_NEAREST))
    return depth, nocs, at(mask, cv2.INTER_NEAREST, 0)


def _bilinear(img, mx, my):
    """``img`` (H, W[, C]) at the points (mx, my) by bilinear weights in float64 (points off the
    image read its nearest edge pixels; :func:`_remapped` uses only those inside)."""
    at = [my, mx]
    if img.ndim == 2:
        return ndimage.map_coordinates(img, at, order=1, mode="nearest")
    return np.stack([ndimage.map_coordinates(img[..., c], at, order=1, mode="nearest")
                     for c in range(img.shape[2])], -1)


def _through_lens(seen, truth, state, rng, px):
    """The frame ``seen`` (its depth, NOCS and mask rendered through a pinhole about its
    principal point) as a camera takes it whose residual radial distortion, k1 uniform in
    +-0.02 ``px`` / 3 and k2 = -k1 / 4, and whose principal point, off by a Gaussian of 0.6%
    of the image's size per axis times ``px`` / 3, are kept for the sequence; the frame's
    ``principal_point`` is the true one. ``truth`` (the true mask) with ``seen``'s marks the
    segments not to interpolate across."""
    h, w = seen.mask.shape
    k1, dx, dy = state._kept("lens", lambda: (
        float(rng.uniform(-1, 1) * 0.02 * px / 3),
        *(float(v) for v in rng.normal(0, 0.006 * px / 3, 2) * [w, h])))
    cx, cy = seen.principal_point
    mx, my = _lens_maps((h, w), seen.focal, (cx, cy), (cx + dx, cy + dy), k1, -k1 / 4)
    return replace(_taken_at(seen, truth, mx, my, exact=False), principal_point=(cx + dx, cy + dy))


def _taken_at(seen: Frame, truth, mx, my, exact: bool) -> Frame:
    """The frame ``seen`` resampled at (mx, my) (:func:`_remapped`), its NOCS 0 off the masks;
    ``truth`` (the true mask) with ``seen``'s marks the segments not to interpolate across."""
    segments = truth.astype(np.float64) * (float(seen.mask.max()) + 1.0) + seen.mask
    depth, nocs, mask = _remapped(seen.depth, seen.nocs, seen.mask, segments, mx, my, exact)
    nocs[mask == 0] = 0.0
    return replace(seen, depth=depth, nocs=nocs, mask=mask)


def _boxed(m, px, rng):
    """Instance mask m as a box-based detector's mask head gives it: grown by 0..``px`` pixels
    (the head's leak into the background) and cut by its detection box, each side of which is
    the true box's moved by -``px``..``px`` (a straight truncation where the box falls short)."""
    ys, xs = np.nonzero(m)
    if len(ys) == 0:
        return m.astype(np.uint8)
    out = m.astype(np.uint8)
    if r := int(rng.integers(0, px + 1)):
        out = cv2.dilate(out, cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1,) * 2))
    d = rng.integers(-px, px + 1, 4)
    y0, y1 = max(ys.min() - d[0], 0), max(ys.max() + 1 + d[1], 0)
    x0, x1 = max(xs.min() - d[2], 0), max(xs.max() + 1 + d[3], 0)
    box = np.zeros_like(out)
    box[y0:y1, x0:x1] = 1
    return out & box


def _view_stretch(nocs, frame, state, rng, rms):
    """Each object's NOCS stretched or flattened (per object, for the whole sequence) along the
    NOCS direction that depth follows on the object (the viewing axis in its frame, from the
    ``frame``'s truth, so the error turns with the view) by a factor 1 +- 3 ``rms`` (+-9% at
    the base bound, as the relief and shape families' +-10%), on the pixels the (true)
    instance covers."""
    out = nocs.copy()
    for iid in np.unique(frame.mask[frame.mask > 0]):
        m = (frame.mask == iid) & np.isfinite(frame.depth)
        if m.sum() < 4:
            continue
        sign = state._sign(("stretch", int(iid)), rng)
        truth = frame.nocs[m] - frame.nocs[m].mean(0)
        axis = np.linalg.lstsq(truth, frame.depth[m] - frame.depth[m].mean(), rcond=None)[0]
        if not np.linalg.norm(axis) > 0:
            continue
        axis /= np.linalg.norm(axis)
        q = nocs[m] - nocs[m].mean(0)
        move = (q @ axis)[:, None] * axis
        out[m] = nocs[m] + sign * 3.0 * rms * move
    return out


def _polygon(m, px, rng):
    """Instance mask m as a detector outlines it: its outline simplified to a polygon (within
    up to 2 ``px`` pixels), with up to two round holes of radius up to ``px`` inside."""
    contours, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_NONE)
    out = np.zeros(m.shape, np.uint8)
    eps = float(rng.uniform(0.5, 2 * px))
    cv2.fillPoly(out, [cv2.approxPolyDP(c, eps, True) for c in contours], 1)
    inside = np.argwhere(cv2.erode(out, np.ones((2 * px + 3,) * 2, np.uint8)) > 0)
    for _ in range(int(rng.integers(0, 3)) if len(inside) else 0):
        y, x = inside[rng.integers(len(inside))]
        cv2.circle(out, (int(x), int(y)), int(rng.integers(1, px + 1)), 0, -1)
    return out


def _hull(m):
    """Instance mask m filled to the convex hull of each of its parts."""
    contours, _ = cv2.findContours(m.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    out = np.zeros(m.shape, np.uint8)
    cv2.fillPoly(out, [cv2.convexHull(c) for c in contours], 1)
    return out


def _ragged(m, px, rng):
    """Instance mask m with a ragged boundary: each pixel within r <= px of it (either side) is
    flipped with one probability up to three quarters per instance."""
    kern = cv2.getStructuringElement(cv2.MORPH_CROSS, (2 * px + 1,) * 2)
    inner = m & ~cv2.erode(m.astype(np.uint8), kern).astype(bool)
    outer = cv2.dilate(m.astype(np.uint8), kern).astype(bool) & ~m
    p = rng.uniform(0.0, 0.75)
    return (m & ~(inner & (rng.random(m.shape) < p))) | (outer & (rng.random(m.shape) < p))


def _mask_errors(mask, nocs, px, rng, variant, state=None):
    """Erode or dilate (``heldout2``: shift; ``heldout3``: fray; ``heldout4``: outline as a
    polygon with holes; ``heldout5``: fill to the convex hull; ``heldout6``: through a 28x28
    mask head; ``heldout7``: by a width kept for the sequence in ``state``, then bleed into
    touching instances; ``heldout8``: grow and cut by a detection box; ``heldout9`` and
    ``heldout10``, ``heldout11`` and ``heldout13``: as the tuning variant; ``heldout12`` has
    :func:`_contact_errors` instead) each instance by up to ``px`` pixels; grown pixels keep
    the background depth and take the nearest object's NOCS, as a segmentation network's
    would."""
    shape = {"heldout": cv2.MORPH_ELLIPSE, "heldout3": cv2.MORPH_CROSS}.get(variant,
                                                                           cv2.MORPH_RECT)
    new = np.zeros_like(mask)
    near = np.stack([cv2.dilate(nocs[..., c].astype(np.float32),
                                cv2.getStructuringElement(shape, (2 * px + 1,) * 2))
                     for c in range(3)], -1)
    for iid in np.unique(mask[mask > 0]):
        m = (mask == iid).astype(np.uint8)
        if variant == "heldout2":
            dx, dy = (int(v) for v in rng.integers(-px, px + 1, 2))
            m = cv2.warpAffine(m, np.float32([[1, 0, dx], [0, 1, dy]]), m.shape[::-1],
                               flags=cv2.INTER_NEAREST)
        elif variant == "heldout3":
            m = _ragged(m.astype(bool), int(rng.integers(1, px + 1)), rng)
        elif variant == "heldout4":
            m = _polygon(m, px, rng)
        elif variant == "heldout5":
            m = _hull(m)
        elif variant == "heldout6":
            m = _mask_head(m, rng)
        elif variant == "heldout8":
            m = _boxed(m, px, rng)
        elif r := (int(state._kept(("mask_px", int(iid)), lambda: rng.integers(-px, px + 1)))
                   if variant == "heldout7" else int(rng.integers(-px, px + 1))):
            kern = cv2.getStructuringElement(shape, (2 * abs(r) + 1,) * 2)
            m = cv2.dilate(m, kern) if r > 0 else cv2.erode(m, kern)
        m = m.astype(bool)
        grow = m & (mask == 0) & (new == 0)
        nocs[grow] = near[grow]
        new[m & ((new == 0) | (mask == iid))] = iid
    if variant == "heldout7":
        new, nocs = _bleed(mask, new, nocs, px, state, rng)
    return new, nocs


@dataclass
class WorldSequence:
    """One sequence of the world: its frames' truth and observations, and the drawn errors."""

    frames: list
    errors: ErrorFamilies
    size: tuple


def world_scene(rng: np.random.Generator, spec: SceneSpec = SceneSpec(), focal=None, size=None,
                objects=None):
    """A random scene layout: (objects, focal, table, (width, height))."""
    w, h = size if size is not None else spec.sizes[rng.integers(len(spec.sizes))]
    n = objects if objects is not None else int(rng.integers(spec.objects[0], spec.objects[1] + 1))
    f = float(rng.uniform(*spec.focal_range)) if focal is None else float(focal)
    # Objects 0.4-2 m away (the table's distance), of household size (0.1-0.3 m bounding-box
    # diagonal) as far as the view holds them.
    dist = float(rng.uniform(*spec.distance_range))
    fov_m = dist * min(w, h) / f
    top = min(spec.object_size[1], 0.6 * fov_m)
    objs, f, table = random_scene(rng, n, f, w, h, distance_range=(dist, dist),
                                  scale_range=(min(spec.object_size[0], 0.6 * top), top))
    return objs, f, table, (w, h)


def world_frames(preset: str | ErrorFamilies, seed: int, n_frames: int = 1,
                 variant: str = "tuning", spec: SceneSpec = SceneSpec(), focal=None, size=None,
                 objects=None, orbit_deg: float = 2.0, zoom_frame: int | None = None,
                 zoom_factor: float = 1.0, renew=()) -> WorldSequence:
    """A sequence of ``n_frames`` frames of one random scene seen by a slowly orbiting camera,
    under one random draw of the preset's error families (``zoom_factor`` multiplies the focal
    length from ``zoom_frame`` on; ``renew``: see :meth:`ErrorState.start`)."""
    from scipy.spatial.transform import Rotation

    from .render import SceneObject

    fam = WORLD_PRESETS[preset] if isinstance(preset, str) else preset
    rng = np.random.default_rng(seed)
    objs, f, (centre, up), (w, h) = world_scene(rng, spec, focal, size, objects)
    errors = fam.draw(rng)
    state = ErrorState.start(errors, rng, variant, renew)
    camera = variant in ("tuning", "heldout11", "heldout12", "heldout13")  # others: their own
    pp = _principal_point(errors.principal_point if camera else 0.0, seed, w, h)
    undistort = _lens(errors.lens if camera else 0.0, seed, variant)
    out = []
    for k in range(n_frames):
        R = Rotation.from_rotvec(np.radians(orbit_deg * k) * up).as_matrix()
        moved = [SceneObject(o.instance_id, o.category, R @ o.rotation,
                             R @ (o.translation - centre) + centre, o.scale)
                 for o in objs]
        fk = f * (zoom_factor if zoom_frame is not None and k >= zoom_frame else 1.0)
        truth = render(moved, fk, w, h, principal_point=pp, table=(centre, up))
        seen = apply_errors(truth, state, rng)
        out.append(seen if undistort is None else _distorted(seen, truth.mask, undistort))
    return WorldSequence(out, errors, (w, h))


def _principal_point(bound: float, seed: int, w: int, h: int):
    """The sequence's principal point (px) for a ``principal_point`` bound, None (the image
    centre) at 0; drawn from a generator of the seed's own, not the sequence's."""
    if bound <= 0:
        return None
    rng = np.random.default_rng([seed, 104])
    off = rng.uniform(0, bound) * rng.uniform(-1, 1, 2) * np.array([w, h])
    cx, cy = image_centre(w, h)
    return (cx + float(off[0]), cy + float(off[1]))


def lens_coefficients(bound: float, seed: int) -> tuple[float, float]:
    """(k1, k2) of the tuning world's lens of a sequence ``seed`` for a ``lens`` bound: k1
    uniform in +-bound, k2 in +-bound / 2, from a generator of the seed's own."""
    k1, k2 = np.random.default_rng([seed, 105]).uniform([-1.0, -0.5], [1.0, 0.5]) * bound
    return float(k1), float(k2)


def _lens(bound: float, seed: int, variant: str):
    """The sequence's lens for a ``lens`` bound, as the map from a distorted normalised point
    (xd, yd) to the pinhole's (x, y); None (a pinhole) at 0. Drawn from a generator of the
    seed's own. ``heldout11``'s is a division model with decentering, x = xd / (1 + l rd^2)
    less the tangential terms of (p1, p2), l uniform in +-1.2 ``bound`` and p1, p2 in
    +-0.2 ``bound`` (a lens model the tuning world's Brown polynomial is not)."""
    if bound <= 0:
        return None
    if variant != "heldout11":
        k1, k2 = lens_coefficients(bound, seed)
        return lambda xd, yd: _undistort(xd, yd, k1, k2)
    rng = np.random.default_rng([seed, 105])
    lam = float(rng.uniform(-1.2, 1.2) * bound)
    p1, p2 = (float(v) for v in rng.uniform(-0.2, 0.2, 2) * bound)

    def division(xd, yd):
        r2 = xd * xd + yd * yd
        return (xd / (1 + lam * r2) - (2 * p1 * xd * yd + p2 * (r2 + 2 * xd * xd)),
                yd / (1 + lam * r2) - (p1 * (r2 + 2 * yd * yd) + 2 * p2 * xd * yd))
    return division


def _distorted(seen: Frame, truth, undistort) -> Frame:
    """The frame ``seen`` (rendered through a pinhole) as a camera takes it whose lens maps
    each distorted normalised point to the pinhole's by ``undistort``, about the same principal
    point; ``truth`` (the true mask) with ``seen``'s marks the segments not to interpolate
    across."""
    h, w = seen.mask.shape
    cx, cy = seen.principal_point
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    x, y = undistort((uu - cx) / seen.focal, (vv - cy) / seen.focal)
    return _taken_at(seen, truth, cx + seen.focal * x, cy + seen.focal * y, exact=True)


def world_frame(preset: str | ErrorFamilies, seed: int, variant: str = "tuning", **kw) -> Frame:
    """One frame of a fresh random scene under a fresh draw of the preset's errors."""
    return world_frames(preset, seed, 1, variant, **kw).frames[0]
