"""``mrm evaluate OUT``: scoring against the bags the replay read, as it read them, and naming
what it expected."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from test_main import mrm, parsers, two_robot_bag
from test_metrics import ROOM, T_MAP_WORLD, circle_path, move_poses

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.simulation import LaserModel, simulate_scan
from multi_robot_mapper.io.bags import RobotRecording, TimedPose, TimedScan, write_recordings
from multi_robot_mapper.io.results import ReplayResult, write_results


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
    from test_recordings import room_drive, ros1_scan, write_ros1_bag, write_truth

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


def room_recordings(shift: float = 0.0) -> tuple[dict[str, RobotRecording], dict[str, np.ndarray]]:
    """Two robots driving circles in ROOM, noise-free scans, reference poses as ground truth."""
    laser = LaserModel(beams=181, range_noise=0.0, dropout=0.0)
    rng = np.random.default_rng(0)
    recordings, references = {}, {}
    for name, cx in (("robot1", 1.3), ("robot2", 2.7)):
        ref = circle_path(cx, 2.0, n=20, radius=0.6)
        stamps = 1_718_000_000.0 + 0.025 * np.arange(20) + shift
        scans = [
            TimedScan(float(t), f"{name}/laser", simulate_scan(ROOM, tuple(p), laser, rng))
            for t, p in zip(stamps, ref, strict=True)
        ]
        truth = [
            TimedPose(float(t), (float(p[0]), float(p[1]), float(p[2])), "world")
            for t, p in zip(stamps, ref, strict=True)
        ]
        recordings[name] = RobotRecording(name, scans, truth)
        references[name] = ref
    return recordings, references


def write_estimate(out: Path, references: dict[str, np.ndarray], drop: int = 0) -> None:
    stamps = 1_718_000_000.0 + 0.025 * np.arange(20)
    write_results(
        out,
        ReplayResult(
            method="reference",
            robots=sorted(references),
            map_segments=se2.transform_segments(T_MAP_WORLD, ROOM),
            segment_robot=np.zeros(4, dtype=np.int64),
            trajectories={
                r: (stamps[drop:], move_poses(T_MAP_WORLD, ref)[drop:])
                for r, ref in references.items()
            },
            robot_frames={r: (0.0, 0.0, 0.0) for r in references},
            stats={},
        ),
    )


def mrm_evaluate(
    capsys: pytest.CaptureFixture[str], out: Path, bag: Path, *extra: str
) -> tuple[int, str, str]:
    from multi_robot_mapper.cli.main import main

    code = main(["evaluate", str(out), "--bag", str(bag), *extra])
    printed, err = capsys.readouterr()
    return code, printed, err


def test_cli_scores_a_reference_replay(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    recordings, references = room_recordings()
    bag = write_recordings(tmp_path / "run", recordings)
    out = tmp_path / "out"
    write_estimate(out, references, drop=2)  # first two scans of each robot left unposed
    code, printed, err = mrm_evaluate(capsys, out, bag, "--json")
    assert code == 0, err
    saved = json.loads((out / "metrics.json").read_text())
    assert json.loads(printed) == saved
    assert saved["robots_merged"] == 2 and saved["robots_total"] == 2
    assert saved["ate_rmse_m"] < 1e-6
    assert (saved["scans_total"], saved["scans_unposed"]) == (40, 4)
    assert saved["pair_success"] == pytest.approx(34 / 38)
    # Noise-free scans of the room, map = the room's walls: every point lies on the map
    # (ranges go through the bag as float32, hence micrometres, not zero).
    assert saved["map_error_m"] < 1e-5 and saved["map_coverage"] == 1.0
    assert saved["reference_points"] == 40 * 181
    assert saved["method"] == "reference"

    code, table, _ = mrm_evaluate(capsys, out, bag)
    assert code == 0
    assert "robots merged      2 / 2" in table and "robot2" in table


def test_cli_user_errors_are_one_line_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    recordings, references = room_recordings()
    bag = write_recordings(tmp_path / "run", recordings)
    out = tmp_path / "out"

    def refused(bag_path: Path, words: str) -> None:
        code, _, err = mrm_evaluate(capsys, out, bag_path)
        assert code == 2 and err.count("\n") == 1 and words in err, err

    refused(bag, "no such result folder")
    write_estimate(out, references)
    (tmp_path / "broken.mcap").write_bytes(b"junk")
    refused(tmp_path / "broken.mcap", "broken.mcap")
    shifted, _ = room_recordings(shift=1e-3)  # another bag: stamps 1 ms later
    refused(write_recordings(tmp_path / "shifted", shifted), "matches no scan")
    del recordings["robot2"]
    refused(write_recordings(tmp_path / "one_robot", recordings), "robot2")
