"""Scenarios for the wrong-decision benchmark (issue 46): robots driving through a building at
the same time, their partial maps as they grow, and the truth to judge every decision by.

A :class:`Scenario` is K robots' drives: every scan with its stamp and true laser pose. Its
sources: the simulator's generated buildings (``generated``), its built-in worlds
(``world``), and the shared CARMEN logs cut into K contiguous runs (``carmen``). Two kinds of
partial map are made of it, as snapshots at the live updates' times:

- **truth maps**: keyframes at the true poses (the local mapper's keyframe rule: 0.5 m or
  0.35 rad), each keyframe's scan fused into the map (Amigoni Alg. 5) and each fused segment
  owned by one keyframe, poses in the robot's own frame (its first scan's pose): merging
  alone is judged;
- **own maps**: each robot mapped by its :class:`LocalMapper` (back end in line), every scan,
  as ``robot_mapper`` maps it: what the merger gets from real robots, pieces and all.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from bench.harness import BAGS, carmen_log
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.fusion import fuse
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.local_mapping import Closure, Keyframe, LocalMapper, LocalMapperConfig
from multi_robot_mapper.core.local_mapping.evidence import Weighed
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.matching.scoring import pair_tolerance
from multi_robot_mapper.core.scan import LaserScanData, ScanError

FloatArray = NDArray[np.float64]

KEYFRAME_DISTANCE = 0.5  # m, the local mapper's keyframe rule
KEYFRAME_TURN = 0.35  # rad
FUSION_TOLERANCE = 0.02  # m, as reference-built maps have been fused (bench/merge_speed.py)
# Two robots overlap at the truth when this much of their walls (within OVERLAP_GAP of each
# other) was seen by both: enough for one place of the merger's to hold shared walls.
OVERLAP_WALL = 10.0  # m
OVERLAP_GAP = 0.10  # m


@dataclasses.dataclass(frozen=True)
class Drive:
    """One robot's run: every scan, its stamp and the laser's true pose in ``world``."""

    stamps: FloatArray  # (N,) s
    T_world_laser: FloatArray  # (N, 3)
    scans: Sequence[LaserScanData]

    @property
    def duration(self) -> float:
        return float(self.stamps[-1] - self.stamps[0]) if len(self.stamps) else 0.0


@dataclasses.dataclass(frozen=True)
class TruthTable:
    """Every robot's true laser poses by stamp: what the judge needs of a scenario."""

    stamps: dict[str, FloatArray]  # robot -> (N,) s
    poses: dict[str, FloatArray]  # robot -> (N, 3) T_world_laser
    # the building's own symmetry (generated buildings): "rotation_180", "rotation_90",
    # "mirror" or "none"; a rotation is about the world origin
    symmetry: str = "none"

    def symmetries(self) -> list[FloatArray]:
        """The rigid motions (3x3, about the world origin) that map the building onto itself,
        the identity left out: a robot placed at one of them, composed with the truth, is
        placed where the building looks the same (no map alone can tell)."""
        turns = {"rotation_180": (np.pi,), "rotation_90": (0.5 * np.pi, np.pi, -0.5 * np.pi)}
        return [se2.matrix_from_pose(0.0, 0.0, t) for t in turns.get(self.symmetry, ())]

    def truth_of(self, robot: str, stamps: FloatArray) -> FloatArray:
        """(N, 3) true laser poses at ``stamps`` (exact: every keyframe is a scan)."""
        known = self.stamps[robot]
        rows = np.clip(
            np.searchsorted(known, np.asarray(stamps, dtype=np.float64)), 0, len(known) - 1
        )
        return np.asarray(self.poses[robot][rows])


@dataclasses.dataclass(frozen=True)
class Scenario:
    """K robots driving at the same time (each run's clock from its own first scan)."""

    name: str
    drives: dict[str, Drive]
    description: dict[str, object] = dataclasses.field(default_factory=dict)

    @property
    def duration(self) -> float:
        return max(d.duration for d in self.drives.values())

    def truth(self) -> TruthTable:
        return TruthTable(
            {r: d.stamps for r, d in self.drives.items()},
            {r: d.T_world_laser for r, d in self.drives.items()},
            str(self.description.get("symmetry", "none")),
        )


