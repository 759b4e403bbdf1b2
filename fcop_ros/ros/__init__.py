"""The ROS 2 shell around the estimator: the node, its input synchroniser, the Fast DDS set-up
and where the config files are found. Only this folder (and the tools) import rclpy."""
