"""The layers docs/DESIGN.md draws, checked on every import statement of the package (function
level included): what each folder may import, and which modules stay free of rclpy or of the
message packages, so that they can be used and tested without ROS."""
import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MESSAGES = ("sensor_msgs", "geometry_msgs", "std_msgs", "visualization_msgs", "diagnostic_msgs",
            "std_srvs", "rcl_interfaces", "builtin_interfaces", "rosgraph_msgs")
PLAIN = ("worker", "sync", "throttle", "calibration", "dds", "config", "allocator",
         "command_line", "gate", "tracker", "answers", "intake", "frame_outcome")
WITHOUT_RCLPY = ("params", "diagnostics", "intrinsics", "frame_estimate", "topics")


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> set:
    """Every module an import statement of ``path`` names, relative imports resolved."""
    package = _module(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    out = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else []
            name = ".".join([*base, node.module] if node.module else base)
            out.add(name)
            out.update(f"{name}.{a.name}" for a in node.names)  # a submodule, if it is one
    return out


FILES = sorted([*ROOT.glob("fcop_ros/**/*.py"), *ROOT.glob("msg_adapters/*.py")])


def _under(names, *prefixes):
    return sorted(n for n in names if any(n == p or n.startswith(p + ".") for p in prefixes))


@pytest.mark.parametrize("path", FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_point_down_the_layers(path):
    mod, names = _module(path), _imports(path)
    if mod.startswith("fcop_ros.core"):
        assert not _under(names, "rclpy", *MESSAGES, "msg_adapters", "fcop_ros.ros",
                          "fcop_ros.tools", "fcop_ros.synthetic"), mod
    if mod.startswith("fcop_ros.synthetic"):
        assert not _under(names, "rclpy", *MESSAGES, "msg_adapters", "fcop_ros.ros",
                          "fcop_ros.tools"), mod
    if mod.startswith("msg_adapters"):
        assert not _under(names, "rclpy", "fcop_ros"), mod
    if mod.startswith("fcop_ros.ros"):
        assert not _under(names, "fcop_ros.tools", "fcop_ros.synthetic"), mod
    if mod.split(".")[-1] in PLAIN and mod.startswith("fcop_ros.ros"):
        assert not _under(names, "rclpy", *MESSAGES), mod
    if mod.split(".")[-1] in WITHOUT_RCLPY and mod.startswith("fcop_ros.ros"):
        assert not _under(names, "rclpy"), mod
    if not mod.startswith(("fcop_ros.tools", "fcop_ros.entry_points")):
        assert not _under(names, "fcop_ros.tools"), mod


def test_the_modules_named_here_exist():
    """A renamed module would silently leave its rule."""
    for name in PLAIN + WITHOUT_RCLPY:
        assert (ROOT / "fcop_ros" / "ros" / f"{name}.py").is_file(), name