# --- sources --------------------------------------------------------------------------------


def carmen_scenario(log: str, robots: int, overlap: int = 0) -> Scenario | None:
    """A shared CARMEN log cut into ``robots`` contiguous runs as ``mrm import-carmen`` cuts
    it (each run ``overlap`` scans into its predecessor), its reference poses the truth.
    None when the log is absent."""
    from multi_robot_mapper.cli.import_carmen import split_runs
    from multi_robot_mapper.io.carmen import carmen_scan_data, monotonic_stamps, read_carmen

    path = carmen_log(log)
    if not path.is_file():
        return None
    scans = read_carmen(path)
    stamps, _ = monotonic_stamps(np.array([s.timestamp for s in scans]), path.name)
    drives = {}
    for k, (start, stop) in enumerate(split_runs(len(scans), robots, overlap)):
        run = range(start, stop)
        drives[f"robot{k + 1}"] = Drive(
            np.asarray(stamps[start:stop], dtype=np.float64),
            np.array([scans[i].reference_pose for i in run], dtype=np.float64),
            [carmen_scan_data(scans[i]) for i in run],
        )
    return Scenario(f"{log}_{robots}", drives, {"source": "carmen", "log": log, "robots": robots})


def world_scenario(world: str, robots: int, seed: int, duration: float = 40.0) -> Scenario:
    """``robots`` robots on overlapping stretches of a built-in world's tour (``mrm
    simulate``), a SICK-like laser at 10 Hz."""
    from multi_robot_mapper.core.simulation import LaserModel, simulate_robots

    laser = LaserModel(beams=361, field_of_view=math.pi, range_max=30.0, rate=10.0)
    runs = simulate_robots(world, robots, laser, seed=seed, duration=duration)
    drives = {
        f"robot{k + 1}": Drive(run.stamps, run.T_world_laser, run.scans)
        for k, run in enumerate(runs)
    }
    return Scenario(f"{world}_{robots}_{seed}", drives, {"source": "world", "world": world})


# The dense bags with reference poses (bags/README.md), and their beam geometry: CARMEN's
# convention, which their reference poses agree with (docs/bags.md).
DENSE_BAGS = ("intel", "aces", "fr079", "mit-csail")


def bag_scenario(bag: str, robots: int) -> Scenario | None:
    """A shared dense bag (every scan, 10 Hz) cut into ``robots`` contiguous runs as ``mrm
    import-bag`` cuts it, CARMEN's beam geometry, its reference poses the truth where a scan
    has one (a pose of NaN elsewhere: those scans are never judged). None when absent."""
    from multi_robot_mapper.io.recordings import (
        BeamGeometry,
        attach_truth,
        cut_recording,
        read_bags,
        read_truth_csv,
        with_beam_geometry,
    )

    path = BAGS / f"{bag}.bag"
    truth_path = BAGS / f"{bag}.truth.csv"
    if not path.is_file() or not truth_path.is_file():
        return None
    recordings = with_beam_geometry(read_bags([path]), BeamGeometry.parse("carmen"))
    (recording,) = recordings.values()
    recording = attach_truth(recording, read_truth_csv(truth_path))
    drives = {}
    for name, run in cut_recording(recording, robots).items():
        stamps = np.array([s.stamp for s in run.scans], dtype=np.float64)
        poses = np.full((len(stamps), 3), np.nan)
        truth_stamps = np.array([g.stamp for g in run.ground_truth], dtype=np.float64)
        rows = np.searchsorted(stamps, truth_stamps).clip(0, len(stamps) - 1)
        exact = np.abs(stamps[rows] - truth_stamps) < 1e-6
        poses[rows[exact]] = np.array([g.pose for g in run.ground_truth])[exact]
        drives[name] = Drive(stamps, poses, [s.scan for s in run.scans])
    return Scenario(f"bag_{bag}_{robots}", drives, {"source": "bag", "bag": bag, "robots": robots})


