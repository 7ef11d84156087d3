"""rclpy nodes: thin adapters from messages to the core and back, and the nodes' configs
(mapper_config, merger_config, params_files: plain dataclasses that load no rclpy, so that the
CLI reads them without ROS)."""
