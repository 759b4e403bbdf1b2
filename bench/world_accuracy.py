"""Accuracy, bias and honesty of the uncertainty on the randomised world, held-out beside tuned.

    python bench/world_accuracy.py [--frames 60] [--sequences 40] [--zoom-sequences 8]
        [--heldout | --heldout2 | --heldout3 | --heldout4 | --heldout5 | --heldout6
         | --heldout7 | --heldout8 | --heldout9 | --heldout10 | --heldout11 | --heldout12
         | --heldout13]
        [--parts single bias window zoom preset_bias pipes weights tau objects gate]
        [--objects N]
        [--set NAME=VALUE] [--orbit DEG] [--given-principal-point] [--first-sequence SEED]
        [--world NAME=VALUE] [--renew FAMILY]

Tuned rows use the seeds the estimator's few constants were chosen on (frames from seed 1000,
sequences from seed 5000, the tuning error model). Held-out rows (--heldout) use seeds from
900000 and the held-out error model (sinusoidal depth fields, a quadratic NOCS warp, elliptic
mask errors; see fcop_ros/synthetic/world.py), looked at once, at the end. After several
rounds had looked at those, --heldout2 (seeds from 950000 and 955000, a third error model:
Gaussian-bump depth fields, twisted NOCS, shifted masks) was first evaluated on 22 Nov 2026.
--heldout3 (seeds from 980000 and 985000, a fourth error model: a depth error affine in
disparity plus polynomial fields, the depth scale redrawn every frame, radially bulging NOCS,
ragged masks) was fixed on 23 Nov 2026 and first evaluated at the end of that round.
--heldout4 (seeds from 990000 and 995000, a fifth error model: depth errors attached to each
object's surface, each object's distance misjudged per frame, NOCS stretched along the viewing
axis, polygon masks with holes, 8-bit NOCS) was fixed on 23 Nov 2026 and run once after it.
--heldout5 (seeds from 1010000 and 1015000, a sixth error model: depth fields piecewise constant
over tiles, a decaying halo at depth edges, one part of each object's NOCS displaced, masks
filled to their convex hull) was fixed on 24 Nov 2026 before that round's choices.
--heldout6 (seeds from 1020000 and 1025000, a seventh error model: a depth field growing with
the squared distance from the image centre plus fields along the image rows, foreground
fattening at depth edges, NOCS shrunk or swollen near each silhouette, masks through a 28x28
mask head) was fixed on 24 Nov 2026 in a round that changed no estimate, and run once at its
end.
--heldout7 (seeds from 1030000 and 1035000, an eighth error model: a depth field following the
image's brightness (shading times albedo) plus fields drawn per segment, NOCS stretched along
the longer image axis of each object's box, touching instances bleeding into each other and
borders with the background moved by a width kept per sequence) was fixed on 24 Nov 2026
before that round's evaluation.
--heldout8 (seeds from 1040000 and 1045000, a ninth error model: a familiar-size depth error
per object plus image fields growing with depth, depth read back from 8-bit normalised
disparity, NOCS turned about each object's vertical axis by a share of their azimuth from the
view, NOCS through JPEG, masks grown and cut by a jittered detection box) was fixed on 24 Nov
2026 before any evaluation on it.
--heldout9 (seeds from 1050000 and 1055000, a tenth error model: depth fields fixed in the
scene, depth predicted at 1/2 or 1/4 size and upsampled, NOCS pulled towards their affine fit
in the image, NOCS and masks one frame late, the principal point off the image centre) was
fixed on 24 Nov 2026 before any evaluation on it.
--heldout10 (seeds from 1060000 and 1065000, an eleventh error model: a residual radial lens
distortion and a principal point off the image centre by a sub-pixel Gaussian, each object's
fine relief sharpened or flattened, holes in each object's depth, NOCS bent and tapered along
each object's up axis, masks that flicker and ids that switch for a frame) was fixed on 24 Nov
2026 before any evaluation on it.
--heldout11 (seeds from 1070000 and 1075000, a twelfth error model: the tuning model's errors
through another lens, a division model with decentering where the tuning world's is a Brown
polynomial) was fixed on 25 Nov 2026 before the lens term of std_rel was judged on it.
--heldout12 (seeds from 1080000 and 1085000, a thirteenth error model: a depth error growing
with the grazing angle between each surface and its viewing ray, each object's NOCS map
misregistered within its mask by a drifting shift, NOCS from a 28x28 grid over each box pasted
back blockily, masks eroded or dilated only where an object meets the table, the tuning camera)
was fixed on 25 Nov 2026 before any evaluation on it.
--heldout13 (seeds from 1090000 and 1095000, a fourteenth error model: stereo depth noise growing
with the square of depth, the depth offset drawn anew in every frame, objects that the depth
sees through to the table over part of their pixels, each object's NOCS moved by a smooth warp
of NOCS space, the tuning camera, depth fields and masks) was fixed on 25 Nov 2026 before any
evaluation on it.

Single frames, per preset: median and p90 |focal error| (%), signed median (%), share of frames
with an estimate, and for fcop_ros the coverage of |error| <= 2 std_rel; beside it the paper's
method taken literally, the 60-line plain reference of the accuracy issue and P4Pf (pycolmap,
2D-NOCS only, median over objects; skipped without pycolmap). Bias: each zero-mean mechanism
alone, its strength drawn up to its base bound, with its signed median's standard error.
Window: static orbiting sequences of 30 frames (window of 30) against the single frames of the
same sequences, and what persists: per sequence the |signed median| of all its frames' errors,
their median over sequences against the single frames' median (the error a sequence's frames
share, which no weighing of those frames averages away: a floor a window nears, not a bound it
cannot pass); zoom sequences (x1.25 and x0.8 at frame 20 of 40): frames until the window
stays within 5% of the new focal length, and restarts on static ones. Zoom (``--parts zoom``):
the same zoom sequences, each one that does not settle within 15 frames told apart by whether
the window restarted at the zoom and how far the frames after it err themselves, beside the
window's coverage of 2 std_rel over the 20 updates after each zoom. Preset bias
(``--parts preset_bias``): fcop_ros's signed median over ``--bias-frames`` frames of each full
preset, with its standard error. Pipes (``--parts pipes``): the NOCS image through JPEG
(``nocs_jpeg``, in no preset) alone, and the shift it makes in ``predicted`` frame by frame on
the same frames; then which part of JPEG does it, on frames with NOCS noise alone. Weights
(``--parts weights``): within a frame, how the
objects' errors rank with their systematic and their noise variance, and the frame's error
under either weighting. Tau (``--parts tau``): the between-object spread that frames of two
or more objects show, the rule ``object_tau`` was set by. Gate (``--parts gate``): on the
window part's static sequences, the share of window updates whose std_rel a node's
``max_uncertainty`` of 0.02, 0.05 (its default) or 0.1 lets through, and how far those err.
``--objects N`` makes every scene
one of N objects (1: the frames a single object gives, which no disagreement between objects
can check); ``--set NAME=VALUE`` tries other EstimatorOptions (the docs' figures use the
defaults).
"""
from __future__ import annotations

