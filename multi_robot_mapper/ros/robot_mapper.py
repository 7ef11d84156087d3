"""``robot_mapper``: one robot's laser scans in, line segments out.

Topics (relative, so ``-r __ns:=/robot1`` gives ``/robot1/scan`` -> ``/robot1/scan_segments``):
  sub ``scan``           sensor_msgs/LaserScan, sensor-data QoS (best effort)
  pub ``scan_segments``  visualization_msgs/Marker LINE_LIST in the scan's frame, stamped with
                         the scan's stamp
Parameters: the fields of :class:`RobotMapperConfig` (``config/robot_mapper.yaml``).
"""

from __future__ import annotations

import sys
import traceback

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan
from visualization_msgs.msg import Marker

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.mapper_config import RobotMapperConfig
from multi_robot_mapper.core.scan import ScanError
from multi_robot_mapper.io.messages import scan_from_msg, seconds_from_stamp, segments_marker
from multi_robot_mapper.ros.parameters import declare_config, on_config_change
from multi_robot_mapper.ros.throttle import ThrottledWarnings


class RobotMapper(Node):
    """Per-robot mapper node (front end for now: scans to segments)."""

    def __init__(self, node_name: str = "robot_mapper", **kwargs: object) -> None:
        super().__init__(node_name, **kwargs)  # type: ignore[arg-type]
        self.config = declare_config(self, RobotMapperConfig)
        self.warnings = ThrottledWarnings(self.get_logger().warning, self.config.warning_period)
        on_config_change(self, RobotMapperConfig, self._apply_config)
        self.scans_received = 0
        self.scans_rejected = 0
        self._segments_pub = self.create_publisher(Marker, "scan_segments", 10)
        self._scan_sub = self.create_subscription(
            LaserScan, "scan", self._on_scan, qos_profile_sensor_data
        )

    def _apply_config(self, config: RobotMapperConfig) -> None:
        self.config = config
        self.warnings.period = config.warning_period

    def _on_scan(self, msg: LaserScan) -> None:
        self.scans_received += 1
        stamp = seconds_from_stamp(msg.header.stamp)
        try:
            segments, valid = extract_scan(scan_from_msg(msg), self.config.extraction)
        except ScanError as exc:
            self.scans_rejected += 1
            self.warnings.warn(
                exc.kind, f"dropped scan (frame '{msg.header.frame_id}', stamp {stamp:.3f}): {exc}"
            )
            return
        except Exception:  # a bug must not take the robot's mapper down with it
            self.scans_rejected += 1
            self.warnings.warn(
                "internal_error",
                f"dropped scan (stamp {stamp:.3f}) after an internal error:\n"
                f"{traceback.format_exc()}",
            )
            return
        for notice in valid.notices:
            self.warnings.warn(notice.kind, f"scan (stamp {stamp:.3f}): {notice.message}")
        self._segments_pub.publish(
            segments_marker(
                segments.segments,
                msg.header,
                namespace="scan_segments",
                width=self.config.segment_marker_width,
            )
        )


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run multi_robot_mapper robot_mapper``)."""
    rclpy.init(args=args)
    try:
        node = RobotMapper()
    except ConfigError as exc:
        print(f"robot_mapper: invalid parameters: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        # A SIGTERM can shut the context down while spin() builds its wait set (an rclpy race);
        # that is a normal shutdown. Anything while the context is still valid is a real error.
        if rclpy.ok():
            raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
