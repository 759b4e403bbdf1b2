"""ament_python package fcop_ros: installable by colcon (ROS machine) and by pip (no ROS).

The ROS 2 client libraries come from the distribution on a ROS machine; without ROS, pip
brings the PyPI wheels of one distribution through the ``kilted`` or ``jazzy`` extra (they
cannot share one environment)."""
import glob

from setuptools import find_packages, setup

package_name = "fcop_ros"
_ROS_PACKAGES = ["rclpy[fastrtps]", "rcl-interfaces", "sensor-msgs", "std-msgs", "geometry-msgs",
                 "visualization-msgs", "diagnostic-msgs", "std-srvs", "builtin-interfaces",
                 "rosgraph-msgs", "ament-index-python", "ament-package"]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["fcop_ros", "fcop_ros.*", "msg_adapters", "msg_adapters.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", sorted(glob.glob("config/*"))),
        ("share/" + package_name + "/launch", sorted(glob.glob("launch/*.launch.py"))),
    ],
    python_requires=">=3.10",
    install_requires=["numpy", "scipy", "opencv-python-headless", "numba", "rosbags>=0.10", "mcap",
                      "matplotlib", "tqdm", "pyyaml"],
    extras_require={
        "kilted": ["ros-" + p for p in _ROS_PACKAGES],
        "jazzy": ["ros-jazzy-" + p for p in _ROS_PACKAGES],
        "test": ["pytest", "pyyaml", "colcon-common-extensions", "setuptools<80", "ruff"],
        "bench": ["pycolmap"],
    },
    zip_safe=True,
    maintainer="fcop_ros developers",
    maintainer_email="fcop-ros@example.com",
    description="Camera focal length from category-level object priors (fCOP) as a ROS 2 node.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "fcop_node = fcop_ros.entry_points:fcop_node",
            "fcop_demo = fcop_ros.entry_points:fcop_demo",
            "fcop_replay = fcop_ros.entry_points:fcop_replay",
            "fcop_make_bag = fcop_ros.entry_points:fcop_make_bag",
            "fcop_eval_nocs = fcop_ros.entry_points:fcop_eval_nocs",
        ],
    },
)
