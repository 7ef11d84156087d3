"""What the benches share: where the data and the outputs are, the logs cut into K robots,
the 0.30 m / 5 deg judgement against the reference, and running ``mrm`` in a child.

Every bench imports these from here (``from bench import harness``; the benches run as
``.venv/bin/python -m bench.NAME`` from the repository root) rather than from one another.
The judge that looks past the reference's own errors is :mod:`bench.reference_check`.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib.util
import math
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from multi_robot_mapper.cli.common import add_set_option
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.config import config_from_flat, parse_override
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.local_mapping import Keyframe, LocalMapper, LocalMapperConfig
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.confidence import RIGHT_ANGLE, RIGHT_DISTANCE
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.scan import LaserScanData
from multi_robot_mapper.core.se2 import Pose
from multi_robot_mapper.core.simulation import LaserModel, _arc_length, drive_path, simulate_scan
from multi_robot_mapper.core.worlds import ROUTES, office_world
from multi_robot_mapper.io.carmen import (
    CarmenScan,
    carmen_scan_data,
    monotonic_stamps,
    read_carmen,
)
from multi_robot_mapper.io.recordings import split_runs

FloatArray = NDArray[np.float64]

__all__ = ["RIGHT_ANGLE", "RIGHT_DISTANCE"]  # the tolerance is the confidence's own

# --- where things are -----------------------------------------------------------------------

REPO = Path(__file__).resolve().parents[1]
OUTPUT = REPO / "bench_output"  # git-ignored
FIGURES = REPO / "docs" / "figures"
# ../shared/data beside the clone, or beside the folder of worktrees holding it.
DATA = next(
    (
        folder / "shared" / "data"
        for folder in REPO.parents[:2]
        if (folder / "shared" / "data").is_dir()
    ),
    REPO.parent / "shared" / "data",
)
CARMEN = DATA / "carmen"
BAGS = DATA / "bags"
# The shared logs most benches run on, and the ones the fitted models were fitted on.
LOGS = ("intel", "aces", "fhw", "csail")
FIT_LOGS = ("intel", "aces", "fhw", "csail", "freiburg-079", "edmonton")
# Child processes and the benches that want one core each: the BLAS libraries' own threads off.
ONE_THREAD = {v: "1" for v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}


def carmen_log(name: str) -> Path:
    """The shared CARMEN log ``name`` (``intel``, ``freiburg-079``, ...); it may be absent."""
    return CARMEN / f"{name}.log.gz"


def present_logs(names: Iterable[str]) -> list[str]:
    """The logs of ``names`` that are there; a note on stderr for each one skipped."""
    present = []
    for name in names:
        if carmen_log(name).is_file():
            present.append(name)
        else:
            print(f"{name}: skipped, {carmen_log(name)} not found", file=sys.stderr)
    return present


def require_log(name: str, bench: str) -> Path:
    """The log ``name``, or exit saying where it was looked for."""
    path = carmen_log(name)
    if not path.is_file():
        raise SystemExit(f"{bench}: {path} not found (the real logs live in ../shared/data)")
    return path


def output_folder(*parts: str) -> Path:
    """``bench_output/PARTS`` (created): where a bench writes unless told otherwise."""
    folder = OUTPUT.joinpath(*parts)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def test_helper(name: str) -> ModuleType:
    """The test helper module ``test/NAME.py`` (e.g. ``hostile_streams``), loaded from its
    file under the name ``bench_test_helpers.NAME``: test/ is not a package, and its name
    is the standard library's."""
    module_name = f"bench_test_helpers.{name}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, REPO / "test" / f"{name}.py")
    if spec is None or spec.loader is None:
        raise ImportError(f"no test helper {REPO / 'test' / name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module  # dataclasses look their module up while it loads
    spec.loader.exec_module(module)
    return module


# --- judging against the reference ----------------------------------------------------------


def right(T_found: Pose, T_true: Pose) -> bool:
    """Within the correctness tolerance (0.30 m / 5 deg) of the truth?"""
    dx, dy, dtheta = se2.between(T_true, T_found)
    return bool(np.hypot(dx, dy) < RIGHT_DISTANCE and abs(dtheta) < RIGHT_ANGLE)


def right_matrix(T_found: FloatArray, T_true: FloatArray) -> bool:
    """:func:`right` for 3x3 matrices."""
    return right(se2.pose_from_matrix(T_found), se2.pose_from_matrix(T_true))


def apart(T_a: FloatArray, T_b: FloatArray) -> bool:
    """Are two SE(2) matrices more than the tolerance (0.30 m or 5 deg) apart?"""
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_a) @ T_b)
    return bool(np.hypot(dx, dy) > RIGHT_DISTANCE or abs(dtheta) > RIGHT_ANGLE)


