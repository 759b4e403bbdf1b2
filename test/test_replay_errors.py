"""fcop_replay under bad arguments and unwritable outputs: one clear line on stderr, the
documented exit code (2 unusable input or arguments, 4 outputs not writable), never a
traceback; estimates.csv written as it goes, so a full disk loses only what follows."""
import contextlib
import csv
import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from fcop_ros.tools import make_bag as mb
from fcop_ros.tools import replay as rp
from fcop_ros.tools import estimates_csv, replay_offline, replay_params
from fcop_ros.tools.bagio import BagSource
from fcop_ros.ros.params import PARAMETERS
from fcop_ros.synthetic import SequenceSpec

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    path = tmp_path_factory.mktemp("bags") / "in"
    mb.make_bag(path, SequenceSpec(8, 160, 120, 150.0, None, None, "mild", 4), seed=3)
    return path


def args(bag, out, *extra):
    return [str(bag), "--depth-topic", mb.TOPICS["depth"], "--nocs-topic", mb.TOPICS["nocs"],
            "--mask-topic", mb.TOPICS["mask"], "--truth-topic", mb.TOPICS["truth"], "--out",
            str(out), *extra]


def one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("fcop_replay: ") and "Traceback" not in err
    return lines[0]


@contextlib.contextmanager
def read_only_dir(path: Path):
    """A directory nobody can write into, root included (permission bits, else the immutable
    flag)."""
    path.mkdir()
    path.chmod(0o555)
    immutable = False
    try:
        if os.access(path, os.W_OK):  # root ignores permission bits
            immutable = subprocess.run(["chattr", "+i", str(path)],
                                       capture_output=True).returncode == 0
            if not immutable:
                pytest.skip("cannot make a read-only directory on this machine")
        yield path
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(path)], check=True)
        path.chmod(0o755)


INT_1000 = "is not allowed: an integer in [1, 1000]"


@pytest.mark.parametrize("override, expected", [
    ("window_frames:=abc", f"parameter window_frames='abc' from -p {INT_1000}"),
    ("window_frames:=0", f"parameter window_frames=0 from -p {INT_1000}"),
    ("window_frames:=2.5", f"parameter window_frames=2.5 from -p {INT_1000}"),
    # Text to rcl, so to the node (Python's int() took it: the replay ran what the node refuses).
    ("window_frames:=1_000", f"parameter window_frames='1_000' from -p {INT_1000}"),
    ("camera_name:=1", "so quote text (-p camera_name:=\"'text'\""),
    ("focal_min:=30000.0",
     "parameter focal_min=30000.0 from -p is not allowed: it must be below focal_max=20000.0"),
    # The value moved is blamed, not the default it collides with (before: focal_min=50.0).
    ("focal_max:=10", "parameter focal_max=10.0 from -p is not allowed: it must be above "
                      "focal_min=50.0"),
    ("sync_mode:=fuzzy",
     "parameter sync_mode='fuzzy' from -p is not allowed: one of exact, approximate"),
    ("publish_poses:=maybe",
     "parameter publish_poses='maybe' from -p is not allowed: true or false"),
    ("window_frames=3", "-p expects NAME:=VALUE, got 'window_frames=3'"),
    ("window_frames:=", "-p window_frames:= has no value"),
    ("window_frames:=#", "-p window_frames:=# has no value"),
    # What a descriptor cannot say: before, this replay ran until 'fcop_node did not start'.
    ("camera_name:=a b", "parameter camera_name='a b' from -p is not allowed: a string ("),
    # The node's own refusal came after --out was cleared (a hostile user's earlier outputs).
    ("qos_overrides./camera/depth.subscription.depth:=-1",
     "parameter qos_overrides./camera/depth.subscription.depth=-1 from -p is not allowed"),
    ("use_sim_time:=banana", "parameter use_sim_time='banana' from -p is not allowed"),
])
def test_invalid_parameter_value_is_refused(bag, tmp_path, capsys, override, expected):
    assert rp.main(args(bag, tmp_path / "o", "-p", override)) == 2
    assert expected in one_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_misspelt_parameter_name_is_refused_with_the_known_names(bag, tmp_path, capsys):
    assert rp.main(args(bag, tmp_path / "o", "-p", "window_frame:=3")) == 2
    line = one_line(capsys.readouterr().err)
    assert "unknown parameter 'window_frame' from -p (did you mean window_frames?)" in line
    assert all(name in line for name in PARAMETERS)


