"""What ``--record`` writes: the viewer configs show it, and each message is logged at its header
stamp."""

from __future__ import annotations

import json
from pathlib import Path


def test_the_viewer_configs_show_what_record_writes_and_are_installed() -> None:
    import yaml

    from multi_robot_mapper.ros import recording

    repo = Path(__file__).resolve().parents[2]
    layout = json.loads((repo / "config" / "foxglove_layout.json").read_text())
    panels = layout["configById"]
    scene = panels["3D!mrm_map"]
    assert scene["followTf"] == "map"
    shown = {topic for topic, settings in scene["topics"].items() if settings["visible"]}
    assert {recording.GLOBAL_MAP[0], recording.GLOBAL_GRID[0]} <= shown
    assert recording.trajectory_topic("robot1") in shown
    assert panels["DiagnosticSummary!mrm_diagnostics"]["topicToRender"] == "/diagnostics"
    rviz = yaml.safe_load((repo / "config" / "multi_robot_mapper.rviz").read_text())
    manager = rviz["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == "map"
    displays = manager["Displays"]
    displays += [d for group in displays for d in group.get("Displays", [])]
    topics = {d["Topic"]["Value"]: d for d in displays if "Topic" in d}
    for topic in (recording.GLOBAL_MAP[0], recording.GLOBAL_GRID[0]):
        assert topics[topic]["Topic"]["Durability Policy"] == "Transient Local"  # latched
    assert recording.trajectory_topic("robot1") in topics
    assert any(d["Class"] == "rviz_default_plugins/TF" for d in displays)
    setup = (repo / "setup.py").read_text()
    assert 'glob("config/*.json")' in setup and 'glob("config/*.rviz")' in setup


def test_a_recorded_message_is_logged_at_its_header_stamp() -> None:
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import OccupancyGrid
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    from visualization_msgs.msg import Marker, MarkerArray

    from multi_robot_mapper.ros.recording import cdr_header_stamp

    header = Header(stamp=Time(sec=1_000_000_123, nanosec=250_000_000), frame_id="map")
    markers = MarkerArray(markers=[Marker(header=header, ns="global_map/robot1")])
    assert cdr_header_stamp(serialize_message(markers), array=True) == 1_000_000_123.25
    assert cdr_header_stamp(serialize_message(MarkerArray()), array=True) is None
    for message in (OccupancyGrid(header=header), DiagnosticArray(header=header)):
        assert cdr_header_stamp(serialize_message(message)) == 1_000_000_123.25
