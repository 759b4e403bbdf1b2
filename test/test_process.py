"""fcop_node as a separate process (the installed executable, Fast DDS profile from config/),
clean shutdown on Ctrl-C, and the ament layout that `ros2 run` relies on (colcon build)."""
import os
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, Image

from fcop_ros.ros.dds import large_image_profile, profile_env_vars
from fcop_ros.synthetic import apply_noise, render_scene
from ros_helpers import (Recorder, as_at_a_terminal, frame_messages, ros_context, spin_until,
                         stamp_ns)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BIN = os.path.dirname(sys.executable)


def _start(cmd, tmp_path, name, env=None):
    out = open(tmp_path / f"{name}.out", "w")
    err = open(tmp_path / f"{name}.err", "w")
    return subprocess.Popen(
        cmd, stdout=out, stderr=err, env=env or os.environ.copy(), preexec_fn=as_at_a_terminal
    ), tmp_path / f"{name}.err"


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
    assert os.access(exe, os.X_OK), (
        "the fcop_node console script is not installed in this environment"
    )
    # The child must read the shipped large-image profile (conftest sets it unless the caller
    # named one): the variable its Fast DDS reads names a file with the same content.
    for var in profile_env_vars():
        assert os.path.isfile(os.environ[var]), (var, os.environ[var])
        with open(os.environ[var]) as fh, open(large_image_profile()) as shipped:
            assert fh.read() == shipped.read(), (
                f"{var} does not name config/fastdds_large_images.xml"
            )
    proc, err = _start([exe, "--ros-args", "-p", "seed:=1", "-r", "__node:=fcop_xproc"],
                       tmp_path, "node")
    try:
        with ros_context() as (ctx, ex):
            tester = Node("xproc_tester", context=ctx)
            pubs = [
                tester.create_publisher(Image, t, qos_profile_sensor_data)
                for t in ("depth", "nocs", "mask")
            ]
            rec = Recorder(tester, CameraInfo, "camera_info")
            ex.add_node(tester)
            assert spin_until(ex, lambda: all(p.get_subscription_count() for p in pubs)
                              and rec.sub.get_publisher_count() > 0, 60), err.read_text()
            sent, resent = [], 0
            for k in range(8):
                fr = apply_noise(render_scene(np.random.default_rng(k), 5, 600.0), "mild",
                                 np.random.default_rng(k))
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
    assert os.access(colcon, os.X_OK), (
        "colcon (colcon-common-extensions) is not installed in this environment"
    )
    src = tmp_path / "ws" / "src" / "fcop_ros"
    src.mkdir(parents=True)
    for name in ("setup.py", "setup.cfg", "package.xml", "resource", "config", "launch",
                 "fcop_ros", "msg_adapters"):
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
    assert (
        prefix / "share" / "ament_index" / "resource_index" / "packages" / "fcop_ros"
    ).is_file()
    # The launch file is installed, and what it names exists in the install tree (`launch` is
    # not on PyPI: it runs here against stand-ins that record what it builds).
    launch_file = prefix / "share" / "fcop_ros" / "launch" / "fcop.launch.py"
    assert launch_file.is_file()
    description = run_launch_file(launch_file, str(prefix))
    node = description.entities[-1]
    assert node.kind == "Node"
    assert os.access(prefix / "lib" / node.kw["package"] / node.kw["executable"], os.X_OK)
    args = {
        a.args[0]: a.kw["default_value"]
        for a in description.entities
        if a.kind == "DeclareLaunchArgument"
    }
    assert args["params_file"] == str(prefix / "share" / "fcop_ros" / "config" / "fcop.yaml")
    assert args["namespace"] == "/camera"
    assert [p.name for p in node.kw["parameters"]] == ["params_file"]
    assert node.kw["namespace"].name == "namespace" and node.kw["name"].name == "node_name"
    # Every remap argument names a topic the node really has (relative, so it follows the
    # namespace).
    topics = {"depth", "nocs", "mask", "camera_info_in", "camera_info"}
    assert {src for src, _ in node.kw["remappings"]} == topics and all(
        args[t] == t for t in topics
    )
    # What `ros2 run fcop_ros fcop_node` does, after `source install/setup.bash`: find the
    # package in the ament index of AMENT_PREFIX_PATH, run <prefix>/lib/fcop_ros/fcop_node.
    script = ("source install/setup.bash && "
              f"prefix=$({sys.executable} -c 'from ament_index_python.packages import "
              "get_package_prefix as g; print(g(\"fcop_ros\"))') && "
              f"{sys.executable} -c 'from fcop_ros.ros.config import config_path; "
              "print(config_path())' && "
              "exec $prefix/lib/fcop_ros/fcop_node --ros-args -r __node:=fcop_colcon "
              "--params-file $prefix/share/fcop_ros/config/fcop.yaml")
    proc = subprocess.Popen(["bash", "-c", script], cwd=ws, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
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


class _Recorded:
    """Stand-in for a launch class: remembers its arguments."""

    def __init__(self, kind, *args, **kw):
        self.kind, self.args, self.kw = kind, args, kw
        self.entities = args[0] if args else []
        self.name = args[0] if args else None


def run_launch_file(path, prefix):
    """Run generate_launch_description() of a launch file with stand-ins for launch and
    launch_ros (not on PyPI) and the real ament index of ``prefix``; return what it built."""
    import importlib.util
    import types
    stubs = {}
    for module, names in (("launch", ["LaunchDescription"]),
                          ("launch.actions", ["DeclareLaunchArgument"]),
                          ("launch.substitutions", ["LaunchConfiguration"]), ("launch_ros", []),
                          ("launch_ros.actions", ["Node"])):
        mod = types.ModuleType(module)
        for name in names:
            setattr(mod, name, lambda *a, _n=name, **k: _Recorded(_n, *a, **k))
        stubs[module] = mod
    saved_modules = {m: sys.modules.get(m) for m in stubs}
    saved_env = os.environ.get("AMENT_PREFIX_PATH")
    sys.modules.update(stubs)
    os.environ["AMENT_PREFIX_PATH"] = prefix
    try:
        spec = importlib.util.spec_from_file_location("fcop_launch", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module.generate_launch_description()
    finally:
        for m, old in saved_modules.items():
            if old is None:
                sys.modules.pop(m, None)
            else:
                sys.modules[m] = old
        if saved_env is None:
            os.environ.pop("AMENT_PREFIX_PATH", None)
        else:
            os.environ["AMENT_PREFIX_PATH"] = saved_env


def test_launch_file_compiles():
    path = os.path.join(ROOT, "launch", "fcop.launch.py")
    with open(path) as fh:
        compile(fh.read(), path, "exec")