@pytest.mark.parametrize(
    "content, expected",
    [
        (None, "cannot read --params-file"),
        ("fcop_node:\n  ros__parameters:\n    window_frames: [1\n", "is not valid YAML (line"),
        ("- just\n- a list\n", "is not a ROS 2 parameter file"),
        (
            "other_node:\n  ros__parameters:\n    window_frames: 3\n",
            "has no section for fcop_node (it has: other_node)",
        ),
        (
            "/**:\n  ros__parameters:\n    window_frames: -4\n",
            "parameter window_frames=-4 from --params-file",
        ),
        (
            "/**:\n  ros__parameters:\n    widow_frames: 4\n",
            "unknown parameter 'widow_frames' from --params-file",
        ),
        ("fcop_node:\n  window_frames: 4\n", "section 'fcop_node' has no ros__parameters"),
        # Text to rcl; PyYAML 1.1 read 1000 and a date.
        (
            "/**:\n  ros__parameters:\n    window_frames: 1_000\n",
            "parameter window_frames='1_000' from --params-file",
        ),
        (
            "/**:\n  ros__parameters:\n    camera_name: 2024-01-01\n    focal_min: 2024-01-01\n",
            "parameter focal_min='2024-01-01' from --params-file",
        ),
        ("/**:\n  ros__parameters:\n    window_frames:\n", "window_frames has no value (line 3)"),
        # A file giving both: the one moved from its default is blamed.
        (
            "/**:\n  ros__parameters:\n    focal_min: 50.0\n    focal_max: 40.0\n",
            "parameter focal_max=40.0 from --params-file",
        ),
        # What rcl refuses (a hostile user's trial: the replay took them).
        (
            "/**:\n  ros__parameters:\n    focal_min: &f 100.0\n    focal_max: *f\n",
            "an alias (*name) at line 4: rcl does not take aliases",
        ),
        (
            "fcop_node:\n  ros__parameters:\n    seed: 1\n  other: 2\n",
            "'other' stands beside ros__parameters",
        ),
        (
            "fcop_node:\n  ros_parameters:\n    seed: 1\n",
            "section 'fcop_node' has no ros__parameters (did you mean ros__parameters for "
            "'ros_parameters'?)",
        ),
        # rcl applies sections in file order, a later one winning: here the wildcard's 10.
        (
            "fcop_node:\n  ros__parameters:\n    focal_max: 100.0\n"
            "/**:\n  ros__parameters:\n    focal_max: 10.0\n",
            "parameter focal_max=10.0 from --params-file",
        ),
    ],
)
def test_invalid_params_file_is_refused(bag, tmp_path, capsys, content, expected):
    pf = tmp_path / "params.yaml"
    if content is not None:
        pf.write_text(content)
    assert rp.main(args(bag, tmp_path / "o", "--params-file", str(pf))) == 2
    assert expected in one_line(capsys.readouterr().err)