import argparse
import time
from dataclasses import replace

import numpy as np
from scipy import ndimage

from fcop_ros import FocalWindow, WindowOptions, estimate_focal, interval_stabbing, solve_triplets
from fcop_ros.core import PAPER_FCOP_IS, EstimatorOptions
from fcop_ros.core.camera import image_centre
from fcop_ros.core.stabbing import focal_intervals
from fcop_ros.synthetic.world import (PIPE_FAMILIES, RENEWABLE, WORLD_PRESETS,
                                     ZERO_MEAN_FAMILIES, ErrorFamilies, _jpeg, world_frame,
                                     world_frames)
from fcop_ros.tools.cli import HelpFormatter
# bench/peers.py: the script's own folder is on the path when run as a script
from peers import p4pf


#: fcop_ros's settings (``--set``) and the scenes' object count (``--objects``; None: 1 to 6).
OPTIONS = EstimatorOptions()
OBJECTS = None
ORBIT_DEG = 2.0  # the camera's orbit per frame in the sequences (world_frames' default)
GIVEN_PP = False  # the sequences' estimates get the true principal point, not the centre
RENEW = ()  # persistent error families the sequences draw anew in every frame (a diagnostic)
WORLD = {}  # error-family bounds of the sequences' presets other than the presets' own


#: Each error model's first frame seed and first sequence seed (``--heldout*`` picks one).
SEEDS = {"tuning": (1000, 5000), "heldout": (900000, 905000), "heldout2": (950000, 955000),
         "heldout3": (980000, 985000), "heldout4": (990000, 995000),
         "heldout5": (1010000, 1015000), "heldout6": (1020000, 1025000),
         "heldout7": (1030000, 1035000), "heldout8": (1040000, 1045000),
         "heldout9": (1050000, 1055000), "heldout10": (1060000, 1065000),
         "heldout11": (1070000, 1075000), "heldout12": (1080000, 1085000),
         "heldout13": (1090000, 1095000)}
ORDINALS = ("", "second ", "third ", "fourth ", "fifth ", "sixth ", "seventh ", "eighth ",
            "ninth ", "tenth ", "eleventh ", "twelfth ", "thirteenth ")