class LazyScans(Sequence[LaserScanData]):
    """A generated building's scans along one drive, ray cast when first read: a truth map
    reads only its keyframes' scans. Each scan's noise comes from its own stream
    (``SeedSequence(seed, spawn_key=(robot, row))``), so reading order does not matter."""

    def __init__(self, scanner: object, drive: object, seed: int, robot: int, start: float) -> None:
        self.scanner, self.drive = scanner, drive
        self.seed, self.robot, self.start = seed, robot, start

    def __len__(self) -> int:
        return len(self.drive.stamps)  # type: ignore[attr-defined]

    def __getitem__(self, row):  # type: ignore[no-untyped-def, override]
        from multi_robot_mapper.core.simulation import scan_from_ranges

        if isinstance(row, slice):
            return [self[i] for i in range(*row.indices(len(self)))]
        pose = self.drive.T_world_laser[row]  # type: ignore[attr-defined]
        seconds = float(self.drive.stamps[row]) - self.start  # type: ignore[attr-defined]
        ranges = self.scanner.ranges((pose[0], pose[1], pose[2]), seconds)  # type: ignore[attr-defined]
        rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(self.robot, row)))
        return scan_from_ranges(ranges, self.scanner.laser, rng)  # type: ignore[attr-defined]


# The lasers a generated scenario draws from: the simulator's model (noise, dropouts, range
# limits) with a SICK LMS's and a Hokuyo UTM-30LX's geometry.
def _lasers() -> dict[str, object]:
    from multi_robot_mapper.core.simulation import LaserModel

    return {
        "sick": LaserModel(beams=181, field_of_view=math.pi, range_max=50.0, rate=10.0),
        "hokuyo": LaserModel(),
    }


def generated_scenario(seed: int, own: bool = False) -> Scenario:
    """A generated building (``core.buildings``) and K robots driving it (``core.building_runs``),
    everything drawn from ``seed``: the plan's kind and size (20-200 m), glass, furniture and
    people; 2-8 robots, the share of their drives on common ground (0 to 1), how long they
    drive (40-120 s at 0.8 m/s), the laser (SICK or Hokuyo geometry) and its rate (10, 20 or
    40 Hz) or sparse keeping (a scan every 0.5 m or 15 deg, as the CARMEN "corrected" logs).
    With ``own`` (the robots map with their own local mappers, every scan: the benchmark's
    cost), at most 5 robots and a dense rate of 10 Hz; the rest drawn alike."""
    from multi_robot_mapper.core.building_runs import (
        BuildingScanner,
        SparseSpacing,
        drive_routes,
        plan_routes,
    )
    from multi_robot_mapper.core.buildings import generate_building
    from multi_robot_mapper.core.simulation import SIM_START_S

    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(4600,)))
    glass = bool(rng.random() < 0.3)
    clutter = float(rng.choice([0.0, 0.0, 0.05, 0.15]))
    people = int(rng.choice([0, 0, 5, 15]))
    robots = int(rng.integers(2, 9))
    overlap = float(rng.choice([0.0, 0.1, 0.25, 0.5, 0.75, 1.0]))
    duration = float(rng.uniform(40.0, 120.0))
    laser_name = str(rng.choice(["sick", "hokuyo"]))
    rate = float(rng.choice([10.0, 20.0, 40.0]))
    sparse = bool(rng.random() < 0.3)
    if own:
        robots, rate = min(robots, 5), 10.0
    building = generate_building(seed, glass=glass, clutter=clutter, people=people)
    laser = dataclasses.replace(_lasers()[laser_name], rate=rate)  # type: ignore[type-var]
    robots = min(robots, len(building.nodes))
    paths = plan_routes(building, robots, 0.8 * duration, overlap, seed)
    drives = drive_routes(paths, 0.8, rate, duration, SparseSpacing() if sparse else None)
    scanner = BuildingScanner.of(building, laser)
    out = {
        f"robot{k + 1}": Drive(
            d.stamps, d.T_world_laser, LazyScans(scanner, d, seed, k, SIM_START_S)
        )
        for k, d in enumerate(drives)
    }
    description: dict[str, object] = {
        "source": "generated",
        "seed": seed,
        "kind": building.kind,
        "size_m": round(building.size, 1),
        "symmetry": building.symmetry,
        "glass": glass,
        "clutter": clutter,
        "people": people,
        "robots": robots,
        "overlap": overlap,
        "duration_s": round(duration, 1),
        "laser": laser_name,
        "rate_hz": rate,
        "sparse": sparse,
    }
    description["own_variant"] = own
    return Scenario(f"generated_{seed}", out, description)


