"""multi_robot_mapper: segment maps from several robots without odometry or known relative poses.

Layers (imports point one way only):
    core  pure numpy/scipy algorithms, one module per pipeline stage
    io    files and messages (CARMEN logs, YAML configuration, ROS message conversion)
    ros   rclpy nodes (thin adapters)        cli   the ``mrm`` command line
"""

__version__ = "0.1.0"
