"""fcop_eval_nocs: focal length error on NOCS-format datasets (REAL275 / CAMERA25 layout).

A frame is a prefix P with P_mask.png, P_coord.png, P_depth.png and P_meta.txt (P_color.png is
not needed). Conventions of the original NOCS loader, followed exactly:
- coord: read as 8-bit BGR, reordered to RGB, divided by 255, z flipped (z = 1 - z; all-zero
  pixels, no prediction, stay zero, as in the node's nocs_dataset convention);
- mask: the third channel of the 8-bit image, 255 = background, other values instance ids;
- depth: uint16 millimetres (REAL275), or 3 channels encoding depth = G * 256 + R with 32001
  meaning no depth (CAMERA25);
- meta: one line per instance "instance_id class_id model_name"; class 0 = not an object.
Predicted depth (--depth DIR) is read from DIR/<same relative path>_depth.png (uint16 mm) or
_depth.npy (float metres); predicted NOCS (--nocs DIR) from DIR/<same path>_coord.png.
The truth is f = (fx + fy) / 2 of the given intrinsics (fx and fy differ by 0.14% on REAL275).
"""
from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from msg_adapters.input_images import to_fcop_convention

from .cli import from_ctrl_c

INTRINSICS = {
    "real275": (591.0125, 590.16775, 322.525, 244.11084),
    "camera25": (577.5, 577.5, 319.5, 239.5),
}


def parse_intrinsics(text: str):
    """'real275', 'camera25' or 'fx,fy,cx,cy'."""
    if text.lower() in INTRINSICS:
        return INTRINSICS[text.lower()]
    try:
        fx, fy, cx, cy = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(
            f"intrinsics must be real275, camera25 or fx,fy,cx,cy; got {text!r}") from None
    if not (0 < fx < math.inf and 0 < fy < math.inf and math.isfinite(cx)
            and math.isfinite(cy)):
        raise ValueError(f"intrinsics fx,fy,cx,cy must be finite, the focal lengths positive; "
                         f"got {text!r}")
    return fx, fy, cx, cy


def _imread(path: Path, flags=cv2.IMREAD_UNCHANGED) -> np.ndarray:
    # Checked first: OpenCV's imread warns on stderr of a missing file, beside our own word.
    if not Path(path).is_file():
        raise FileNotFoundError(f"image not found: {path}")
    img = cv2.imread(str(path), flags)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path}")
    return img


def load_coord(path: Path) -> np.ndarray:
    """(H,W,3) float32 NOCS from a *_coord.png, as the NOCS loader does it, but for all-zero
    pixels: they stay zero (no prediction), as the node's ``nocs_convention: nocs_dataset``
    keeps them, where the loader's flip made them (0, 0, 1), a point of the shape."""
    coord = _imread(path, cv2.IMREAD_COLOR)[:, :, (2, 1, 0)].astype(np.float32) / 255.0
    return to_fcop_convention(coord)


def load_mask(path: Path) -> np.ndarray:
    """(H,W) int32 instance ids with 255 (background) turned into 0."""
    mask = _imread(path, cv2.IMREAD_COLOR)[:, :, 2].astype(np.int32)
    mask[mask == 255] = 0
    return mask


def load_depth(path: Path) -> np.ndarray:
    """(H,W) float32 metres, NaN where there is no depth."""
    if path.suffix == ".npy":
        d = np.load(path).astype(np.float32)
        d[~(d > 0)] = np.nan
        return d
    raw = _imread(path)
    if raw.ndim == 3:  # CAMERA25 encoding
        raw = raw[:, :, 1].astype(np.uint32) * 256 + raw[:, :, 2]
        raw = np.where(raw == 32001, 0, raw)
    elif raw.dtype != np.uint16:
        raise ValueError(f"{path}: depth must be uint16 millimetres or the 3-channel CAMERA "
                         f"encoding, got {raw.dtype}")
    d = raw.astype(np.float32) / 1000.0
    d[raw == 0] = np.nan
    return d


def load_meta(path: Path) -> dict[int, int]:
    """{instance_id: class_id} of the real objects (class 0 lines dropped)."""
    out = {}
    for line in path.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 2 and int(parts[1]) != 0:
            out[int(parts[0])] = int(parts[1])
    return out


def find_frames(root: Path):
    """Frame prefixes (sorted) under root: every *_mask.png with a *_coord.png beside it."""
    return sorted(p.with_name(p.name[: -len("_mask.png")]) for p in root.rglob("*_mask.png")
                  if p.with_name(p.name[: -len("_mask.png")] + "_coord.png").exists())