def test_params_file_sections_for_any_namespace(tmp_path):
    """Sections apply as rcl applies them, in file order with a later value winning (the
    node's own, in any namespace, nested or not, and wildcards alike), then -p; sections of
    other nodes are ignored; documents and repeated sections add up."""
    pf = tmp_path / "p.yaml"
    pf.write_text("other:\n  ros__parameters:\n    window_frames: 999\n"
                  "/**:\n  ros__parameters:\n    window_frames: 9\n    min_window_votes: 40\n"
                  "    use_sim_time: false\n"
                  "/camera/fcop_node:\n  ros__parameters:\n    window_frames: 7\n    seed: 5\n"
                  "robot:\n  arm:\n    fcop_node:\n      ros__parameters:\n"
                  "        min_frames: 3\n"
                  "---\nfcop_node:\n  ros__parameters:\n    focal_min: 40.0\n"
                  "fcop_node:\n  ros__parameters:\n    focal_max: 4500.0\n")
    assert replay_params.load_params_file(pf) == {
        "window_frames": 7, "min_window_votes": 40, "use_sim_time": False, "seed": 5,
        "min_frames": 3, "focal_min": 40.0, "focal_max": 4500.0}
    params = replay_params.node_parameters(
        str(pf), ["seed:=11", "focal_min:=60", "noise_bound_mode:=absolute", "noise_bound:=5"])
    assert params["seed"] == 11 and params["window_frames"] == 7
    # an int for a double
    assert params["focal_min"] == 60.0 and type(params["focal_min"]) is float
    assert params["noise_bound"] == 5.0 and params["noise_bound_mode"] == "absolute"
    parse = replay_params.parse_value
    assert parse("1e3") == 1000.0 and parse("true") is True and parse("x") == "x"


def test_out_is_a_file(bag, tmp_path, capsys):
    out = tmp_path / "o"
    out.write_text("not a directory")
    assert rp.main(args(bag, out)) == 4
    assert f"--out {out} exists and is not a directory" in one_line(capsys.readouterr().err)
    assert out.read_text() == "not a directory"


def test_out_is_read_only(bag, tmp_path, capsys):
    with read_only_dir(tmp_path / "ro") as out:
        assert rp.main(args(bag, out)) == 4
        line = one_line(capsys.readouterr().err)
        # The first failure is the one reported (before the fix a second exception from the
        # cleanup replaced it).
        assert f"cannot write {out}/estimates.csv: " in line
        assert ("Permission denied" in line or "Operation not permitted" in line)
        assert os.listdir(out) == []
        # Below a read-only directory --out cannot even be created.
        assert rp.main(args(bag, out / "sub")) == 4
        assert f"cannot write --out {out}/sub: " in one_line(capsys.readouterr().err)


def test_disk_full_from_the_start(bag, tmp_path, capsys):
    """/dev/full: every write fails with ENOSPC, a real device doing what a full disk does."""
    out = tmp_path / "o"
    out.mkdir()
    (out / "estimates.csv").symlink_to("/dev/full")
    assert rp.main(args(bag, out)) == 4
    line = one_line(capsys.readouterr().err)
    assert f"cannot write {out}/estimates.csv: No space left on device" in line


class _FullAfter:
    """A text file on a disk that fills up after ``lines`` lines."""

    def __init__(self, fh, lines):
        self.fh, self.left = fh, lines

    def write(self, text):
        if self.left <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.left -= text.count("\n")
        return self.fh.write(text)

    def flush(self):
        self.fh.flush()

    def close(self):
        self.fh.close()


