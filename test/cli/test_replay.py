"""``mrm replay``: its default (it merges) and its summary line, and ``--record``'s MCAP file read
back (topics, message counts, the final global map's markers against map.json)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from test_main import mrm, two_robot_bag


def check_summary(line: str, out: Path) -> None:
    """The last line says how many robots merged and names each unmerged one with the reason
    robots.json gives."""
    frames = json.loads((out / "robots.json").read_text())
    unmerged = {r: v for r, v in frames.items() if isinstance(v, str)}
    assert line.startswith(f"{len(frames) - len(unmerged)} of {len(frames)} robots merged"), line
    for robot, why in unmerged.items():
        assert f"{robot} ({why.removeprefix('unmerged: ')})" in line, line


def test_replay_merges_by_default_and_its_last_line_says_who(capsys, tmp_path: Path) -> None:
    bag = two_robot_bag(capsys, tmp_path)
    out = tmp_path / "default"
    code, text, err = mrm(capsys, "replay", bag, "--out", out)
    assert code == 0, err
    assert json.loads((out / "stats.json").read_text())["method"] == "pivot"
    check_summary(text.strip().splitlines()[-1], out)
    # A link no map can reach: robot2 is unmerged, named with its reason; map.png is still
    # written (robot2 in a panel of its own).
    strict = tmp_path / "strict"
    code, text, err = mrm(
        capsys, "replay", bag, "--out", strict, "--set", "merge.link_min_wall=1e3"
    )
    assert code == 0, err
    last = text.strip().splitlines()[-1]
    assert last.startswith("1 of 2 robots merged (reference robot1); unmerged: robot2 ("), last
    check_summary(last, strict)
    assert (strict / "map.png").stat().st_size > 0
    code, text, _ = mrm(capsys, "replay", bag, "--out", tmp_path / "local", "--method", "local")
    assert code == 0 and "0 of 2 robots merged: method 'local'" in text.splitlines()[-1]


def test_a_single_robot_is_merged_as_the_only_robot(capsys, tmp_path: Path) -> None:
    bag = tmp_path / "one"
    assert (
        mrm(capsys, "simulate", "--robots", 1, "--out", bag, "--duration", 3, "--rate", 10)[0] == 0
    )
    code, text, err = mrm(capsys, "replay", bag, "--out", tmp_path / "o")
    assert code == 0, err
    assert text.strip().splitlines()[-1] == (
        "1 of 1 robot merged: robot1 is the only robot (its map frame is map)"
    )


def read_mcap(path: Path) -> list[tuple[str, int, object]]:
    """(topic, log time in ns, decoded message) of every message, in log-time order, decoded
    with the schemas the file carries (as Foxglove does), through rosbags' rosbag2 reader."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    messages = []
    with Reader(path) as reader:
        for connection, stamp, data in reader.messages():
            messages.append(
                (connection.topic, stamp, store.deserialize_cdr(data, connection.msgtype))
            )
    return messages


def frame_segments(markers: list) -> dict[str, np.ndarray]:
    """Each robot's segments in ``map`` from a /global_map array: every keyframe's line list
    moved by the marker's pose."""
    found: dict[str, list[np.ndarray]] = {}
    for marker in markers:
        if not marker.ns.startswith("global_map/") or marker.action != 0:
            continue
        points = np.array([(p.x, p.y) for p in marker.points]).reshape(-1, 2)
        q = marker.pose.orientation
        yaw = 2.0 * np.arctan2(q.z, q.w)
        rotation = np.array([[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]])
        placed = points @ rotation.T + (marker.pose.position.x, marker.pose.position.y)
        found.setdefault(marker.ns.split("/", 1)[1], []).append(placed.reshape(-1, 4))
    return {robot: np.vstack(parts) for robot, parts in found.items()}


