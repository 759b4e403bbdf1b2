"""fcop_eval_nocs on frames written in the NOCS dataset layout from rendered scenes, checked
against the original loader's conventions (BGR coord PNG, flipped z, 255 background)."""
import csv

import cv2
import numpy as np
import pytest

from fcop_ros import estimate_focal
from fcop_ros.tools import nocs_eval as ne
from fcop_ros.core.pose import rotation_angle_deg
from fcop_ros.synthetic import random_scene, render

FX, FY, CX, CY = ne.INTRINSICS["real275"]


def scene_frames(seed, n=3):
    """Rendered frames at REAL275 intrinsics (fx = fy = 591.0125 for the renderer)."""
    rng = np.random.default_rng(seed)
    objs, _, table = random_scene(rng, 5, FX)
    out = []
    for k in range(n):
        for o in objs:
            o.translation = o.translation + rng.normal(0, 0.01, 3)
        out.append(render(objs, FX, 640, 480, principal_point=(CX, CY), table=table))
    return out


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    root = tmp_path_factory.mktemp("real_test")
    truth = {}
    for s in range(2):
        for k, fr in enumerate(scene_frames(s)):
            prefix = root / f"scene_{s + 1}" / f"{k:04d}"
            ne.write_frame(prefix, fr.depth, fr.nocs, fr.mask,
                           {o.instance_id: 1 + o.instance_id % 6 for o in fr.objects})
            truth[prefix] = fr
    return root, truth


def reference_coord(path):
    """The original NOCS loader's lines, verbatim in effect."""
    coord_map = cv2.imread(str(path))[:, :, :3]
    coord_map = coord_map[:, :, (2, 1, 0)]
    coord_map = np.array(coord_map, dtype=np.float32) / 255
    coord_map[:, :, 2] = 1 - coord_map[:, :, 2]
    return coord_map


def test_loader_matches_the_nocs_conventions(dataset):
    root, truth = dataset
    prefix, fr = next(iter(truth.items()))
    depth, nocs, mask = ne.load_frame(prefix, root)
    np.testing.assert_array_equal(nocs[mask > 0],
                                  reference_coord(str(prefix) + "_coord.png")[mask > 0])
    raw_mask = cv2.imread(str(prefix) + "_mask.png")[:, :, 2]
    assert (raw_mask[fr.mask == 0] == 255).all()
    np.testing.assert_array_equal(mask, fr.mask.astype(np.int32))
    obj = fr.mask > 0
    assert np.abs(nocs[obj] - fr.nocs[obj]).max() <= 0.5 / 255 + 1e-6
    assert np.nanmax(np.abs(depth[obj] - fr.depth[obj])) <= 0.0005 + 1e-6
    # The coord PNG on disk is BGR with z flipped: its first channel holds 1 - z.
    raw = cv2.imread(str(prefix) + "_coord.png")
    iy, ix = np.argwhere(obj)[0]
    assert abs(raw[iy, ix, 0] / 255 - (1 - fr.nocs[iy, ix, 2])) <= 0.5 / 255 + 1e-6
    assert abs(raw[iy, ix, 2] / 255 - fr.nocs[iy, ix, 0]) <= 0.5 / 255 + 1e-6


def test_a_pixel_without_prediction_stays_without_one(tmp_path):
    """A newcomer's review: the loader's flip made an all-zero coord pixel (no prediction) the
    point (0, 0, 1) of the shape, where the node's nocs_dataset convention keeps it zero."""
    from msg_adapters import depth_to_image, mask_to_image, nocs_to_image
    from msg_adapters.input_images import frame_from_images

    coord = np.full((4, 4, 3), 128, np.uint8)
    coord[1, 2] = 0
    cv2.imwrite(str(tmp_path / "x_coord.png"), coord)
    nocs = ne.load_coord(tmp_path / "x_coord.png")
    assert (nocs[1, 2] == 0).all() and nocs[0, 0, 2] == pytest.approx(1 - 128 / 255)
    # The node reads the same pixels through nocs_convention 'nocs_dataset' alike.
    rgb = (coord[:, :, ::-1] / 255.0).astype(np.float32)  # the PNG's values as RGB in [0, 1]
    _, node_nocs, _ = frame_from_images(
        depth_to_image(np.ones((4, 4), np.float32), "32FC1"), nocs_to_image(rgb, "rgb8"),
        mask_to_image(np.ones((4, 4), np.uint8), "mono8"), nocs_convention="nocs_dataset")
    np.testing.assert_allclose(node_nocs, nocs, atol=1e-6)