def test_disk_full_midway_keeps_the_rows_before_and_says_what_was_lost(
    bag, tmp_path, capsys, monkeypatch
):
    real_open = open

    def open_on_small_disk(path, mode="r", *a, **kw):
        fh = real_open(path, mode, *a, **kw)
        return _FullAfter(fh, 1 + 3) if Path(path).name == "estimates.csv" else fh

    def no_room_for_the_report(*args):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(estimates_csv, "open", open_on_small_disk, raising=False)
    monkeypatch.setattr(replay_offline, "write_report", no_room_for_the_report)
    out = tmp_path / "o"
    assert rp.main(args(bag, out)) == 4
    line = one_line(capsys.readouterr().err)
    assert line.startswith(
        f"fcop_replay: cannot write {out}/estimates.csv: No space left on device; "
    )
    # The rows are written as they come: the three before the disk filled are on disk.
    with real_open(out / "estimates.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and all(abs(float(r["focal_error_pct"])) < 5 for r in rows)
    assert "estimates.csv holds 3 of 4 estimates" in line and "stopped after 4 of 8 frames" in line
    assert "report.png not written" in line  # the second failure is mentioned, not raised instead
    # The output bag was closed properly, with the frames estimated before the stop.
    src = BagSource(out / "fcop_output")
    assert src.counts["/fcop/camera_info"] == 4
    src.close()


def test_subprocess_exit_codes_without_traceback(bag, tmp_path):
    """The installed entry point, as a user runs it."""
    exe = [sys.executable, "-m", "fcop_ros.tools.replay"]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run(exe + args(bag, tmp_path / "o", "-p", "window_frames:=abc"),
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 2 and "window_frames='abc' from -p is not allowed" in one_line(r.stderr)
    (tmp_path / "f").write_text("")
    r = subprocess.run(exe + args(bag, tmp_path / "f"), capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 4 and "exists and is not a directory" in one_line(r.stderr)


def test_the_shipped_config_applies_to_the_replayed_node():
    """Whether config/fcop.yaml is keyed 'fcop_node:' or '/**:', replay finds every parameter in
    it."""
    from fcop_ros.ros.config import config_path
    params = replay_params.node_parameters(None)
    assert set(PARAMETERS) <= set(params)
    for name, spec in PARAMETERS.items():
        assert params[name] == spec.default, name
    assert replay_params.load_params_file(config_path()) == params


def test_a_bag_where_the_output_bag_goes_is_refused_not_deleted(bag, tmp_path, capsys):
    """A hostile user replayed a bag named fcop_output inside --out: the replay cleared it as a
    previous output and wrote its own in its place."""
    import shutil
    inside = tmp_path / "o" / "fcop_output"
    shutil.copytree(bag, inside)
    files = sorted(p.name for p in inside.iterdir())
    assert rp.main(args(inside, tmp_path / "o")) == 2
    assert "where the output bag goes" in one_line(capsys.readouterr().err)
    assert sorted(p.name for p in inside.iterdir()) == files


def test_truth_without_a_focal_length_leaves_the_truth_columns_empty(tmp_path):
    """An uncalibrated driver publishes K all zero: the replay stopped at its first estimate
    as a 'damaged bag' (a division by zero) and lost the rest."""
    from fcop_ros.tools.estimates_csv import EstimatesCsv
    from fcop_ros.tools.replay_base import ReplaySummary
    summary = ReplaySummary()
    table = EstimatesCsv(tmp_path / "e.csv", True, summary)
    for k, truth in enumerate((0.0, float("nan"), 600.0)):
        table.truth(k, truth)
        table.add({"stamp_ns": k, "focal": 601.0, "cx": 1.0, "cy": 1.0, "support": 5,
                   "std_rel": 0.01, "objects": 2})
    table.close()
    rows = (tmp_path / "e.csv").read_text().splitlines()
    assert [r.split(",")[-2:] for r in rows[1:]] == [["", ""], ["", ""], ["600.0000", "0.1667"]]
    assert summary.errors_pct == [pytest.approx(0.1666667)]


@pytest.mark.parametrize("play", [False, True])
def test_one_topic_for_two_images_is_refused(bag, tmp_path, capsys, play):
    """The mask's topic given for the NOCS too: refused before --out is touched or anything is
    played (before, offline, its encoding went unchecked, the node dropped every frame and the
    replay waited out its timeout, then said the machine might be overloaded)."""
    argv = args(bag, tmp_path / "o")
    argv[argv.index("--nocs-topic") + 1] = mb.TOPICS["mask"]
    if play:  # without the options play ignores (each would add a line)
        argv = argv[:argv.index("--truth-topic")] + ["--play"]
    assert rp.main(argv) == 2
    assert ("--nocs-topic, --mask-topic name the same topic"
            in one_line(capsys.readouterr().err))
    assert not (tmp_path / "o").exists()
