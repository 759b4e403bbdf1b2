"""Start fcop_node with its parameters and remaps:

    ros2 launch fcop_ros fcop.launch.py namespace:=/camera [params_file:=my.yaml]
        [nocs:=/nocs_net/coords]

Arguments: namespace (default /camera), node_name (fcop_node), params_file (default: the
installed config/fcop.yaml, keyed /** so it applies under any namespace and name), and the topic
remaps depth, nocs, mask, camera_info_in (inputs) and camera_info (output), each relative to the
namespace unless given as an absolute name.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

PACKAGE = "fcop_ros"
EXECUTABLE = "fcop_node"
PARAMS_FILE = os.path.join("config", "fcop.yaml")  # under share/fcop_ros
TOPICS = ("depth", "nocs", "mask", "camera_info_in", "camera_info")


def generate_launch_description():
    default_params = os.path.join(get_package_share_directory(PACKAGE), PARAMS_FILE)
    args = [
        DeclareLaunchArgument("namespace", default_value="/camera",
                              description="Namespace of the node and its topics"),
        DeclareLaunchArgument("node_name", default_value=EXECUTABLE,
                              description="Name of the node"),
        DeclareLaunchArgument("params_file", default_value=default_params,
                              description="Parameters file (ROS 2 YAML)"),
    ]
    args += [DeclareLaunchArgument(t, default_value=t,
                                   description=f"Topic for '{t}' (relative to the namespace)")
             for t in TOPICS]
    node = Node(
        package=PACKAGE,
        executable=EXECUTABLE,
        name=LaunchConfiguration("node_name"),
        namespace=LaunchConfiguration("namespace"),
        parameters=[LaunchConfiguration("params_file")],
        remappings=[(t, LaunchConfiguration(t)) for t in TOPICS],
        output="screen",
        emulate_tty=True,
    )
    return LaunchDescription(args + [node])
