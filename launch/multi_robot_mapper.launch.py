"""Launch one robot_mapper per robot and a map_merger (apt-installed ROS 2 Jazzy, colcon).

    ros2 launch multi_robot_mapper multi_robot_mapper.launch.py robots:=robot1,robot2,robot3

Arguments:
  robots        comma-separated robot namespaces (each gets /<robot>/scan -> robot_mapper)
  method        merging method of the map_merger (pivot; ffs once it is built)
  params_file   ROS 2 params file of both nodes (default: the installed
                config/multi_robot_mapper.yaml)
  use_sim_time  true when replaying a bag with its /clock

Without launch (PyPI installs have none): ``mrm run --robots robot1,robot2,robot3``
starts the same nodes in one process.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription

PACKAGE = "multi_robot_mapper"


def _nodes(context, *args, **kwargs):  # OpaqueFunction calls it with the launch context
    robots = [
        name.strip().strip("/")
        for name in LaunchConfiguration("robots").perform(context).split(",")
        if name.strip().strip("/")
    ]
    params_file = LaunchConfiguration("params_file").perform(context)
    use_sim_time = LaunchConfiguration("use_sim_time").perform(context).lower() == "true"
    common = [params_file, {"use_sim_time": use_sim_time}]
    mappers = [
        Node(
            package=PACKAGE,
            executable="robot_mapper",
            name="robot_mapper",
            namespace=robot,
            parameters=common,
            output="screen",
        )
        for robot in robots
    ]
    merger = Node(
        package=PACKAGE,
        executable="map_merger",
        name="map_merger",
        parameters=[
            *common,
            {"robots": ",".join(robots), "method": LaunchConfiguration("method").perform(context)},
        ],
        output="screen",
    )
    return [*mappers, merger]


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(
        get_package_share_directory(PACKAGE), "config", "multi_robot_mapper.yaml"
    )
    return LaunchDescription(
        [
            DeclareLaunchArgument("robots", default_value="robot1,robot2,robot3"),
            DeclareLaunchArgument("method", default_value="pivot"),
            DeclareLaunchArgument("params_file", default_value=default_params),
            DeclareLaunchArgument("use_sim_time", default_value="false"),
            OpaqueFunction(function=_nodes),
        ]
    )
