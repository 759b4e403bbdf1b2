"""package.xml and setup.py declare what the code imports: every third-party module imported by
the installed packages has its rosdep key in package.xml and its PyPI name in setup.py."""
import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# module imported -> (rosdep key or ROS package in package.xml, PyPI requirement in setup.py:
# a plain name in install_requires, or 'ros:<name>' for the ROS wheels of both extras)
DEPENDENCIES = {"rclpy": ("rclpy", "ros:rclpy[fastrtps]"),
                "rcl_interfaces": ("rcl_interfaces", "ros:rcl-interfaces"),
                "ament_index_python": ("ament_index_python", "ros:ament-index-python"),
                "sensor_msgs": ("sensor_msgs", "ros:sensor-msgs"),
                "std_msgs": ("std_msgs", "ros:std-msgs"),
                "geometry_msgs": ("geometry_msgs", "ros:geometry-msgs"),
                "visualization_msgs": ("visualization_msgs", "ros:visualization-msgs"),
                "diagnostic_msgs": ("diagnostic_msgs", "ros:diagnostic-msgs"),
                "std_srvs": ("std_srvs", "ros:std-srvs"),
                "builtin_interfaces": ("builtin_interfaces", "ros:builtin-interfaces"),
                "rosgraph_msgs": ("rosgraph_msgs", "ros:rosgraph-msgs"),
                "numpy": ("python3-numpy", "numpy"), "scipy": ("python3-scipy", "scipy"),
                "cv2": ("python3-opencv", "opencv-python-headless"),
                "numba": ("python3-numba", "numba"),
                "matplotlib": ("python3-matplotlib", "matplotlib"),
                "tqdm": ("python3-tqdm", "tqdm"), "yaml": ("python3-yaml", "pyyaml"),
                "rosbags": ("python3-rosbags-pip", "rosbags>=0.10"),
                "mcap": ("mcap-ros2-support", "mcap")}
OWN = {"fcop_ros", "msg_adapters"}


def imported_modules():
    found = {}
    for pkg in OWN:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                else:
                    continue
                for name in names:
                    top = name.split(".")[0]
                    if top not in sys.stdlib_module_names and top not in OWN:
                        found.setdefault(top, str(path.relative_to(ROOT)))
    return found


def setup_requirements():
    """install_requires, and the ROS wheels' names of setup.py (_ROS_PACKAGES)."""
    tree = ast.parse((ROOT / "setup.py").read_text())
    ros, install = [], []
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "_ROS_PACKAGES":
            ros = ast.literal_eval(node.value)
        if isinstance(node, ast.keyword) and node.arg == "install_requires":
            install = ast.literal_eval(node.value)
    return ros, install


def test_every_import_is_declared():
    root = ET.parse(ROOT / "package.xml").getroot()
    exec_deps = {e.text for e in root.findall("exec_depend")} | {
        e.text for e in root.findall("depend")
    }
    ros, install = setup_requirements()
    for module, where in sorted(imported_modules().items()):
        assert module in DEPENDENCIES, f"{module} (imported in {where}) has no known rosdep key"
        key, req = DEPENDENCIES[module]
        assert key in exec_deps, (
            f"package.xml lacks <exec_depend>{key}</exec_depend> for {module} ({where})"
        )
        if req.startswith("ros:"):
            assert req[4:] in ros, f"setup.py's _ROS_PACKAGES lacks {req[4:]} for {module}"
        else:
            assert req in install, f"setup.py's install_requires lacks {req} for {module}"


def test_test_dependencies_are_declared_once():
    root = ET.parse(ROOT / "package.xml").getroot()
    exec_deps = [e.text for e in root.findall("exec_depend")]
    test_deps = [e.text for e in root.findall("test_depend")]
    assert "python3-pytest" in test_deps and "python3-yaml" in exec_deps
    assert len(set(exec_deps)) == len(exec_deps) and not set(exec_deps) & set(test_deps)


def test_the_package_imports_light_and_reaches_everything_on_use():
    """``import fcop_ros`` loads neither numpy nor rclpy; its estimator names and subpackages
    come on first use (a hostile trial found ``fcop_ros.core`` an AttributeError until
    imported by name, and ``importlib`` among the package's public names)."""
    import subprocess
    code = (
        "import sys, fcop_ros\n"
        "assert not {'numpy', 'rclpy'} & set(sys.modules), sorted(sys.modules)\n"
        "assert 'importlib' not in dir(fcop_ros)\n"
        "assert fcop_ros.core.estimate_focal is fcop_ros.estimate_focal\n"
        "assert fcop_ros.synthetic.__name__ == 'fcop_ros.synthetic'\n"
        "assert 'estimate_focal' in vars(fcop_ros)\n"  # resolved once, then a plain attribute
        "assert 'rclpy' not in sys.modules\n"
        "try:\n    fcop_ros.nothing\nexcept AttributeError as e:\n    print(e)\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "module 'fcop_ros' has no attribute 'nothing'"
