"""fcop_node as a separate process (the installed executable, Fast DDS profile from config/),
clean shutdown on Ctrl-C, and the ament layout that `ros2 run` relies on (colcon build)."""
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from fcop_ros.dds import large_image_profile, profile_env_vars
from fcop_ros.synthetic import apply_noise, render_scene
from ros_helpers import Recorder, frame_messages, ros_context, spin_until, stamp_ns

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)


def _start(cmd, tmp_path, name, env=None):
    out = open(tmp_path / f"{name}.out", "w")
    err = open(tmp_path / f"{name}.err", "w")
    return subprocess.Popen(cmd, stdout=out, stderr=err, env=env or os.environ.copy()), tmp_path / f"{name}.err"


def _interrupt(proc, timeout=20.0) -> int:
    proc.send_signal(signal.SIGINT)
    try:
        return proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        raise


def test_installed_node_across_processes_answers_640x480(tmp_path):
    exe = os.path.join(BIN, "fcop_node")
    assert os.access(exe, os.X_OK), "the fcop_node console script is not installed in this environment"
    # The child must read the shipped large-image profile (conftest sets it unless the caller
    # named one): the variable its Fast DDS reads names a file with the same content.
    for var in profile_env_vars():
        assert os.path.isfile(os.environ[var]), (var, os.environ[var])
        with open(os.environ[var]) as fh, open(large_image_profile()) as shipped:
            assert fh.read() == shipped.read(), f"{var} does not name config/fastdds_large_images.xml"
    proc, err = _start([exe, "--ros-args", "-p", "seed:=1", "-r", "__node:=fcop_xproc"], tmp_path, "node")
    try:
        with ros_context() as (ctx, ex):
            tester = Node("xproc_tester", context=ctx)
            pubs = [tester.create_publisher(Image, t, qos_profile_sensor_data) for t in ("depth", "nocs", "mask")]
            rec = Recorder(tester, CameraInfo, "camera_info")
            ex.add_node(tester)
            assert spin_until(ex, lambda: all(p.get_subscription_count() for p in pubs)
                              and rec.sub.get_publisher_count() > 0, 60), err.read_text()
            sent, resent = [], 0
            for k in range(8):
                fr = apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "mild", np.random.default_rng(k))
                stamp = 1_000_000_000 * (100 + k)
                msgs = frame_messages(fr, stamp)
                sent.append(stamp)
                # Best effort, like a camera: a sample may be lost (e.g. before the remote reader
                # has matched this writer). Send again; what arrived twice is dropped as duplicate.
                for attempt in range(3):
                    for p, m in zip(pubs, msgs):
                        p.publish(m)
                    if spin_until(ex, lambda: len(rec) >= k + 1, 10):
                        break
                    resent += 1
                assert len(rec) == k + 1, err.read_text()
            assert [stamp_ns(m) for m in rec.msgs] == sent
            # Without the profile about 1 in 100 such images arrives; with it, nearly all do.
            assert resent <= 2
            assert all(abs(m.k[0] / 600.0 - 1) < 0.03 for m in rec.msgs)
            assert rec.msgs[-1].width == 640 and rec.msgs[-1].height == 480
            tester.destroy_node()
        assert _interrupt(proc) == 0
        assert "Traceback" not in err.read_text()
    finally:
        if proc.poll() is None:
            proc.kill()


def test_colcon_build_gives_the_ros2_run_layout(tmp_path):
    colcon = os.path.join(BIN, "colcon")
    assert os.access(colcon, os.X_OK), "colcon (colcon-common-extensions) is not installed in this environment"
    src = tmp_path / "ws" / "src" / "fcop_ros"
    src.mkdir(parents=True)
    for name in ("setup.py", "setup.cfg", "package.xml", "resource", "config", "fcop_ros", "msg_adapters"):
        path = os.path.join(ROOT, name)
        (shutil.copytree if os.path.isdir(path) else shutil.copy)(path, src / name)
    ws = tmp_path / "ws"
    res = subprocess.run([colcon, "build"], cwd=ws, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    prefix = ws / "install" / "fcop_ros"
    exe = prefix / "lib" / "fcop_ros" / "fcop_node"
    assert os.access(exe, os.X_OK)
    assert (prefix / "share" / "fcop_ros" / "config" / "fcop.yaml").is_file()
    assert (prefix / "share" / "fcop_ros" / "package.xml").is_file()
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "fcop_ros").is_file()
    # What `ros2 run fcop_ros fcop_node` does, after `source install/setup.bash`: find the
    # package in the ament index of AMENT_PREFIX_PATH, run <prefix>/lib/fcop_ros/fcop_node.
    script = ("source install/setup.bash && "
              f"prefix=$({sys.executable} -c 'from ament_index_python.packages import get_package_prefix as g; "
              "print(g(\"fcop_ros\"))') && "
              f"{sys.executable} -c 'from fcop_ros.config import config_path; print(config_path())' && "
              "exec $prefix/lib/fcop_ros/fcop_node --ros-args -r __node:=fcop_colcon "
              "--params-file $prefix/share/fcop_ros/config/fcop.yaml")
    proc = subprocess.Popen(["bash", "-c", script], cwd=ws, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        deadline = time.monotonic() + 30
        ready = False
        lines = []
        while time.monotonic() < deadline and not ready:
            line = proc.stderr.readline()
            lines.append(line)
            ready = "fcop_node ready" in line
            if proc.poll() is not None:
                break
        assert ready, "".join(lines) + proc.stdout.read()
        assert _interrupt(proc) == 0
        out = proc.stdout.read()
        assert str(prefix / "share" / "fcop_ros" / "config" / "fcop.yaml") in out
        rest = proc.stderr.read()
        assert "Traceback" not in rest, rest
    finally:
        if proc.poll() is None:
            proc.kill()