# --- partial maps as they grow ------------------------------------------------------------


def keyframe_rows(poses: FloatArray) -> list[int]:
    """Rows of the drive that become keyframes: the first, then each scan 0.5 m or 0.35 rad
    from the last keyframe. Only rows with a true pose (a dense bag's scans between its
    reference poses have NaN) can be keyframes of a truth map."""
    posed = np.flatnonzero(np.isfinite(poses).all(axis=1))
    if len(posed) == 0:
        return []
    rows = [int(posed[0])]
    for row in posed[1:]:
        last = poses[rows[-1]]
        moved = math.hypot(*(poses[row, :2] - last[:2]))
        if moved >= KEYFRAME_DISTANCE or abs(float(se2.wrap_angle(poses[row, 2] - last[2]))) >= (
            KEYFRAME_TURN
        ):
            rows.append(int(row))
    return rows


def truth_snapshots(drive: Drive, times: Sequence[float]) -> list[list[Keyframe]]:
    """The robot's truth map (module doc) as it stood at each of ``times`` (seconds from its
    first scan): its keyframes, poses in its own frame, segments in each keyframe's."""
    config, extraction = IntegrateConfig(), ExtractionConfig()
    rows = keyframe_rows(drive.T_world_laser)
    if not rows:  # no scan of this run has a true pose: no truth map
        return [[] for _ in times]
    T_robot_world = se2.invert(se2.matrix_from_pose(*drive.T_world_laser[rows[0]]))
    world = np.zeros((0, 4))
    owner = np.zeros(0, dtype=np.int64)
    elapsed = drive.stamps[rows] - drive.stamps[0]
    snapshots: list[list[Keyframe]] = []
    done = 0
    for time in times:
        while done < len(rows) and elapsed[done] <= time:
            row = rows[done]
            try:
                found = extract_scan(drive.scans[row], extraction)[0].segments
            except ScanError:  # a scan of open space or glass: no return, no wall
                found = np.zeros((0, 4))
            T_world_keyframe = se2.matrix_from_pose(*drive.T_world_laser[row])
            placed = se2.transform_segments(T_world_keyframe, found)
            mine = np.full(len(placed), done, dtype=np.int64)
            world, owner = fuse(
                world, owner, placed, mine, pair_tolerance(config), FUSION_TOLERANCE
            )
            done += 1
        keyframes = []
        for k in range(done):
            row = rows[k]
            T_world_keyframe = se2.matrix_from_pose(*drive.T_world_laser[row])
            keyframes.append(
                Keyframe(
                    k,
                    float(drive.stamps[row]),
                    np.array(se2.pose_from_matrix(T_robot_world @ T_world_keyframe)),
                    se2.transform_segments(se2.invert(T_world_keyframe), world[owner == k]),
                )
            )
        snapshots.append(keyframes)
    return snapshots


@dataclasses.dataclass
class OwnMap:
    """A robot's own local mapping: its keyframes at each update, and its closures and joins."""

    snapshots: list[list[Keyframe]]
    closures: list[Closure]  # loop closures and joins accepted (``Closure.kind``)
    keyframe_stamps: FloatArray  # (K,) stamp of every keyframe, by index
    scans_mapped: int
    weighed: list[Weighed]  # every closure and join the evidence model weighed