# --- logs cut into K robots -----------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class CutLog:
    """A shared CARMEN log cut into K contiguous runs as ``mrm import-carmen`` cuts it."""

    name: str
    scans: list[CarmenScan]  # the whole log's scans, with their reference poses
    stamps: FloatArray  # their stamps, made strictly increasing (as the import makes them)
    runs: list[tuple[int, int]]  # each robot's [start, stop) of ``scans``


def cut_log(name: str, robots: int, overlap: int = 0) -> CutLog:
    """Log ``name`` cut into ``robots`` runs, each extended ``overlap`` scans back."""
    path = carmen_log(name)
    scans = read_carmen(path)
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in scans]), path.name)
    return CutLog(name, scans, np.asarray(stamps), split_runs(len(scans), robots, overlap))


def mrm(args: list[str], log: Path | None = None) -> float:
    """Run ``mrm ARGS`` in a child process on one BLAS thread from the repository root (its
    output appended to ``log``, or dropped); its wall time in s. RuntimeError if it fails."""
    started = time.perf_counter()
    command = [sys.executable, "-m", "multi_robot_mapper.cli.main", *args]
    env = {**os.environ, **ONE_THREAD}
    if log is None:
        code = subprocess.run(command, stdout=subprocess.DEVNULL, env=env, cwd=REPO).returncode
    else:
        with log.open("a") as out:
            out.write(f"$ mrm {' '.join(args)}\n")
            out.flush()
            code = subprocess.run(
                command, stdout=out, stderr=subprocess.STDOUT, env=env, cwd=REPO
            ).returncode
    if code:
        tail = log.read_text().strip().splitlines()[-1:] if log else []
        raise RuntimeError(f"mrm {args[0]} exited {code}: {' '.join(tail)} (see {log})")
    return time.perf_counter() - started


def imported_bag(
    name: str, robots: int, bag: Path, overlap: int = 0, log: Path | None = None
) -> Path:
    """``bag``: log ``name`` cut into ``robots`` robots by ``mrm import-carmen`` (each run
    ``overlap`` scans into its predecessor), imported once and reused after."""
    imported = [str(carmen_log(name)), "--robots", str(robots)]
    if overlap:
        imported += ["--overlap-scans", str(overlap)]
    return _imported_once("import-carmen", imported, bag, log)


def imported_dense_bag(name: str, robots: int, bag: Path, log: Path | None = None) -> Path:
    """``bag``: the shared dense bag ``name`` (``BAGS/NAME.bag``, every scan) cut into
    ``robots`` robots by ``mrm import-bag``, its truth file's reference poses attached and
    CARMEN's beam geometry (the shared bags were converted from CARMEN logs: docs/bags.md),
    imported once and reused after."""
    source, truth = BAGS / f"{name}.bag", BAGS / f"{name}.truth.csv"
    imported = [str(source), "--robots", str(robots), "--beam-geometry", "carmen"]
    if truth.is_file():
        imported += ["--truth", str(truth)]
    return _imported_once("import-bag", imported, bag, log)


def _imported_once(command: str, arguments: list[str], bag: Path, log: Path | None) -> Path:
    """``mrm COMMAND ARGUMENTS --out`` into ``bag`` unless it is there: written under a
    temporary name and renamed when complete, so an interrupted import is never reused."""
    if not bag.exists():
        bag.parent.mkdir(parents=True, exist_ok=True)
        partial = bag.with_name(bag.name + ".partial")
        shutil.rmtree(partial, ignore_errors=True)  # left by an interrupted import
        mrm([command, *arguments, "--out", str(partial)], log)
        partial.rename(bag)
    return bag


def present_bags(names: Iterable[str]) -> list[str]:
    """The shared dense bags of ``names`` that are there; a note on stderr for each one
    skipped."""
    present = []
    for name in names:
        if (BAGS / f"{name}.bag").is_file():
            present.append(name)
        else:
            print(f"{name}: skipped, {BAGS / f'{name}.bag'} not found", file=sys.stderr)
    return present