def load_frame(prefix: Path, root: Path, depth_dir: Path | None = None,
               nocs_dir: Path | None = None):
    """depth (m), nocs and mask of one frame, with predicted depth / NOCS when given; instances
    not listed as objects in the meta file are removed from the mask."""
    rel = prefix.relative_to(root)
    if depth_dir is None:
        depth = load_depth(Path(str(prefix) + "_depth.png"))
    else:
        base = depth_dir / rel
        npy, png = Path(str(base) + "_depth.npy"), Path(str(base) + "_depth.png")
        depth = load_depth(npy if npy.exists() else png)
    coord_path = Path(str(prefix if nocs_dir is None else nocs_dir / rel) + "_coord.png")
    nocs = load_coord(coord_path)
    mask = load_mask(Path(str(prefix) + "_mask.png"))
    meta = Path(str(prefix) + "_meta.txt")
    if meta.exists():
        objects = load_meta(meta)
        mask[~np.isin(mask, list(objects))] = 0
    return depth, nocs, mask


def write_frame(prefix: Path, depth: np.ndarray, nocs: np.ndarray, mask: np.ndarray,
                classes: dict[int, int]) -> None:
    """Write a frame in the NOCS layout (the inverse of the loader), e.g. from a rendered
    scene."""
    prefix.parent.mkdir(parents=True, exist_ok=True)
    mm = np.where(np.isfinite(depth) & (depth > 0), np.round(depth * 1000.0), 0)
    cv2.imwrite(str(prefix) + "_depth.png", np.clip(mm, 0, 65535).astype(np.uint16))
    rgb = np.stack([nocs[..., 0], nocs[..., 1], 1.0 - nocs[..., 2]], -1)
    rgb[mask == 0] = 0
    cv2.imwrite(str(prefix) + "_coord.png",
                np.clip(np.round(rgb * 255), 0, 255).astype(np.uint8)[..., ::-1])
    m = np.where(mask > 0, mask, 255).astype(np.uint8)
    cv2.imwrite(str(prefix) + "_mask.png", m)
    lines = [f"{iid} {cls} model_{iid}" for iid, cls in sorted(classes.items())]
    Path(str(prefix) + "_meta.txt").write_text("\n".join(lines) + "\n")


CSV_FIELDS = ["scene", "frame", "focal_true", "focal", "error_pct", "objects", "inlier_ratio",
              "reason"]


def evaluate(root, intrinsics, depth_dir=None, nocs_dir=None, out_csv=None,
             use_principal_point=True, progress=None, options=None):
    """Estimate every frame (with ``options``, an EstimatorOptions; default fcop_ros's); return
    (rows, per-scene medians) and write the per-frame CSV. ``progress(done, total)`` is called
    once the CSV is open (done 0) and after every frame's row."""
    from ..core import estimate_focal
    from ..core.camera import true_focal

    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"dataset directory not found: {root}")
    frames = find_frames(root)
    if not frames:
        raise FileNotFoundError(f"no frame (*_mask.png with *_coord.png) under {root}")
    fx, fy, cx, cy = intrinsics
    f_true = true_focal(fx, fy)
    rows = []
    # Opened first and written row by row: a --csv that cannot be written fails before hours of
    # estimation, and an interrupted run keeps the frames before.
    try:
        fh = None if out_csv is None else open(out_csv, "w", newline="")
    except OSError as exc:
        raise OSError(f"cannot write --csv {out_csv}: {exc.strerror or exc}") from None
    try:
        writer = None if fh is None else csv.DictWriter(fh, fieldnames=CSV_FIELDS)
        if writer is not None:
            writer.writeheader()
            fh.flush()
        if progress:
            progress(0, len(frames))
        for n, prefix in enumerate(frames):
            rel = prefix.relative_to(root)
            scene = str(rel.parent) if str(rel.parent) != "." else root.name
            row = {"scene": scene, "frame": rel.name, "focal_true": f_true, "focal": "",
                   "error_pct": "", "objects": 0, "inlier_ratio": 0.0}
            try:  # one unreadable frame of a dataset is a row with its reason, not the end
                depth, nocs, mask = load_frame(prefix, root, depth_dir, nocs_dir)
                pp = (cx, cy) if use_principal_point else None
                est = estimate_focal(depth, nocs, mask, pp, options=options, seed=n)
            except (OSError, ValueError) as exc:
                row["reason"] = f"frame skipped: {exc}"
            else:
                err = None if est.focal is None else 100.0 * (est.focal / f_true - 1.0)
                row.update({"focal": "" if est.focal is None else round(est.focal, 4),
                            "error_pct": "" if err is None else round(err, 4),
                            "objects": len(est.objects),
                            "inlier_ratio": round(est.inlier_ratio, 4), "reason": est.reason})
            rows.append(row)
            if writer is not None:
                writer.writerow(row)
                fh.flush()
            if progress:
                progress(n + 1, len(frames))
    finally:
        if fh is not None:
            fh.close()
    scenes = {}
    for r in rows:
        scenes.setdefault(r["scene"], []).append(r)
    summary = {s: _median_abs(rs) for s, rs in sorted(scenes.items())}
    summary["all"] = _median_abs(rows)
    return rows, summary