def test_loaded_frames_give_focal_and_proper_poses(dataset):
    root, truth = dataset
    for prefix, fr in truth.items():
        depth, nocs, mask = ne.load_frame(prefix, root)
        est = estimate_focal(depth, nocs, mask, (CX, CY), seed=0)
        # 1 mm depth and 8-bit NOCS quantisation; measured up to 0.32% on these frames.
        assert abs(est.focal / FX - 1) < 0.008
        truth_obj = {o.instance_id: o for o in fr.objects}
        for o in est.objects:
            # A wrong channel order or z flip would give a reflection, not a small angle.
            assert np.linalg.det(o.rotation) > 0.999
            assert rotation_angle_deg(o.rotation, truth_obj[o.instance_id].rotation) < 3.0


def test_cli_per_scene_medians_and_csv(dataset, tmp_path, capsys):
    root, truth = dataset
    out = tmp_path / "eval.csv"
    assert ne.main([str(root), "--intrinsics", "real275", "--csv", str(out)]) == 0
    text = capsys.readouterr().out
    assert "| scene_1 |" in text and "| scene_2 |" in text and "| all |" in text
    rows = list(csv.DictReader(open(out)))
    assert len(rows) == 6 and {r["scene"] for r in rows} == {"scene_1", "scene_2"}
    f_true = 0.5 * (FX + FY)
    for r in rows:
        assert float(r["focal_true"]) == pytest.approx(f_true)
        # truth (fx+fy)/2 differs from the rendered fx by 0.07%
        assert abs(float(r["error_pct"])) < 0.9
    assert ne.main([str(tmp_path / "nope"), "--intrinsics", "real275"]) == 2
    assert ne.main([str(root), "--intrinsics", "1,2,3"]) == 2
    assert ne.main([str(root), "--intrinsics", "camera25", "--depth",
                    str(tmp_path / "missing")]) == 2
    capsys.readouterr()


def test_predicted_depth_and_nocs_directories(dataset, tmp_path):
    root, truth = dataset
    pred_d, pred_n = tmp_path / "depth_pred", tmp_path / "nocs_pred"
    for prefix, fr in truth.items():
        rel = prefix.relative_to(root)
        (pred_d / rel).parent.mkdir(parents=True, exist_ok=True)
        # a global scale error
        np.save(str(pred_d / rel) + "_depth.npy", (1.25 * fr.depth).astype(np.float32))
        ne.write_frame(pred_n / rel, fr.depth, fr.nocs, fr.mask, {1: 1})
    rows, summary = ne.evaluate(root, ne.INTRINSICS["real275"], pred_d, pred_n)
    assert summary["all"][1] == 6 and summary["all"][0] < 1.0  # the scale error cancels


def test_camera25_depth_encoding(tmp_path):
    mm = np.array([[0, 1234, 40000]], dtype=np.uint32)
    enc = np.zeros((1, 3, 3), np.uint8)
    enc[..., 1], enc[..., 2] = mm // 256, mm % 256
    enc[0, 0, 1], enc[0, 0, 2] = 32001 // 256, 32001 % 256  # "no depth"
    path = tmp_path / "x_depth.png"
    cv2.imwrite(str(path), enc)
    d = ne.load_depth(path)
    assert np.isnan(d[0, 0]) and d[0, 1] == pytest.approx(1.234) and d[0, 2] == pytest.approx(40.0)