def reference_keyframes(scans: list[CarmenScan], spacing: float, turn: float) -> list[Keyframe]:
    """A run's keyframes as a robot's ``partial_map`` carries them, built at the reference
    poses: a keyframe where the laser moved ``spacing`` or turned ``turn`` since the last (the
    local mapper's keyframe rule), every scan fused, each fused segment owned by the keyframe
    of its scan and stored in that keyframe's frame; poses in the run's first scan's frame."""
    T_robot_world = se2.invert(se2.matrix_from_pose(*scans[0].reference_pose))
    world = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    poses: list[FloatArray] = []
    stamps: list[float] = []
    config = IntegrateConfig()
    for scan in scans:
        pose = np.asarray(scan.reference_pose, dtype=np.float64)
        if not poses or (
            np.hypot(*(pose[:2] - poses[-1][:2])) >= spacing
            or abs(float(se2.wrap_angle(pose[2] - poses[-1][2]))) >= turn
        ):
            poses.append(pose)
            stamps.append(scan.timestamp)
        found = extract_scan(carmen_scan_data(scan), ExtractionConfig())[0].segments
        placed = se2.transform_segments(se2.matrix_from_pose(*pose), found)
        own = np.full(len(placed), len(poses) - 1, dtype=np.int64)
        world, owner = fuse(world, owner, placed, own, pair_tolerance(config), 0.02)
    keyframes = []
    for k, pose in enumerate(poses):
        T_world_keyframe = se2.matrix_from_pose(*pose)
        segments = se2.transform_segments(se2.invert(T_world_keyframe), world[owner == k])
        T_robot_keyframe = np.array(se2.pose_from_matrix(T_robot_world @ T_world_keyframe))
        keyframes.append(Keyframe(k, stamps[k], T_robot_keyframe, segments))
    return keyframes


def equal_runs(scans: Sequence[CarmenScan], robots: int, overlap: int) -> list[list[CarmenScan]]:
    """The issue-13 benches' cut (``merge_speed``, ``merge_growth``, ``whole_merge``):
    ``robots`` runs of ``len // robots`` scans, each starting ``overlap`` scans before its
    predecessor ends (the remainder of the division is left out)."""
    size = len(scans) // robots
    return [list(scans[max(0, k * size - overlap) : (k + 1) * size]) for k in range(robots)]


def joint_cut(
    scans: list[CarmenScan], robots: int, overlap: int
) -> tuple[dict[str, FloatArray], dict[str, list[Keyframe]]]:
    """A log cut into ``robots`` runs (:func:`equal_runs`): each run's T_world_robotmap (its
    first scan's reference pose) and its keyframes built at the reference poses
    (:func:`reference_keyframes`)."""
    frames, keyframes = {}, {}
    for k, run in enumerate(equal_runs(scans, robots, overlap)):
        frames[f"robot{k}"] = se2.matrix_from_pose(*run[0].reference_pose)
        keyframes[f"robot{k}"] = reference_keyframes(run, 0.5, 0.35)
    return frames, keyframes


def add_merge_overrides(parser: argparse.ArgumentParser) -> None:
    """``--set NAME=VALUE`` (repeatable): a MergeConfig field; read by :func:`merge_config_of`."""
    add_set_option(parser, "override a MergeConfig field, e.g. --set link_set_uniqueness=3")


def merge_config_of(args: argparse.Namespace) -> MergeConfig:
    return config_from_flat(MergeConfig, dict(parse_override(o) for o in args.overrides))


# --- runs mapped by the local mapper --------------------------------------------------------


@dataclasses.dataclass
class MappedRun:
    """One robot's run of a CARMEN log, mapped by one LocalMapper (back end in line)."""

    scans: list[CarmenScan]  # the whole log's scans (with their reference poses)
    start: int  # the run's scans are scans[start:stop]
    stop: int
    mapper: LocalMapper
    index_of: dict[float, int]  # a scan's stamp -> its index in ``scans``


def map_run(name: str, robots: int, robot: int, overrides: dict[str, Any]) -> MappedRun:
    """Map robot ``robot`` (0-based) of log ``name`` cut into ``robots`` runs (:func:`cut_log`)
    with the local mapper's config changed by ``overrides``."""
    log = cut_log(name, robots)
    start, stop = log.runs[robot]
    mapper = LocalMapper(config_from_flat(LocalMapperConfig, overrides))
    extraction = ExtractionConfig()
    for index in range(start, stop):
        data = carmen_scan_data(log.scans[index])
        segments, _ = extract_scan(data, extraction)
        mapper.add_scan(float(log.stamps[index]), segments, data)
    index_of = {float(log.stamps[i]): i for i in range(start, stop)}
    return MappedRun(log.scans, start, stop, mapper, index_of)


Rows = list[dict[str, Any]]