def _median_abs(rows):
    errs = [abs(r["error_pct"]) for r in rows if r["error_pct"] != ""]
    return (float(np.median(errs)) if errs else float("nan"), len(errs), len(rows))


def build_parser() -> argparse.ArgumentParser:
    from .cli import HelpFormatter

    ap = argparse.ArgumentParser(prog="fcop_eval_nocs", description=__doc__,
                                 formatter_class=HelpFormatter,
                                 epilog="exit codes:\n  0   done (a frame that cannot be "
                                        "read is a CSV row with its reason)\n"
                                        "  2   unusable input (missing "
                                        "directory, no frame, bad --intrinsics, a --csv that "
                                        "cannot be written)\n  130 interrupted (the CSV, "
                                        "if it was opened, holds the frames before)")
    ap.add_argument("dir", help="dataset directory (scenes of *_mask.png, *_coord.png, "
                                "*_depth.png, *_meta.txt)")
    ap.add_argument("--intrinsics", required=True,
                    help="real275, camera25 or fx,fy,cx,cy (required)")
    ap.add_argument("--depth", default="sensor", help="'sensor' or a directory of predicted depth")
    ap.add_argument("--nocs", default="gt", help="'gt' or a directory of predicted *_coord.png")
    ap.add_argument("--csv", default="nocs_eval.csv", help="per-frame results")
    ap.add_argument("--image-centre", action="store_true",
                    help="assume the principal point at the image centre (as the paper does) "
                         "instead of cx, cy")
    return ap


def _quiet_opencv() -> None:
    """OpenCV's own warnings off stderr (an unreadable image is a CSV row with its reason)."""
    try:
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_ERROR)
    except AttributeError:  # an OpenCV build without its logging module
        pass


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    done = []  # [(frames done, frames)] once the CSV is open: what Ctrl-C leaves

    def progress(n, total):
        done[:] = [(n, total)]

    _quiet_opencv()
    try:
        intr = parse_intrinsics(args.intrinsics)
        depth_dir = None if args.depth == "sensor" else Path(args.depth)
        nocs_dir = None if args.nocs == "gt" else Path(args.nocs)
        for d, what in ((depth_dir, "--depth"), (nocs_dir, "--nocs")):
            if d is not None and not d.is_dir():
                raise FileNotFoundError(f"{what} directory not found: {d}")
        t0 = time.perf_counter()
        rows, summary = evaluate(args.dir, intr, depth_dir, nocs_dir, args.csv,
                                 not args.image_centre, progress=progress)
    # OSError: missing input, or a --csv that cannot be written
    except (OSError, ValueError) as exc:
        print(f"fcop_eval_nocs: {exc}", file=sys.stderr)
        return 2
    except (KeyboardInterrupt, SystemError) as exc:
        if not from_ctrl_c(exc):  # Ctrl-C inside a compiled kernel: numba's SystemError
            raise
        kept = (f"{args.csv} holds the {done[0][0]} of {done[0][1]} frames done before"
                if done else f"{args.csv} not written")
        print(f"fcop_eval_nocs: interrupted; {kept}", file=sys.stderr)
        return 130
    print(f"{len(rows)} frames in {time.perf_counter() - t0:.1f} s; median |focal error| per "
          f"scene (frames with an estimate / frames):\n")
    print("| scene | median error % | frames |")
    print("|---|---|---|")
    for scene, (med, n_ok, n) in summary.items():
        print(f"| {scene} | {med:.2f} | {n_ok}/{n} |")
    print(f"\nper-frame results: {args.csv}")
    return 0


if __name__ == "__main__":  # python -m: as the console script, signals included
    from fcop_ros.entry_points import fcop_eval_nocs

    raise SystemExit(fcop_eval_nocs())