def plain_reference(fr, rng):
    """The accuracy issue's plain reference: 7x7 masked box means of depth and NOCS inside each
    instance, 2 px erosion, triplets with well-separated NOCS among random candidates, interval
    stabbing with a 1% relative bound."""
    h, w = fr.depth.shape
    cx, cy = image_centre(w, h)
    xs, ds, ps, tris, off = [], [], [], [], 0
    for iid in np.unique(fr.mask[fr.mask > 0]):
        m = (
            ndimage.binary_erosion(fr.mask == iid, iterations=2)
            & np.isfinite(fr.depth)
            & (fr.nocs.sum(-1) > 0)
        )
        if m.sum() < 50:
            continue
        k = np.ones((7, 7))
        cnt = ndimage.convolve(m.astype(float), k, mode="constant")
        d = ndimage.convolve(np.where(m, fr.depth, 0.0), k, mode="constant") / np.maximum(cnt, 1)
        p = (
            np.stack(
                [
                    ndimage.convolve(np.where(m, fr.nocs[..., c], 0.0), k, mode="constant")
                    for c in range(3)
                ],
                -1,
            )
            / np.maximum(cnt, 1)[..., None]
        )
        rr, cc = np.nonzero(m)
        if rr.size > 2000:
            pick = rng.choice(rr.size, 2000, replace=False)
            rr, cc = rr[pick], cc[pick]
        x = np.column_stack([cc - cx, rr - cy]).astype(float)
        cand = rng.integers(0, rr.size, (4000, 3))
        pp = p[rr, cc]
        sep = np.minimum.reduce([np.linalg.norm(pp[cand[:, a]] - pp[cand[:, b]], axis=1)
                                 for a, b in ((0, 1), (1, 2), (0, 2))])
        best = cand[np.argsort(-sep)[:1000]]
        xs.append(x), ds.append(d[rr, cc]), ps.append(pp), tris.append(best + off)
        off += rr.size
    if not tris:
        return None
    f, _, ok = solve_triplets(np.concatenate(xs), np.concatenate(ds), np.concatenate(ps),
                              np.concatenate(tris))
    f = f[ok & (f > 50) & (f < 20000)]
    if f.size == 0:
        return None
    lo, hi, back = focal_intervals(f, 0.01, "relative")
    st = interval_stabbing(lo, hi)
    return float(back(st.point))


def methods(have_colmap):
    out = {
        "fcop_ros": lambda fr, k: estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k, poses=False,
                                                  options=OPTIONS),
        "paper's method taken literally": lambda fr, k: (
            estimate_focal(fr.depth, fr.nocs, fr.mask, options=PAPER_FCOP_IS, seed=k).focal
        ),
        "plain reference (issue 8)": lambda fr, k: plain_reference(fr, np.random.default_rng(k)),
    }
    if have_colmap:
        out["P4Pf (pycolmap)"] = lambda fr, k: p4pf(fr, seed=k)[0]
    return out


def single_frames(presets, frames, first_seed, variant, have_colmap):
    print("| preset | method | median abs error % | p90 % | signed median % | answered | "
          "coverage of 2 std_rel | median std_rel % | ms per frame |")
    print("|---|---|---|---|---|---|---|---|---|")
    for preset in presets:
        data = [world_frame(preset, first_seed + s, variant, objects=OBJECTS)
                for s in range(frames)]
        for name, fn in methods(have_colmap).items():
            err, cover, std, t = [], [], [], 0.0
            for k, fr in enumerate(data):
                t0 = time.perf_counter()
                out = fn(fr, k)
                t += time.perf_counter() - t0
                f = out.focal if hasattr(out, "focal") else out
                if f is None:
                    continue
                e = np.log(f / fr.focal)
                err.append(100 * e)
                if hasattr(out, "std_rel") and out.std_rel:
                    cover.append(abs(e) <= 2 * out.std_rel)
                    std.append(100 * out.std_rel)
            err = np.array(err)
            cov = f"{100 * np.mean(cover):.0f}%" if cover else "-"
            med_std = f"{np.median(std):.2f}" if std else "-"
            print(
                f"| {preset} | {name} | {np.median(np.abs(err)):.2f} | "
                f"{np.percentile(np.abs(err), 90):.2f} | "
                f"{np.median(err):+.2f} | {err.size}/{frames} | {cov} | {med_std} | "
                f"{1000 * t / frames:.0f} |",
                flush=True,
            )


def _median_standard_error(err: np.ndarray) -> float:
    """The standard error of err's median: the spread of the medians of 1000 bootstrap
    resamples (seeded, so a table reads the same in every run); NaN without values."""
    if err.size == 0:
        return float("nan")
    boot = np.random.default_rng(0).choice(err, (1000, err.size))
    return float(np.std(np.median(boot, axis=1)))


def bias(frames, first_seed, variant):
    print("\n| mechanism alone (strength up to) | signed median % | its standard error "
          "(bootstrap) | median abs error % | coverage |")
    print("|---|---|---|---|---|")
    for fam in ZERO_MEAN_FAMILIES:
        err, cover = [], []
        for s in range(frames):
            fr = world_frame(f"only_{fam}", first_seed + s, variant, objects=OBJECTS)
            est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False,
                                 options=OPTIONS)
            if est.focal is not None:
                e = np.log(est.focal / fr.focal)
                err.append(100 * e)
                cover.append(abs(e) <= 2 * est.std_rel)
        err = np.array(err)
        print(f"| {fam} ({getattr(WORLD_PRESETS['only_' + fam], fam)}) | {np.median(err):+.2f} | "
              f"{_median_standard_error(err):.2f} | {np.median(np.abs(err)):.2f} | "
              f"{100 * np.mean(cover):.0f}% |", flush=True)


