"""fcop_ros against alternatives on the same rendered frames and the same correspondences.

    python bench/peers.py [--frames 40]          (pycolmap from the [bench] extra for P4Pf)

Methods: fcop_ros as shipped; the paper's fCOP-IS taken literally (uniform triplets, 5 px bound,
interval midpoint); the paper's RANSAC variant; P4Pf with LO-RANSAC and focal refinement on each
object's 2D-NOCS correspondences (pycolmap.estimate_and_refine_absolute_pose, needs no depth),
fused over objects by the median; the median of the triplet votes as the floor. All use the
correspondences fcop_ros extracts (same pixels, same NOCS). Prints median / p90 focal error (%),
median object rotation error (deg) and translation error (% of the distance; P4Pf has no metric
scale without depth), the share of frames with an estimate and the time, per noise preset.
"""
from __future__ import annotations

import argparse
from dataclasses import replace
import time

import numpy as np

from fcop_ros import estimate_focal
from fcop_ros.core import PAPER_FCOP_IS
from fcop_ros.core.camera import image_centre
from fcop_ros.core.correspondences import extract_instances
from fcop_ros.core.pose import rotation_angle_deg
from fcop_ros.synthetic import PRESETS, apply_noise, render_scene

LITERAL = PAPER_FCOP_IS


def p4pf(frame, max_points=1000, seed=0):
    """Median over objects of pycolmap's P4Pf + LO-RANSAC + refinement; and {id: rotation}."""
    import pycolmap

    h, w = frame.depth.shape
    cx, cy = image_centre(w, h)
    rng = np.random.default_rng(seed)
    instances = extract_instances(frame.depth, frame.nocs, frame.mask, (cx, cy), rng=rng,
                                  max_pixels=max_points)
    focals, rots = [], {}
    for inst in instances:
        # COLMAP puts the centre of the top-left pixel at (0.5, 0.5).
        uv = inst.x + [cx + 0.5, cy + 0.5]
        cam = pycolmap.Camera(model="SIMPLE_PINHOLE", width=w, height=h,
                              params=[0.8 * w, cx + 0.5, cy + 0.5])
        est = pycolmap.AbsolutePoseEstimationOptions()
        est.estimate_focal_length = True
        est.ransac.max_error = 4.0
        ref = pycolmap.AbsolutePoseRefinementOptions()
        ref.refine_focal_length = True
        ref.refine_extra_params = False
        res = pycolmap.estimate_and_refine_absolute_pose(uv, inst.p - 0.5, cam, est, ref)
        if res is None:
            continue
        f = float(cam.params[0])  # pycolmap refines the camera in place
        if 0.1 * w < f < 100 * w:
            focals.append(f)
            rots[inst.instance_id] = np.asarray(res["cam_from_world"].rotation.matrix())
    return (float(np.median(focals)) if focals else None), rots


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--frames", type=int, default=40)
    args = ap.parse_args()
    try:
        import pycolmap  # noqa: F401
        have_colmap = True
    except ImportError:
        have_colmap = False
        print("pycolmap is not installed (pip install '.[bench]'): the P4Pf row is skipped\n")
    clean = [render_scene(np.random.default_rng(k), 5, 600.0) for k in range(args.frames)]
    methods = {
        "fcop_ros (single frame)": lambda fr, k: estimate_focal(
            fr.depth, fr.nocs, fr.mask, seed=k
        ),
        "paper fCOP-IS literal (5 px)": lambda fr, k: estimate_focal(
            fr.depth, fr.nocs, fr.mask, options=LITERAL, seed=k
        ),
        "paper fCOP-RANSAC": lambda fr, k: estimate_focal(
            fr.depth, fr.nocs, fr.mask, options=replace(LITERAL, method="ransac"), seed=k
        ),
    }
    print(
        f"{args.frames} frames per preset, 640x480, 5 objects, f = 600 px. "
        "Cells: median / p90 |focal error| %, median rotation error deg, median translation error "
        "% of the distance, frames with an estimate, ms per frame\n"
    )
    names = (
        list(methods)
        + (["P4Pf LO-RANSAC + refine (pycolmap), median over objects"] if have_colmap else [])
        + ["median of triplet votes"]
    )
    print("| method | " + " | ".join(PRESETS) + " |")
    print("|---|" + "---|" * len(PRESETS))
    results = {n: [] for n in names}
    for preset in PRESETS:
        frames = [
            apply_noise(fr, preset, np.random.default_rng(1000 + k)) for k, fr in enumerate(clean)
        ]
        for name in names:
            errs, rot, trans, ms = [], [], [], []
            for k, fr in enumerate(frames):
                truth = {o.instance_id: o for o in fr.objects}
                t0 = time.perf_counter()
                trs = {}
                if name.startswith("P4Pf"):
                    f, rots = p4pf(fr, seed=k)  # no depth: no metric translation
                elif name.startswith("median"):
                    est = estimate_focal(fr.depth, fr.nocs, fr.mask, seed=k)
                    f, rots = (float(np.median(est.votes)) if est.votes.size else None), {}
                else:
                    est = methods[name](fr, k)
                    f = est.focal
                    rots = {o.instance_id: o.rotation for o in est.objects}
                    trs = {o.instance_id: o.translation for o in est.objects}
                ms.append(1000 * (time.perf_counter() - t0))
                errs.append(np.nan if f is None else 100 * abs(f / fr.focal - 1))
                rot += [
                    rotation_angle_deg(R, truth[i].rotation) for i, R in rots.items() if i in truth
                ]
                trans += [
                    100
                    * np.linalg.norm(t - truth[i].translation)
                    / np.linalg.norm(truth[i].translation)
                    for i, t in trs.items()
                    if i in truth
                ]
            e = np.array(errs)
            ok = np.isfinite(e)
            rot_text = f"{np.median(rot):.1f}°" if rot else "n/a"
            trans_text = f"{np.median(trans):.1f}%" if trans else "n/a"
            cell = (
                (
                    f"{np.median(e[ok]):.2f} / {np.percentile(e[ok], 90):.2f}, {rot_text}, "
                    f"{trans_text}, {ok.mean():.0%}, {np.median(ms):.0f} ms"
                )
                if ok.any()
                else "-"
            )
            results[name].append(cell)
    for name in names:
        print(f"| {name} | " + " | ".join(results[name]) + " |")


if __name__ == "__main__":
    main()
