"""The relations metric (Kümmerle et al. 2009) on trajectories with known errors, and
``mrm evaluate --relations`` end to end, with and without a log giving the relations' clock."""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_recordings import ros1_scan, scan_reading, write_ros1_bag

from multi_robot_mapper.cli.main import main
from multi_robot_mapper.core import se2
from multi_robot_mapper.evaluation.relations import (
    MATCHED,
    UNPOSED,
    WITHOUT_SCAN,
    Relations,
    RelationsFormatError,
    combine,
    read_relations,
    relation_errors,
)
from multi_robot_mapper.io.results import ReplayResult, write_results

STAMPS = 500.0 + 0.25 * np.arange(10)  # the relations' clock
PAIRS = [(i, i + 1) for i in range(9)] + [(0, 7), (2, 9)]


def path_poses() -> np.ndarray:
    """Ten poses along a curve, turning as they go (a laser's true path)."""
    s = np.arange(10.0)
    return np.column_stack((0.4 * s, np.sin(0.5 * s), 0.3 * s - 1.0))


def true_relations(poses: np.ndarray) -> Relations:
    first = np.array([i for i, _ in PAIRS])
    second = np.array([j for _, j in PAIRS])
    return Relations(STAMPS[first], STAMPS[second], se2.between_each(poses[first], poses[second]))


def write_relations_file(path: Path, relations: Relations) -> Path:
    lines = ["# timestamp1 timestamp2 x y z roll pitch yaw"]
    for t1, t2, motion in zip(relations.first, relations.second, relations.motion, strict=True):
        x, y, yaw = (repr(float(v)) for v in motion)
        lines.append(f"{t1:.6f} {t2:.6f} {x} {y} 0.000000 0.000000 0.000000 {yaw}")
    path.write_text("\n".join(lines) + "\n")
    return path


def involving(k: int) -> np.ndarray:
    return np.array([k in pair for pair in PAIRS])


def test_the_true_trajectory_in_any_frame_has_no_error() -> None:
    poses = path_poses()
    moved = se2.compose_each(np.tile([5.0, -3.0, 2.0], (10, 1)), poses)  # another map frame
    errors = relation_errors(true_relations(poses), STAMPS, moved)
    assert np.all(errors.status == MATCHED)
    assert np.max(errors.translation_m) < 1e-12 and np.max(errors.rotation_rad) < 1e-12


def test_a_pose_moved_10_cm_errs_by_10_cm_on_its_relations_only() -> None:
    poses = path_poses()
    estimate = poses.copy()
    estimate[4] = se2.compose(poses[4], (0.1, 0.0, 0.0))  # 10 cm ahead, in its own frame
    errors = relation_errors(true_relations(poses), STAMPS, estimate)
    np.testing.assert_allclose(errors.translation_m[involving(4)], 0.1, atol=1e-12)
    np.testing.assert_allclose(errors.translation_m[~involving(4)], 0.0, atol=1e-12)
    np.testing.assert_allclose(errors.rotation_rad, 0.0, atol=1e-12)
    summary = errors.summary()
    share = involving(4).mean()  # 2 of 11 relations
    assert summary["translation_mean_m"] == pytest.approx(0.1 * share)
    assert summary["translation_std_m"] == pytest.approx(0.1 * math.sqrt(share * (1 - share)))
    assert (summary["matched"], summary["relations"]) == (11, 11)


def test_a_pose_turned_in_place() -> None:
    """Turned by d about its own origin: as the second scan of a relation only the rotation errs
    (d); as the first, the other scan's position is seen turned: 2 |t| sin(d / 2)."""
    poses = path_poses()
    estimate = poses.copy()
    turn = 0.05
    estimate[2] = se2.compose(poses[2], (0.0, 0.0, turn))
    relations = true_relations(poses)
    errors = relation_errors(relations, STAMPS, estimate)
    np.testing.assert_allclose(errors.rotation_rad[involving(2)], turn, atol=1e-12)
    second = relations.second == STAMPS[2]  # (1, 2)
    first = relations.first == STAMPS[2]  # (2, 3) and (2, 9)
    np.testing.assert_allclose(errors.translation_m[second], 0.0, atol=1e-12)
    expected = 2.0 * np.hypot(*relations.motion[first, :2].T) * math.sin(turn / 2)
    np.testing.assert_allclose(errors.translation_m[first], expected, atol=1e-12)