def _estimates(preset, frames, first_seed, variant):
    """(frame, fcop_ros's estimate) for each of ``frames`` frames of ``preset``."""
    for s in range(frames):
        fr = world_frame(preset, first_seed + s, variant, objects=OBJECTS)
        yield fr, estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False,
                                 options=OPTIONS)


def preset_bias(presets, frames, first_seed, variant):
    """fcop_ros's signed median over many frames of each full preset, with its standard error:
    60 frames cannot tell a bias of a few tenths of a percent from chance."""
    print("\n| preset (fcop_ros) | frames | signed median % | its standard error (bootstrap) | "
          "signed mean % | its standard error |")
    print("|---|---|---|---|---|---|")
    for preset in presets:
        err = [100 * np.log(est.focal / fr.focal)
               for fr, est in _estimates(preset, frames, first_seed, variant)
               if est.focal is not None]
        err = np.array(err)
        print(f"| {preset} | {err.size} | {np.median(err):+.2f} | "
              f"{_median_standard_error(err):.2f} | {np.mean(err):+.2f} | "
              f"{np.std(err) / np.sqrt(err.size):.2f} |", flush=True)


def pipes(frames, first_seed, variant):
    """What each pipe between the predictors and the estimator does (errors in no preset, not
    zero-mean): fcop_ros's signed median with the pipe alone, and the shift it makes in
    ``predicted``, frame by frame on the same frames (which differ only by the pipe)."""
    print("\n| pipe | alone: signed median % (standard error) | `predicted` without / with it: "
          "signed median % | median abs error % | coverage | paired shift: median % "
          "(standard error) |")
    print("|---|---|---|---|---|---|")
    for pipe in PIPE_FAMILIES:
        alone = np.array([100 * np.log(est.focal / fr.focal) for fr, est in
                          _estimates(f"only_{pipe}", frames, first_seed, variant)
                          if est.focal is not None])
        pairs = [[(np.log(est.focal / fr.focal), est.std_rel) if est.focal is not None
                  else (np.nan, np.nan) for fr, est in _estimates(p, frames, first_seed, variant)]
                 for p in ("predicted", f"predicted_{pipe}")]
        (e0, s0), (e1, s1) = (100 * np.array(p).T for p in pairs)

        def row(e, s):
            ok = np.isfinite(e)
            return (f"{np.median(e[ok]):+.2f}", f"{np.median(np.abs(e[ok])):.2f}",
                    f"{100 * np.mean(np.abs(e[ok]) <= 2 * s[ok]):.0f}%")

        shift = (e1 - e0)[np.isfinite(e1 - e0)]
        print(f"| {pipe} | {np.median(alone):+.2f} ({_median_standard_error(alone):.2f}) | "
              + " | ".join(f"{a} / {b}" for a, b in zip(row(e0, s0), row(e1, s1)))
              + f" | {np.median(shift):+.2f} ({_median_standard_error(shift):.2f}) |",
              flush=True)


def jpeg_parts(frames, first_seed, variant, quality=85):
    """Which part of JPEG moves the focal length: frames with per-pixel NOCS noise alone (up to
    its base bound) sent raw, rounded to 8 bits, through JPEG at ``quality`` with the colour kept
    whole (4:4:4) or halved (4:2:0, as ROS's compressed transport sends it), and the last with
    the masks eroded by 3 px instead of 1 (were the error only at the silhouettes, that would
    remove it). Each frame is made once and sent every way."""
    eroded = replace(OPTIONS, erode_px=3)
    ways = {"raw": (lambda n: n, OPTIONS),
            "8 bits": (lambda n: np.round(n * 255.0) / 255.0, OPTIONS),
            "JPEG 4:4:4": (lambda n: _jpeg(n, quality, full_chroma=True), OPTIONS),
            "JPEG 4:2:0": (lambda n: _jpeg(n, quality), OPTIONS),
            "JPEG 4:2:0, erode_px 3": (lambda n: _jpeg(n, quality), eroded)}
    noisy = ErrorFamilies(nocs_pixel=WORLD_PRESETS["only_nocs_pixel"].nocs_pixel)
    err = {way: [] for way in ways}
    for s in range(frames):
        fr = world_frame(noisy, first_seed + s, variant, objects=OBJECTS)
        for way, (send, opts) in ways.items():
            nocs = send(fr.nocs)
            nocs[fr.mask == 0] = 0.0
            est = estimate_focal(fr.depth, nocs, fr.mask, seed=s, poses=False, options=opts)
            if est.focal is not None:
                err[way].append(100 * np.log(est.focal / fr.focal))
    print(f"\n| the NOCS image (noise alone, quality {quality}) | signed median % "
          "(standard error) | median abs error % |")
    print("|---|---|---|")
    for way, e in err.items():
        e = np.array(e)
        print(f"| {way} | {np.median(e):+.2f} ({_median_standard_error(e):.2f}) | "
              f"{np.median(np.abs(e)):.2f} |", flush=True)


