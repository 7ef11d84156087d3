"""The first hour of a new user: ``mrm``'s help, its messages for the usual mistakes, Ctrl-C,
``mrm replay``'s default (it merges) and its summary line, ``mrm evaluate OUT`` scoring against
the bags the replay read, and ``--record``'s MCAP file read back (topics, message counts, the
final global map's markers against map.json)."""

from __future__ import annotations

import argparse
import io
import json
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from multi_robot_mapper.cli.main import build_parser, main


def mrm(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return code, out, err


def parsers() -> dict[str, argparse.ArgumentParser]:
    top = build_parser()
    found = {"mrm": top}
    for action in top._actions:
        if isinstance(action, argparse._SubParsersAction):
            found.update({f"mrm {n}": p for n, p in action.choices.items()})
    return found


def test_every_option_has_help_that_says_its_default() -> None:
    for name, parser in parsers().items():
        formatter = parser._get_formatter()
        for action in parser._actions:
            if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
                continue
            what = f"{name} {'/'.join(action.option_strings) or action.dest}"
            assert action.help, f"{what} has no help"
            text = formatter._expand_help(action) if action.help else ""
            flag = action.nargs == 0  # store_true: off unless given
            if action.option_strings and not action.required and not flag:
                assert "default" in text, f"{what}: the help does not say the default: {text!r}"


def test_help_has_no_restructuredtext_and_lists_each_command_once(capsys) -> None:
    for name, parser in parsers().items():
        text = parser.format_help()
        assert "``" not in text and ":func:" not in text and ":mod:" not in text, name
    text = parsers()["mrm"].format_help()
    for command in ("demo", "replay", "evaluate", "simulate", "import-bag", "run"):
        lines = [line for line in text.splitlines() if line.strip().startswith(command + " ")]
        assert len(lines) == 1, (command, lines)
    assert "{demo," not in text  # the choices' braces are not a second list


def test_evaluate_given_the_bag_names_the_folder_it_expected(capsys, tmp_path: Path) -> None:
    bag = tmp_path / "sim"
    assert (
        mrm(capsys, "simulate", "--robots", 1, "--out", bag, "--duration", 1, "--rate", 5)[0] == 0
    )
    code, _, err = mrm(capsys, "evaluate", bag, "--bag", bag)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"{bag} is a bag, not a replay result" in err
    assert "the folder that mrm replay --out wrote (map.json" in err
    code, _, err = mrm(capsys, "evaluate", tmp_path, "--bag", bag)  # a folder, no map.json
    assert code == 2 and "a folder without map.json" in err and "mrm replay --out" in err
    code, _, err = mrm(capsys, "evaluate", tmp_path / "nope", "--bag", bag)
    assert code == 2 and "no such result folder" in err


def test_a_missing_input_has_one_wording(capsys, tmp_path: Path) -> None:
    missing = tmp_path / "nope"
    cases = {
        "bag": ("replay", missing, "--out", tmp_path / "o"),
        "log file": ("import-carmen", missing, "--robots", 2, "--out", tmp_path / "b"),
        "params file": ("run", "--robots", "r1", "--params-file", missing),
    }
    for kind, args in cases.items():
        code, _, err = mrm(capsys, *args)
        assert code == 2 and err.strip().endswith(f"error: no such {kind}: {missing}"), err


def two_robot_bag(capsys, folder: Path, duration: float = 8.0) -> Path:
    bag = folder / "sim"
    args = ("--robots", 2, "--out", bag, "--duration", duration, "--rate", 10, "--seed", 3)
    assert mrm(capsys, "simulate", *args)[0] == 0
    return bag


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


def evaluated(capsys, *args: object) -> tuple[dict, str]:
    """``mrm evaluate ARGS --json``: the metrics it printed (also metrics.json) and its stderr."""
    code, printed, err = mrm(capsys, "evaluate", *args, "--json")
    assert code == 0, err
    return json.loads(printed), err


def test_evaluate_alone_scores_against_the_bags_replay_read(
    capsys, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``mrm evaluate OUT``, no --bag: the bag mrm replay read, found from another folder (its
    path was recorded absolute), scored exactly as with --bag, and said so in one line."""
    bag = two_robot_bag(capsys, tmp_path)
    monkeypatch.chdir(tmp_path)
    assert mrm(capsys, "replay", "sim", "--out", "out")[0] == 0  # relative paths
    monkeypatch.chdir(bag)
    out = tmp_path / "out"
    said = f"scoring against the bag(s) mrm replay read: {bag}"
    recorded, err = evaluated(capsys, out)
    assert err == said + "\n"  # on stderr: stdout stays JSON
    given, err = evaluated(capsys, out, "--bag", bag)
    assert recorded == given and err == ""
    assert recorded["bag"] == str(bag) and recorded["scans_total"] == 160
    assert recorded["robots_total"] == 2 and recorded["reference_points"] > 0
    code, table, _ = mrm(capsys, "evaluate", out)
    assert code == 0 and table.startswith(said + "\nmethod: pivot\n"), table
    bag_help = next(a.help for a in parsers()["mrm evaluate"]._actions if a.dest == "bags")
    assert "default: without --relations, the bags mrm replay read" in str(bag_help)


def test_evaluate_names_a_recorded_bag_that_moved_and_an_old_folder_needs_bag(
    capsys, tmp_path: Path
) -> None:
    bag = two_robot_bag(capsys, tmp_path, duration=3.0)
    out = tmp_path / "out"
    assert mrm(capsys, "replay", bag, "--out", out, "--method", "reference")[0] == 0
    moved = bag.rename(tmp_path / "moved")
    code, _, err = mrm(capsys, "evaluate", out)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert f"error: no such bag: {bag} (the bag mrm replay read for {out}" in err
    assert "give --bag with where it is now" in err
    scored, _ = evaluated(capsys, out, "--bag", moved)  # --bag overrides the record
    assert scored["bag"] == str(moved) and scored["robots_merged"] == 2
    (out / "replay.json").unlink()  # a folder from before the record: as before, --bag needed
    code, _, err = mrm(capsys, "evaluate", out)
    assert code == 2 and len(err.strip().splitlines()) == 1, err
    assert "nothing to score against: give --bag (reference poses) or --relations" in err
    assert f"no {out / 'replay.json'}: the replay that made the folder did not record" in err
    assert evaluated(capsys, out, "--bag", moved)[0] == scored


def test_evaluate_reads_the_bag_with_the_options_replay_read_it_with(
    capsys, tmp_path: Path
) -> None:
    """A bag that only reads right with --scan-topics, --names, --beam-geometry and --truth:
    evaluate alone reads it with the recorded ones; one given replaces its record."""
    from test_bag_inputs import room_drive, ros1_scan, write_ros1_bag, write_truth

    stamps, poses, scans = room_drive(60)
    laser = [(t, ros1_scan(t, s, i)) for i, (t, s) in enumerate(zip(stamps, scans, strict=True))]
    bag = write_ros1_bag(tmp_path / "mine.bag", {"/front_laser": laser})
    truth = write_truth(tmp_path / "mine.truth.csv", range(0, 60, 3), stamps, poses)
    options = ("--scan-topics", "/front_laser", "--names", "rover", "--beam-geometry", "carmen")
    out = tmp_path / "out"
    code, _, err = mrm(capsys, "replay", bag, "--out", out, *options, "--truth", truth)
    assert code == 0, err
    recorded, _ = evaluated(capsys, out)
    assert list(recorded["robots"]) == ["rover"] and recorded["scans_total"] == 20
    assert recorded["ate_all_rmse_m"] < 0.05
    assert evaluated(capsys, out, "--bag", bag, *options, "--truth", truth)[0] == recorded
    assert mrm(capsys, "evaluate", out, "--bag", bag)[0] == 2  # not readable without them
    denser = write_truth(tmp_path / "denser.truth.csv", range(0, 60, 2), stamps, poses)
    assert evaluated(capsys, out, "--truth", denser)[0]["scans_total"] == 30

    truth.rename(tmp_path / "elsewhere.csv")
    code, _, err = mrm(capsys, "evaluate", out)
    assert code == 2 and f"error: no such truth file: {truth} (" in err and "give --truth" in err
    bag.rename(tmp_path / "gone.bag")
    code, _, err = mrm(capsys, "evaluate", out)
    assert code == 2 and f"no such bag: {bag}" in err
    # The moved bag's message gives the options to read it with, to copy after --bag.
    assert f"--names rover --scan-topics /front_laser --beam-geometry=carmen --truth {truth}" in err


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


def test_progress_off_a_terminal_is_a_line_per_stage_and_period() -> None:
    from multi_robot_mapper.cli.progress import ProgressBar

    stream = io.StringIO()
    bar = ProgressBar("mrm replay (pivot)", stream=stream, period=1e9)
    for done in range(1, 101):
        bar("mapping robot1" if done <= 50 else "mapping robot2", done, 100)
    bar("merging", 0, 1)
    bar("merging", 1, 1)
    bar.close()
    assert stream.getvalue().splitlines() == [
        "mrm replay (pivot): mapping robot1 1/100 (1%)",
        "mrm replay (pivot): merging 0/1 (0%)",
    ]


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / 100.0  # utime + stime, in clock ticks


@pytest.mark.parametrize("moment", ["importing", "mapping"])
def test_ctrl_c_at_any_moment_is_one_line_and_exit_130(tmp_path: Path, moment: str, capsys) -> None:
    bag = two_robot_bag(capsys, tmp_path, duration=20.0)
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", "replay", str(bag)]
    command += ["--out", str(tmp_path / "out")]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([sys.executable, "-c", "import multi_robot_mapper.cli.replay"], check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    importing = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    # Judged by the CPU time the process has used, not by the clock (a busy machine): a
    # quarter of the imports in, or well past them.
    threshold = 0.25 * importing if moment == "importing" else 2.0 * importing + 1.0
    process = subprocess.Popen(
        command,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 300.0
    while _cpu_seconds(process.pid) < threshold:
        assert process.poll() is None and time.monotonic() < deadline, process.returncode
        time.sleep(0.01)
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().splitlines()[-1] == "mrm replay: interrupted; nothing half-written was left"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    assert not (tmp_path / "out").exists()


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