def test_unposed_and_unknown_scans_are_counted_not_scored() -> None:
    poses = path_poses()
    estimate = poses.copy()
    estimate[5] = np.nan  # the method left scan 5 unposed
    relations = true_relations(poses)
    # Scan 8 is not in the trajectory's robot at all.
    keep = np.arange(10) != 8
    errors = relation_errors(relations, STAMPS[keep], estimate[keep])
    assert np.count_nonzero(errors.status == UNPOSED) == np.count_nonzero(involving(5))
    assert np.count_nonzero(errors.status == WITHOUT_SCAN) == np.count_nonzero(involving(8))
    assert np.all(np.isnan(errors.translation_m[errors.status != MATCHED]))
    summary = errors.summary()
    assert summary["matched"] == 11 - 2 - 2
    assert summary["translation_mean_m"] < 1e-12


def test_stamps_match_within_a_millisecond_only() -> None:
    poses = path_poses()
    relations = true_relations(poses)
    assert np.all(relation_errors(relations, STAMPS + 0.0009, poses).status == MATCHED)
    assert np.all(relation_errors(relations, STAMPS + 0.0011, poses).status == WITHOUT_SCAN)


def test_several_robots_score_each_relation_once() -> None:
    poses = path_poses()
    relations = true_relations(poses)
    wrong = poses.copy()
    wrong[:, 0] *= 2.0  # a robot whose trajectory is stretched
    first = relation_errors(relations, STAMPS[:6], poses[:6])  # scans 0-5
    second = relation_errors(relations, STAMPS[4:], wrong[4:])  # scans 4-9, overlapping
    both = combine([first, second])
    assert np.all(both.status[[0, 1, 2, 3, 4]] == MATCHED)  # (0,1) .. (4,5) by the first
    assert np.max(both.translation_m[:5]) < 1e-12  # the first robot's (right) scores
    assert both.status[9] == WITHOUT_SCAN  # (0, 7) spans both runs: no robot has it whole
    assert np.all(both.status[5:9] == MATCHED)  # (5,6) .. (8,9) by the second robot
    assert np.min(both.translation_m[5:9]) > 0.1


@settings(max_examples=40, deadline=None)
@given(
    st.floats(-50, 50),
    st.floats(-50, 50),
    st.floats(-math.pi, math.pi),
    st.lists(st.floats(-0.2, 0.2), min_size=30, max_size=30),
)
def test_errors_do_not_depend_on_the_map_frame(
    x: float, y: float, theta: float, noise: list[float]
) -> None:
    poses = path_poses()
    estimate = poses + np.reshape(noise, (10, 3))
    relations = true_relations(poses)
    here = relation_errors(relations, STAMPS, estimate)
    moved = se2.compose_each(np.tile([x, y, theta], (10, 1)), estimate)
    there = relation_errors(relations, STAMPS, moved)
    np.testing.assert_allclose(there.translation_m, here.translation_m, atol=1e-9)
    np.testing.assert_allclose(there.rotation_rad, here.rotation_rad, atol=1e-9)


def test_relations_files(tmp_path: Path) -> None:
    poses = path_poses()
    path = write_relations_file(tmp_path / "r.relations", true_relations(poses))
    read = read_relations(path)
    assert len(read) == 11
    np.testing.assert_allclose(read.motion, true_relations(poses).motion)
    bad = tmp_path / "bad.relations"
    bad.write_text("# header\n1 2 3 4 5 6 7 8\n1 2 3 nan 5 6 7 8\n")
    with pytest.raises(RelationsFormatError, match="line 3: expected 8 finite numbers"):
        read_relations(bad)
    bad.write_text("# nothing\n")
    with pytest.raises(RelationsFormatError, match="no relation"):
        read_relations(bad)


# --- mrm evaluate --relations -----------------------------------------------------------------


BAG_STAMPS = 1_000_000_000.0 + 0.1 * np.arange(10)  # what a converter rewrote them to