def weights(presets, frames, first_seed, variant):
    """What ranks the objects' errors within a frame: each combined object's |error| against
    its systematic variance (std_rel^2 - std_rel_noise^2) and its noise variance (Spearman,
    averaged over frames with at least four objects), and the frame's median |error| with the
    objects weighted by 1 / noise (fcop_ros) or by 1 / std_rel^2."""
    from scipy.stats import spearmanr

    print("\n| preset | frames (with >= 4 objects) | rank correlation of |error| with systematic "
          "variance | with noise variance | median abs error %: weights 1 / noise | "
          "weights 1 / std_rel^2 |")
    print("|---|---|---|---|---|---|")
    for preset in presets:
        r_sys, r_noise, e_noise, e_total = [], [], [], []
        for s in range(frames):
            fr = world_frame(preset, first_seed + s, variant, objects=OBJECTS)
            est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=s, poses=False,
                                 options=OPTIONS)
            if est.focal is None:
                continue
            f, std, noise = (np.array(c) for c in zip(*est.object_focals.values()))
            y = np.log(f / fr.focal)
            for w, out in ((1 / noise**2, e_noise), (1 / std**2, e_total)):
                out.append(abs(np.sum(w * y) / w.sum()))
            if y.size >= 4:
                r_sys.append(spearmanr(np.abs(y), std**2 - noise**2)[0])
                r_noise.append(spearmanr(np.abs(y), noise**2)[0])
        print(f"| {preset} | {len(e_noise)} ({len(r_sys)}) | {np.nanmean(r_sys):.2f} | "
              f"{np.nanmean(r_noise):.2f} | {100 * np.median(e_noise):.2f} | "
              f"{100 * np.median(e_total):.2f} |", flush=True)


def tau(presets, frames, first_seed, variant):
    """The between-object spread that frames of two or more objects show beyond the objects'
    own budgets: per frame the DerSimonian-Laird estimate over its combined objects (log f and
    std_rel from ``object_focals``), then its root mean square over the frames (the prior
    ``object_tau`` a frame of one object needs, for noisy NOCS where the fits lean on depth
    one for one), its median and the share of frames with any."""
    print("\n| preset | frames of 2+ objects | root mean square tau % | median tau % | "
          "frames with tau > 0 |")
    print("|---|---|---|---|---|")
    for preset in presets:
        t2 = []
        for _, est in _estimates(preset, frames, first_seed, variant):
            if est.focal is None or len(est.object_focals) < 2:
                continue
            y = np.log([f for f, _, _ in est.object_focals.values()])
            w = 1.0 / np.array([sd for _, sd, _ in est.object_focals.values()]) ** 2
            m = np.sum(w * y) / w.sum()
            q, c = np.sum(w * (y - m) ** 2), w.sum() - np.sum(w * w) / w.sum()
            t2.append(max(0.0, (q - (y.size - 1)) / c) if c > 0 else 0.0)
        t2 = np.array(t2)
        print(f"| {preset} | {t2.size} | {100 * np.sqrt(t2.mean()):.2f} | "
              f"{100 * np.sqrt(np.median(t2)):.2f} | {100 * np.mean(t2 > 0):.0f}% |", flush=True)


#: run_sequence's rows by its arguments: the window, zoom and gate parts run the same
#: sequences, and their estimates depend on nothing else once main() has set the globals.
_SEQUENCE_ROWS = {}


def run_sequence(preset, seed, n, variant, zoom=1.0, estimates=None):
    """Per frame (true focal, frame's focal, its std_rel, window's focal, its std_rel,
    restarted); the frames' estimates are appended to ``estimates`` when it is a list (then
    the sequence is run anew; otherwise rows already run are reused)."""
    key = (preset, seed, n, variant, zoom)
    if estimates is None and key in _SEQUENCE_ROWS:
        return _SEQUENCE_ROWS[key]
    if WORLD:
        preset = replace(WORLD_PRESETS[preset], **WORLD)
    seq = world_frames(preset, seed, n, variant, zoom_frame=n // 2 if zoom != 1.0 else None,
                       zoom_factor=zoom, objects=OBJECTS, orbit_deg=ORBIT_DEG, renew=RENEW)
    win = FocalWindow(WindowOptions(max_frames=30))
    rows = []
    for k, fr in enumerate(seq.frames):
        pp = fr.principal_point if GIVEN_PP else None
        est = estimate_focal(fr.depth, fr.nocs, fr.mask, pp, seed=k, poses=False,
                             options=OPTIONS)
        w = win.add(est, k / 30)
        rows.append((fr.focal, est.focal, est.std_rel, w.focal, w.std_rel, w.changed))
        if estimates is not None:
            estimates.append(est)
    _SEQUENCE_ROWS[key] = rows
    return rows


def zoom_sequence(preset, seed, variant, factor):
    """The rows of a 40-frame sequence from its zoom (x ``factor`` at frame 20) on, and the
    frames after the zoom until the window is within 5% of the new focal for good."""
    rows = run_sequence(preset, seed, 40, variant, factor)[20:]
    bad = [i for i, r in enumerate(rows) if r[3] is None or abs(np.log(r[3] / r[0])) > 0.05]
    return rows, (bad[-1] + 1 if bad else 0)