def test_record_writes_the_outputs_as_they_evolved_to_an_mcap_file(capsys, tmp_path: Path) -> None:
    bag = two_robot_bag(capsys, tmp_path, duration=8.0)
    out = tmp_path / "out"
    record = out / "replay.mcap"  # inside --out: written into the new folder
    args = ("replay", bag, "--out", out, "--record", record, "--record-period", 2)
    code, text, err = mrm(capsys, *args)
    assert code == 0, err
    messages = read_mcap(record)
    topics = {topic for topic, _, _ in messages}
    frames = json.loads((out / "robots.json").read_text())
    merged = [r for r, f in frames.items() if not isinstance(f, str)]
    assert topics == {"/global_map", "/global_grid", "/tf", "/diagnostics"} | {
        f"/trajectories/{r}" for r in merged
    }
    counts = {t: sum(1 for m in messages if m[0] == t) for t in topics}
    stats = json.loads((out / "stats.json").read_text())
    # 8 s of scans, a merge every 2 s of bag time after the first scan, then the final one.
    assert stats["snapshots"] == 3
    assert counts["/global_map"] == counts["/tf"] == counts["/diagnostics"] == 4
    assert "recorded 4 merges (/diagnostics 4, /global_grid 4, /global_map 4, /tf 4" in text
    stamps = [stamp for _, stamp, _ in messages]
    assert stamps == sorted(stamps)
    # Each global map is stamped (header and log time) with its snapshot's bag time; the last
    # is the replay's own result: its markers are map.json's segments.
    maps = [(stamp, m) for topic, stamp, m in messages if topic == "/global_map"]
    for stamp, array in maps:
        header = array.markers[0].header.stamp
        assert header.sec * 10**9 + header.nanosec == stamp
    result = json.loads((out / "map.json").read_text())
    segments, owners = np.array(result["segments"]), np.array(result["segment_robot"])
    final = frame_segments(maps[-1][1].markers)
    assert sorted(final) == merged
    for index, robot in enumerate(result["robots"]):
        if robot in final:
            mine = segments[owners == index]
            assert final[robot].shape == mine.shape
            assert np.allclose(np.sort(final[robot], axis=0), np.sort(mine, axis=0), atol=1e-6)
    first = frame_segments(maps[0][1].markers)
    assert sum(len(s) for s in first.values()) < len(segments)  # the map grew
    diagnostics = [m for topic, _, m in messages if topic == "/diagnostics"][-1]
    names = {status.name: status for status in diagnostics.status}
    assert names["map_merger"].message == (
        "all 2 robots merged" if len(merged) == 2 else f"{len(merged)} of 2 robots merged"
    )
    tf = [m for topic, _, m in messages if topic == "/tf"][-1]
    children = {t.child_frame_id for t in tf.transforms}
    assert {f"{r}/map" for r in merged} | {"robot1/laser", "robot2/laser"} <= children
    draw_frame(tmp_path / "mcap_frame.png", final, counts, maps[-1][0])


def draw_frame(path: Path, frame: dict[str, np.ndarray], counts: dict[str, int], stamp: int):
    """The decoded final /global_map frame as a picture, the file's topics and counts in its
    title (what the test read back, to look at)."""
    from multi_robot_mapper.io import pictures

    figure, ax = pictures.plt.subplots(figsize=(8, 6))
    for robot, segments in frame.items():
        pictures.draw_segments(
            ax, segments, pictures.robot_colors(sorted(frame))[robot], 1.0, robot
        )
    ax.legend(loc="upper right")
    title = f"/global_map at {stamp * 1e-9:.1f} s, read back from the MCAP file\n" + ", ".join(
        f"{topic} {n}" for topic, n in sorted(counts.items())
    )
    pictures.finish_metric_axes(ax, title, pictures.segments_extent(list(frame.values())))
    pictures.save_figure(figure, path)


def test_record_needs_a_merging_method_and_an_mcap_name(capsys, tmp_path: Path) -> None:
    bag = tmp_path / "no-bag-read"
    for args, said in (
        (("--method", "local", "--record", tmp_path / "r.mcap"), "needs --method pivot or ffs"),
        (("--record", tmp_path / "r.bag"), "must end in .mcap"),
    ):
        code, _, err = mrm(capsys, "replay", bag, "--out", tmp_path / "o", *args)
        assert code == 2 and said in err and len(err.strip().splitlines()) == 1, err