def own_snapshots(
    drive: Drive, times: Sequence[float], config: LocalMapperConfig | None = None
) -> OwnMap:
    """The robot mapped by its own :class:`LocalMapper` (back end in line), every scan; its
    partial map at each of ``times`` (seconds from its first scan)."""
    mapper = LocalMapper(config if config is not None else LocalMapperConfig())
    extraction = ExtractionConfig()
    snapshots: list[list[Keyframe]] = []
    pending = list(times)
    start = float(drive.stamps[0])
    for stamp, scan in zip(drive.stamps, drive.scans, strict=True):
        while pending and stamp - start > pending[0]:
            snapshots.append(mapper.keyframes())
            pending.pop(0)
        try:
            segments, _ = extract_scan(scan, extraction)
            mapper.add_scan(float(stamp), segments, scan)
        except Exception:  # as the node does (a bad scan is dropped): the map so far is kept
            continue
    snapshots += [mapper.keyframes() for _ in pending]
    stamps = np.array([kf.stamp for kf in sorted(mapper.keyframes(), key=lambda k: k.index)])
    weighed = list(mapper.backend.closer.weighed)  # type: ignore[attr-defined]
    # The headings bridged across losses are edges too (kind "heading": judged on the heading
    # alone, the only thing they constrain).
    headings = list(mapper.backend.closer.headings)  # type: ignore[attr-defined]
    closures = list(mapper.closures) + headings
    return OwnMap(snapshots, closures, stamps, len(drive.stamps), weighed)


def update_times(scenario: Scenario, updates: int) -> list[float]:
    """Seconds from the start at which the merger updates: ``updates`` times, evenly, the last
    once the last robot has stopped."""
    stop = scenario.duration
    times = [float(t) for t in stop * np.arange(1, updates) / updates]
    return [*times, stop + 1e-6]


# --- the truth of a scenario --------------------------------------------------------------


def world_walls(keyframes: Sequence[Keyframe], T_world_keyframe: FloatArray) -> FloatArray:
    """A robot's map in ``world``: each keyframe's segments at its true pose ``(K, 3)``."""
    parts = [
        se2.transform_segments(se2.matrix_from_pose(*pose), kf.segments)
        for kf, pose in zip(keyframes, np.asarray(T_world_keyframe).reshape(-1, 3), strict=True)
        if np.isfinite(pose).all()  # a keyframe without a reference pose is left out
    ]
    return np.vstack(parts) if parts else np.zeros((0, 4))


def shared_wall(a: FloatArray, b: FloatArray) -> float:
    """Metres of map a's walls within OVERLAP_GAP of map b's (both in ``world``)."""
    if len(a) == 0 or len(b) == 0:
        return 0.0
    step = 0.05
    points_a = sample_segments(a, step)[0]
    points_b = sample_segments(b, step)[0]
    near = cKDTree(points_b).query(points_a, distance_upper_bound=OVERLAP_GAP)[0] < OVERLAP_GAP
    return float(near.sum() * step)


def overlap_component(walls: dict[str, FloatArray]) -> set[str]:
    """The largest group of robots joined by pairs that overlap at the truth (OVERLAP_WALL of
    shared wall): the robots any merger could place in one map. Empty when no two overlap."""
    names = sorted(walls)
    group = {r: {r} for r in names}
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            if group[a] is group[b]:
                continue
            if min(shared_wall(walls[a], walls[b]), shared_wall(walls[b], walls[a])) >= (
                OVERLAP_WALL
            ):
                union = group[a] | group[b]
                for r in union:
                    group[r] = union
    largest = max((g for g in group.values()), key=len, default=set())
    return set(largest) if len(largest) >= 2 else set()


def iterate_seeds(first: int, count: int) -> Iterator[int]:
    yield from range(first, first + count)