def _ratio_cell(win, single) -> str:
    """'ratio (90% interval)' of the window's median abs error to the single frames', both
    lists of per-sequence lists of errors: a sequence's frames share its errors, so the
    interval resamples sequences (1000 bootstrap draws)."""
    def ratio(pick):
        return (np.median(np.concatenate([win[i] for i in pick]))
                / np.median(np.concatenate([single[i] for i in pick])))

    n = len(single)
    boot = np.random.default_rng(0).integers(0, n, (1000, n))
    lo, hi = np.percentile([ratio(b) for b in boot], [5, 95])
    return f"{ratio(np.arange(n)):.2f} ({lo:.2f}-{hi:.2f})"


def window(presets, sequences, first_seed, variant, zoom_sequences):
    print(
        "\n| preset | sequences | single frames: median abs error % | window: median abs error % "
        "| ratio (90% interval over sequences) | median of the window's frames: ratio | "
        "what persists: ratio | window coverage of 2 std_rel | restarts on static "
        "| zoom x1.25 / x0.8: frames until within 5% for good |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for preset in presets:
        # Per sequence: its frames' errors are correlated, so the interval resamples sequences.
        single, win, oracle, cover, restarts, delays = [], [], [], [], 0, []
        persists = []
        for q in range(sequences):
            rows = run_sequence(preset, first_seed + q, 30, variant)
            errs = [np.log(r[1] / r[0]) if r[1] is not None else np.nan for r in rows]
            # The error a sequence's frames share: the signed median of all of them, which no
            # weighing of these frames averages away (errors that repeat from view to view).
            if np.isfinite(errs).any():
                persists.append(abs(np.nanmedian(errs)))
            single.append([]), win.append([]), oracle.append([])
            for k, (t, f, s, wf, ws, ch) in enumerate(rows):
                if k < 5:
                    continue
                restarts += ch
                # The unweighted median of the same frames' errors, for comparison.
                seen = np.array(errs[max(0, k - 29): k + 1])
                if np.isfinite(seen).any():
                    oracle[-1].append(abs(np.nanmedian(seen)))
                if f is not None:
                    single[-1].append(abs(np.log(f / t)))
                if wf is not None:
                    win[-1].append(abs(np.log(wf / t)))
                    cover.append(abs(np.log(wf / t)) <= 2 * ws)
        for q in range(zoom_sequences):
            for factor in (1.25, 0.8):
                delays.append(zoom_sequence(preset, first_seed + 100 + q, variant, factor)[1])

        med_single = np.median(np.concatenate(single))
        print(
            f"| {preset} | {sequences} | {100 * med_single:.2f} | "
            f"{100 * np.median(np.concatenate(win)):.2f} | "
            f"{_ratio_cell(win, single)} | "
            f"{np.median(np.concatenate(oracle)) / med_single:.2f} | "
            f"{np.median(persists) / med_single:.2f} | "
            f"{100 * np.mean(cover):.0f}% | {restarts} | {sorted(delays)} |",
            flush=True,
        )


def _objects_pooled(estimates, budget: bool) -> float | None:
    """log f of a window that pools each object's focal lengths over its frames first (objects
    matched by instance id; weights 1 / noise, as the window weighs frames), then the objects,
    weighted by their pooled noise or, with ``budget``, by their systematic budget (the median
    of their frames' variance less noise) plus it."""
    rows = {}
    for est in estimates:
        if est.focal is not None:
            for iid, (f, sd, sn) in est.object_focals.items():
                rows.setdefault(iid, []).append((np.log(f), sd * sd, sn * sn))
    if not rows:
        return None
    y, w = [], []
    for a in map(np.array, rows.values()):
        inv = 1.0 / a[:, 2]
        y.append(np.sum(inv * a[:, 0]) / inv.sum())
        w.append(1.0 / (1.0 / inv.sum() + (np.median(a[:, 1] - a[:, 2]) if budget else 0.0)))
    y, w = np.array(y), np.array(w)
    return float(np.sum(w * y) / w.sum())


def objects(presets, sequences, first_seed, variant):
    """A trial, not kept: the window pools frames; here each object is pooled over the
    window's frames first, then the objects (the principal point as each frame corrected it,
    not pooled). Same static sequences and scoring as the window part."""
    print("\n| preset | sequences | single frames: median abs error % | window of frames: ratio "
          "(90% interval) | objects pooled, noise weights | objects pooled, budget weights |")
    print("|---|---|---|---|---|---|")
    for preset in presets:
        errs = {m: [] for m in ("single", "window", "noise", "budget")}
        for q in range(sequences):
            ests = []
            rows = run_sequence(preset, first_seed + q, 30, variant, estimates=ests)
            for m in errs:
                errs[m].append([])
            for k in range(5, len(rows)):
                truth, f, _, wf, _, _ = rows[k]
                if f is not None:
                    errs["single"][-1].append(abs(np.log(f / truth)))
                if wf is not None:
                    errs["window"][-1].append(abs(np.log(wf / truth)))
                for m in ("noise", "budget"):
                    y = _objects_pooled(ests[max(0, k - 29): k + 1], m == "budget")
                    if y is not None:
                        errs[m][-1].append(abs(y - np.log(truth)))

        cells = [_ratio_cell(errs[m], errs["single"]) for m in ("window", "noise", "budget")]
        print(f"| {preset} | {sequences} | {100 * np.median(np.concatenate(errs['single'])):.2f} "
              f"| {' | '.join(cells)} |", flush=True)


#: max_uncertainty values the gate part tries: the node's default (0.05, config/fcop.yaml) and
#: one tighter and one looser.
GATES = (0.02, 0.05, 0.1)


def gate(presets, sequences, first_seed, variant):
    """What a node's ``max_uncertainty`` lets through on the window part's static sequences:
    per value, the share of window updates (from the sixth frame on) whose std_rel is at most
    it, and the median and p90 |error| of those and the share of them beyond 5%: how often a
    robot gets CameraInfo, and how good what it gets is."""
    print("\n| preset | max_uncertainty | published updates | their median / p90 abs error % "
          "| published beyond 5% |")
    print("|---|---|---|---|---|")
    for preset in presets:
        err, std = [], []
        for q in range(sequences):
            for k, (t, _, _, wf, ws, _) in enumerate(run_sequence(preset, first_seed + q, 30,
                                                                   variant)):
                if k >= 5 and wf is not None:
                    err.append(abs(np.log(wf / t)))
                    std.append(ws)
        err, std = np.array(err), np.array(std)
        for g in GATES:
            out = err[std <= g]
            cells = (f"{100 * np.median(out):.2f} / {100 * np.percentile(out, 90):.2f} | "
                     f"{100 * np.mean(out > 0.05):.1f}%" if out.size else "- | -")
            print(f"| {preset} | {g:g} | {100 * out.size / err.size:.0f}% | {cells} |",
                  flush=True)


def zoom(presets, zoom_sequences, first_seed, variant):
    """What keeps a zoom sequence from being within 5% for good in 15 frames: the window's
    restart (frames from the zoom to the first restart after it) or the sequence's own frames
    (the median |error| of the single frames after the zoom, which no window averages away
    when a static scene repeats the same predictor errors every frame)."""
    print("\n| preset | zoom sequences | within 5% for good in 15 frames | restarted within 3 "
          "frames | window coverage of 2 std_rel after the zoom | not within 15 frames: restart "
          "delay; median abs error % of the frames after the zoom, single / window at the end |")
    print("|---|---|---|---|---|---|")
    for preset in presets:
        within, prompt, misses, cover = 0, 0, [], []
        for q in range(zoom_sequences):
            for factor in (1.25, 0.8):
                rows, delay = zoom_sequence(preset, first_seed + 100 + q, variant, factor)
                restart = next((i for i, r in enumerate(rows) if r[5]), None)
                within += delay <= 15
                prompt += restart is not None and restart <= 3
                cover += [abs(np.log(r[3] / r[0])) <= 2 * r[4] for r in rows if r[3] is not None]
                if delay > 15:
                    # A sequence whose frames all go unanswered after the zoom (its objects
                    # left the view) has no single-frame error: "no frame", not a NaN and
                    # numpy's warning about an empty mean.
                    answered = [abs(np.log(r[1] / r[0])) for r in rows if r[1] is not None]
                    single = f"{100 * np.median(answered):.1f}" if answered else "no frame"
                    end = (f"{100 * abs(np.log(rows[-1][3] / rows[-1][0])):.1f}"
                           if rows[-1][3] else "none")
                    misses.append(f"x{factor} seed {first_seed + 100 + q}: "
                                  f"{'none' if restart is None else restart}; "
                                  f"{single} / {end}")
        n = 2 * zoom_sequences
        print(f"| {preset} | {n} | {within} | {prompt} | {100 * np.mean(cover):.0f}% | "
              f"{', '.join(misses) or '-'} |", flush=True)


def main() -> None:
    global OPTIONS, OBJECTS, ORBIT_DEG, GIVEN_PP, RENEW
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=HelpFormatter)
    ap.add_argument(
        "--frames", type=int, default=60, help="frames per preset for single-frame figures"
    )
    ap.add_argument("--sequences", type=int, default=40,
                    help="static sequences per preset")
    ap.add_argument("--zoom-sequences", type=int, default=8,
                    help="zoom sequences per preset and zoom direction")
    held = ap.add_mutually_exclusive_group()
    for k, name in enumerate(SEEDS):
        if name != "tuning":
            held.add_argument(f"--{name}", dest="variant", action="store_const", const=name,
                              help=f"the {ORDINALS[k - 1]}held-out seeds and error model "
                              "instead")
    ap.add_argument("--parts", nargs="+", default=["single", "bias", "window"],
                    choices=["single", "bias", "window", "zoom", "preset_bias", "pipes",
                             "weights", "tau", "objects", "gate"],
                    help="zoom (not run by default): what keeps each zoom sequence from "
                    "settling, the restart or the frames themselves; preset_bias (not run by "
                    "default): fcop_ros's signed median over --bias-frames frames of each full "
                    "preset; pipes (not run by default): a JPEG'd NOCS image alone and in "
                    "`predicted`, on --frames frames; weights (not run by default): "
                    "what ranks the objects' errors within a frame, over --bias-frames frames; "
                    "objects (not run by default): a window that pools each object over its "
                    "frames first, on the window part's static sequences (a trial, not kept); "
                    "gate (not run by default): the share of window updates each "
                    "max_uncertainty lets through, and their errors")
    ap.add_argument("--bias-frames", type=int, default=2000,
                    help="frames per preset for preset_bias")
    ap.add_argument("--objects", type=int, default=None,
                    help="objects per scene (default: 1 to 6 at random)")
    ap.add_argument("--set", nargs="+", default=[], metavar="NAME=VALUE",
                    help="fcop_ros's EstimatorOptions other than the defaults, e.g. "
                    "object_tau=0.03 (a trial; the figures in the docs use the defaults)")
    ap.add_argument("--orbit", type=float, default=ORBIT_DEG, metavar="DEG",
                    help="the camera's orbit about the scene per frame in the window's and "
                    "zooms' sequences (a trial: how much the window averages as the view "
                    "changes; the figures in the docs use 2)")
    ap.add_argument("--given-principal-point", action="store_true",
                    help="the sequences' estimates get the true principal point instead of "
                    "assuming the image centre (a trial: what the window loses to it)")
    ap.add_argument("--first-sequence", type=int, default=None, metavar="SEED",
                    help="the sequences' first seed instead of the error model's (a trial: "
                    "other draws of the same world)")
    ap.add_argument("--renew", nargs="+", default=[], choices=RENEWABLE, metavar="FAMILY",
                    help="draw these persistent error families of the sequences anew in every "
                    f"frame ({', '.join(RENEWABLE)}; a diagnostic of what the window averages)")
    ap.add_argument("--world", nargs="+", default=[], metavar="NAME=VALUE",
                    help="the sequences' error-family bounds other than the presets' own, e.g. "
                    "principal_point=0 (a trial)")
    args = ap.parse_args()
    OBJECTS = args.objects
    ORBIT_DEG, GIVEN_PP, RENEW = args.orbit, args.given_principal_point, tuple(args.renew)
    for item in args.world:
        name, _, value = item.partition("=")
        # Of the bound's own type: a pixel count stays an integer, which its draw keeps whole.
        kind = type(getattr(WORLD_PRESETS["predicted"], name))
        WORLD[name] = kind(float(value)) if kind is not bool else value.lower() in ("1", "true")
    given = {}
    for item in args.set:
        name, _, value = item.partition("=")
        default = getattr(EstimatorOptions(), name)
        given[name] = type(default)(value)
    OPTIONS = EstimatorOptions(**given)
    if given or OBJECTS is not None or ORBIT_DEG != 2.0 or GIVEN_PP or WORLD or RENEW:
        print(f"settings: {given or 'defaults'}; objects per scene: {OBJECTS or '1 to 6'}; "
              f"orbit {ORBIT_DEG:g} deg per frame; principal point "
              f"{'given' if GIVEN_PP else 'assumed at the centre'} in the sequences; "
              f"world {WORLD or 'as the presets'}; renewed every frame: "
              f"{', '.join(RENEW) or 'none'}\n")
    try:
        import pycolmap  # noqa: F401
        have_colmap = True
    except ImportError:
        have_colmap = False
        print("pycolmap is not installed (pip install '.[bench]'): no P4Pf rows\n")
    variant = args.variant or "tuning"
    frame_seed, seq_seed = SEEDS[variant]
    if args.first_sequence is not None:
        seq_seed = args.first_sequence
    print(
        f"{'tuning' if variant == 'tuning' else 'HELD-OUT'} set: error model '{variant}', "
        f"frames from seed {frame_seed}, sequences from seed {seq_seed}\n"
    )
    presets = ["sensor", "predicted"]
    if "single" in args.parts:
        single_frames(presets, args.frames, frame_seed, variant, have_colmap)
    if "bias" in args.parts:
        bias(args.frames, frame_seed, variant)
    if "window" in args.parts:
        window(presets, args.sequences, seq_seed, variant, args.zoom_sequences)
    if "zoom" in args.parts:
        zoom(presets, args.zoom_sequences, seq_seed, variant)
    if "preset_bias" in args.parts:
        preset_bias(presets, args.bias_frames, frame_seed, variant)
    if "pipes" in args.parts:
        pipes(args.frames, frame_seed, variant)
        jpeg_parts(args.frames, frame_seed, variant)
    if "weights" in args.parts:
        weights(presets, args.bias_frames, frame_seed, variant)
    if "tau" in args.parts:
        tau(presets, args.frames, frame_seed, variant)
    if "gate" in args.parts:
        gate(presets, args.sequences, seq_seed, variant)
    if "objects" in args.parts:
        objects(presets, args.sequences, seq_seed, variant)


if __name__ == "__main__":
    main()