def test_cli_unwritable_csv_is_one_line_and_exit_2(dataset, tmp_path, capsys):
    root, _ = dataset
    (tmp_path / "file").write_text("")
    assert ne.main([str(root), "--intrinsics", "real275", "--csv",
                    str(tmp_path / "file" / "eval.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fcop_eval_nocs: ") and "Not a directory" in err and "\n" not in err


@pytest.mark.parametrize("intrinsics", ["0,0,159.5,119.5", "nan,nan,159.5,119.5",
                                        "600,600,inf,119.5"])
def test_intrinsics_without_a_usable_focal_are_refused(dataset, intrinsics, capsys):
    """A hostile user: '0,0,...' was a ZeroDivisionError traceback, 'nan,...' printed nan
    medians with exit 0."""
    root, _ = dataset
    assert ne.main([str(root), "--intrinsics", intrinsics]) == 2
    assert capsys.readouterr().err.startswith("fcop_eval_nocs: intrinsics fx,fy,cx,cy must be")


def test_an_unreadable_frame_is_a_row_and_the_others_are_estimated(dataset, tmp_path):
    """One frame's missing depth ended the whole run with no CSV (a hostile user's trial)."""
    import shutil
    root, _ = dataset
    copy = tmp_path / "data"
    shutil.copytree(root, copy)
    victim = sorted(copy.rglob("*_depth.png"))[1]
    victim.unlink()
    out = tmp_path / "eval.csv"
    assert ne.main([str(copy), "--intrinsics", "real275", "--csv", str(out)]) == 0
    rows = list(csv.DictReader(open(out)))
    skipped = [r for r in rows if r["reason"].startswith("frame skipped: ")]
    assert len(rows) == 6 and len(skipped) == 1 and str(victim) in skipped[0]["reason"]
    assert all(r["focal"] for r in rows if r not in skipped)


def test_an_unwritable_csv_fails_before_the_first_frame(dataset, tmp_path, capsys, monkeypatch):
    root, _ = dataset
    monkeypatch.setattr(ne, "load_frame", lambda *a: pytest.fail("a frame was read"))
    (tmp_path / "csvdir").mkdir()
    assert ne.main([str(root), "--intrinsics", "real275", "--csv", str(tmp_path / "csvdir")]) == 2
    assert "Is a directory" in capsys.readouterr().err


def test_interrupted_keeps_the_rows_before_and_exits_130(dataset, tmp_path, capsys, monkeypatch):
    root, _ = dataset
    real, calls = ne.load_frame, []

    def load(*args):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args)

    monkeypatch.setattr(ne, "load_frame", load)
    out = tmp_path / "eval.csv"
    assert ne.main([str(root), "--intrinsics", "real275", "--csv", str(out)]) == 130
    assert len(list(csv.DictReader(open(out)))) == 2
    assert "interrupted" in capsys.readouterr().err


def test_ctrl_c_inside_a_compiled_kernel_is_an_interruption(dataset, tmp_path, capsys,
                                                            monkeypatch):
    """numba wraps a KeyboardInterrupt raised inside a kernel in a SystemError; that is Ctrl-C
    too (130, the rows before kept), while any other SystemError still propagates."""
    root, _ = dataset

    def interrupted(*args):
        try:
            raise KeyboardInterrupt
        except KeyboardInterrupt:
            raise SystemError("<built-in function ...> returned a result with an exception set")

    monkeypatch.setattr(ne, "load_frame", interrupted)
    out = tmp_path / "eval.csv"
    assert ne.main([str(root), "--intrinsics", "real275", "--csv", str(out)]) == 130
    assert "interrupted" in capsys.readouterr().err

    def broken(*args):
        raise SystemError("a real bug")

    monkeypatch.setattr(ne, "load_frame", broken)
    with pytest.raises(SystemError, match="a real bug"):
        ne.main([str(root), "--intrinsics", "real275", "--csv", str(out)])
