"""Find the package's config files whether installed by colcon, by pip, or run from the source."""
from __future__ import annotations

import os
import sys

_PACKAGE = "fcop_ros"
# The repository root when run from the source tree: fcop_ros/ros/config.py -> three levels up.
_SOURCE_ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def config_path(name: str = "fcop.yaml") -> str:
    """Path of ``config/<name>``: the ament share directory (colcon), ``<prefix>/share`` (pip
    install), or the source tree (pip install -e, which skips data_files). Raises
    FileNotFoundError naming the places looked at."""
    candidates = []
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
        try:
            candidates.append(os.path.join(get_package_share_directory(_PACKAGE), "config", name))
        # OSError: no AMENT_PREFIX_PATH
        except (PackageNotFoundError, LookupError, ValueError, KeyError, OSError):
            pass
    except ImportError:
        pass
    candidates.append(os.path.join(sys.prefix, "share", _PACKAGE, "config", name))
    candidates.append(os.path.join(_SOURCE_ROOT, "config", name))
    for path in candidates:
        if os.path.isfile(path):
            return path
    raise FileNotFoundError(f"{name} not found in: {', '.join(candidates)}")