def replay_result(out: Path, stamps: np.ndarray, estimate: np.ndarray) -> Path:
    posed = np.isfinite(estimate[:, 0])
    write_results(
        out,
        ReplayResult(
            method="local",
            robots=["robot"],
            map_segments=np.zeros((0, 4)),
            segment_robot=np.zeros(0, dtype=np.int64),
            trajectories={"robot": (stamps[posed], estimate[posed])},
            robot_frames={"robot": None},
            stats={},
        ),
    )
    return out


def evaluate(capsys: pytest.CaptureFixture[str], *args: object) -> tuple[int, str, str]:
    code = main(["evaluate", *map(str, args)])
    printed, err = capsys.readouterr()
    return code, printed, err


def test_cli_relations_on_the_trajectory_stamps(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    poses = path_poses()
    estimate = poses.copy()
    estimate[4] = se2.compose(poses[4], (0.1, 0.0, 0.0))
    out = replay_result(tmp_path / "out", STAMPS, estimate)
    relations = write_relations_file(tmp_path / "r.relations", true_relations(poses))
    code, printed, err = evaluate(capsys, out, "--relations", relations)
    assert code == 0, err
    share = 2 / 11
    std = 0.1 * math.sqrt(share * (1 - share))
    assert "relations          11 of 11 matched" in printed
    assert f"translational    {0.1 * share:.4f} ± {std:.4f} m" in printed
    saved = json.loads((out / "metrics.json").read_text())["relations"]
    assert saved["translation_mean_m"] == pytest.approx(0.1 * share)
    assert saved["rotation_mean_deg"] == pytest.approx(0.0, abs=1e-9)


def test_cli_relations_through_the_log_of_the_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The bag's stamps were rewritten (1e9 + 0.1 k s): the log the bag was made from gives
    each scan its stamp on the relations' clock (its k-th FLASER line is scan k)."""
    poses = path_poses()
    bag = write_ros1_bag(
        tmp_path / "run.bag",
        {"/scan": [(t, ros1_scan(t, scan_reading(2.0))) for t in BAG_STAMPS]},
    )
    log = tmp_path / "run.clf.gz"
    with gzip.open(log, "wt") as stream:
        for t in STAMPS:
            stream.write(f"FLASER 3 1.0 1.0 1.0 0 0 0 0 0 0 {t:.6f} host {t:.6f}\n")
    estimate = poses.copy()
    estimate[7] = np.nan  # unposed
    out = replay_result(tmp_path / "out", BAG_STAMPS, estimate)
    relations = write_relations_file(tmp_path / "r.relations", true_relations(poses))
    args = ("--relations", relations, "--bag", bag, "--relation-stamps", log, "--json")
    code, printed, err = evaluate(capsys, out, *args)
    assert code == 0, err
    saved = json.loads(printed)["relations"]
    assert (saved["matched"], saved["unposed"], saved["without_scan"]) == (8, 3, 0)
    assert saved["translation_mean_m"] < 1e-9
    # Without the log, no relation stamp names a scan of the bag.
    code, printed, _ = evaluate(capsys, out, "--relations", relations, "--bag", bag, "--json")
    assert code == 0 and json.loads(printed)["relations"]["without_scan"] == 11
    # A log of another length cannot be the bag's.
    short = tmp_path / "short.clf"
    short.write_text("FLASER 3 1.0 1.0 1.0 0 0 0 0 0 0 500.0 host 500.0\n")
    code, _, err = evaluate(capsys, out, *args[:4], "--relation-stamps", short)
    assert code == 2 and "1 readable FLASER lines for the bag's 10 scans" in err
    assert err.count("\n") == 1


def test_cli_relations_user_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = replay_result(tmp_path / "out", STAMPS, path_poses())
    relations = write_relations_file(tmp_path / "r.relations", true_relations(path_poses()))
    broken = tmp_path / "broken.relations"
    broken.write_text("1 2 3\n")
    for args, words in (
        ((), "give --bag (reference poses) or --relations"),
        (("--relations", tmp_path / "none"), "no such file"),
        (("--relations", broken), "line 1: expected 8 finite numbers"),
        (("--relations", relations, "--relation-stamps", relations), "needs --relations and"),
    ):
        code, _, err = evaluate(capsys, out, *args)
        assert code == 2 and words in err and err.count("\n") == 1, err