def judge_every_run(judge: Callable[[str, int, int, dict[str, Any]], Rows], doc: str) -> list[Rows]:
    """The command line the run-by-run benches share (``--logs``, ``--robots``, ``--jobs``,
    ``--set``), and ``judge(log, robots, robot, overrides)`` called for every robot's run of
    every log cut into each robot count, in ``--jobs`` processes; the results in that order."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--logs", nargs="+", default=["intel", "aces", "fhw", "csail", "edmonton"])
    parser.add_argument("--robots", nargs="+", type=int, default=[4, 2])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    args = parser.parse_args()
    overrides = dict(parse_override(o) for o in args.overrides)
    cases = [
        (name, robots, robot)
        for name in args.logs
        if carmen_log(name).is_file()
        for robots in args.robots
        for robot in range(robots)
    ]
    with ProcessPoolExecutor(args.jobs) as pool:
        names, counts, robots_ = (list(column) for column in zip(*cases, strict=True))
        return list(pool.map(judge, names, counts, robots_, [overrides] * len(cases)))


# --- scans ----------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class ExtractedLog:
    """One CARMEN log, extracted once: views, segment sets and reference poses."""

    name: str
    views: list[LaserScanData]
    segments: list[FloatArray]
    poses: list[Pose]


def extracted_log(name: str) -> ExtractedLog | None:
    """Log ``name`` with every scan's segments; None (with a note) when it is absent."""
    if not present_logs([name]):
        return None
    scans = list(read_carmen(carmen_log(name)))
    views = [carmen_scan_data(s) for s in scans]
    segments = [extract_scan(v, ExtractionConfig())[0].segments for v in views]
    return ExtractedLog(name, views, segments, [s.reference_pose for s in scans])


def simulated_scans(laser: LaserModel, count: int, seed: int = 0) -> list[LaserScanData]:
    """``count`` scans of the office world spread along its route, driven once at 1 m/s."""
    walls = office_world()
    route = np.asarray(ROUTES["office"], dtype=np.float64)
    poses = drive_path(route, 1.0, laser.rate, float(_arc_length(route)[-1]))
    poses = poses[np.linspace(0, len(poses) - 1, count).astype(int)]
    rng = np.random.default_rng(seed)
    return [simulate_scan(walls, tuple(p), laser, rng) for p in poses]


# --- the reference poses' agreement with a beam geometry (carmen_geometry, bag_geometry) ----


def scan_pairs(poses: FloatArray, min_turn_deg: float, max_gap: int, limit: int) -> list:
    """For each scan the first later scan (within ``max_gap``) turned enough and close by."""
    pairs = []
    for i in range(len(poses)):
        for j in range(i + 1, min(len(poses), i + max_gap + 1)):
            turn = abs((poses[i, 2] - poses[j, 2] + math.pi) % (2 * math.pi) - math.pi)
            if (
                math.degrees(turn) >= min_turn_deg
                and np.hypot(*(poses[i, :2] - poses[j, :2])) < 1.5
            ):
                pairs.append((i, j))
                break
    return pairs[:: max(1, len(pairs) // limit)]


def world_points(ranges, pose, first, step, near, far) -> np.ndarray:
    angles = first + step * np.arange(ranges.size)
    keep = (ranges > near) & (ranges < far)
    x, y, theta = pose
    local_x, local_y = ranges[keep] * np.cos(angles[keep]), ranges[keep] * np.sin(angles[keep])
    c, s = math.cos(theta), math.sin(theta)
    return np.c_[x + c * local_x - s * local_y, y + s * local_x + c * local_y]


def point_to_line_rms(scans, pairs, first, step, near, far) -> tuple[float, int]:
    errors = []
    for i, j in pairs:
        a = world_points(scans[i].ranges, scans[i].reference_pose, first, step, near, far)
        b = world_points(scans[j].ranges, scans[j].reference_pose, first, step, near, far)
        if len(a) < 20 or len(b) < 20:
            continue
        tree = cKDTree(a)
        distance, nearest = tree.query(b, distance_upper_bound=0.3)
        found = np.isfinite(distance)
        _, neighbours = tree.query(a[nearest[found]], k=5)
        centred = a[neighbours] - a[neighbours].mean(axis=1, keepdims=True)
        eigenvalues, eigenvectors = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))
        straight = eigenvalues[:, 0] < 0.05 * eigenvalues[:, 1]  # neighbours on a line
        normal = eigenvectors[:, :, 0]
        offset = np.abs(np.einsum("ni,ni->n", b[found] - a[nearest[found]], normal))[straight]
        errors.append(offset[offset < 0.1])
    e = np.concatenate(errors)
    return float(np.sqrt(np.mean(e**2))), e.size


def pair_indices(log: ExtractedLog, limit: int) -> NDArray[np.int64]:
    """Every consecutive pair of ``log``'s scans (the first's index), or ``limit`` of them
    spread evenly over the log."""
    pairs = np.arange(len(log.segments) - 1)
    if limit and limit < len(pairs):
        pairs = pairs[np.linspace(0, len(pairs) - 1, limit).astype(int)]
    return pairs
