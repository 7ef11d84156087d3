"""Where the relation error of the raw MIT CSAIL log comes from (issue 47, target <= 0.010 m).

The bag's every scan through one robot's local mapper (CARMEN's beam geometry, as
``bench/bag_replay.py``), its trajectory scored on ``mit-csail.relations`` with the raw log's
stamps (``mrm evaluate --relation-stamps``), and then taken apart:

- the errors by the relation's length and turn, and by the time between its two scans;
- the trajectory shifted by one and two scans (is a scan paired with its neighbour's stamp?);
- every placed scan refined again by point-to-line least squares of its raw beam end points on
  the final fused map (``--refine``: does the map hold more than the placements?);
- the corrected log's own reference poses (``mit-csail.truth.csv``) on the relations they cover.

    .venv/bin/python -m bench.relation_spans [--refine]
"""

from __future__ import annotations

import argparse
import itertools
import time

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from bench.harness import BAGS
from multi_robot_mapper.core.extraction import extract_scan
from multi_robot_mapper.core.local_mapping import LocalMapper
from multi_robot_mapper.core.scan import scan_points
from multi_robot_mapper.evaluation.relations import Relations, read_relations, relation_errors
from multi_robot_mapper.io.carmen import read_carmen
from multi_robot_mapper.io.recordings import (
    BeamGeometry,
    read_bags,
    read_truth_csv,
    with_beam_geometry,
)
from multi_robot_mapper.ros.mapper_config import RobotMapperConfig

FloatArray = NDArray[np.float64]
SAMPLE_STEP = 0.02  # m: the map's segments as points this far apart, for nearest-line search
GATE = 0.10  # m: a beam end point farther than this from every map line is not used
CAUCHY = 0.03  # m: the scale of the refinement's robust weight


def _summary(relations: Relations, stamps: FloatArray, poses: FloatArray) -> str:
    errors = relation_errors(relations, stamps, poses)
    ok = np.isfinite(errors.translation_m)
    t, r = errors.translation_m[ok], np.degrees(errors.rotation_rad[ok])
    return f"{ok.sum()} matched, {t.mean():.4f} ± {t.std():.4f} m, {r.mean():.3f} deg"


def _breakdown(relations: Relations, stamps: FloatArray, poses: FloatArray) -> None:
    errors = relation_errors(relations, stamps, poses)
    ok = np.isfinite(errors.translation_m)
    t = errors.translation_m[ok]
    length = np.hypot(relations.motion[ok, 0], relations.motion[ok, 1])
    turn = np.abs(np.degrees(relations.motion[ok, 2]))
    gap = (relations.second - relations.first)[ok]
    for name, value, edges in (
        ("length (m)", length, (0.0, 0.5, 1.0, 5.0, np.inf)),
        ("turn (deg)", turn, (0.0, 1.0, 5.0, 20.0, np.inf)),
        ("time apart (s)", gap, (0.0, 2.0, 10.0, 60.0, np.inf)),
    ):
        for lo, hi in itertools.pairwise(edges):
            chosen = (value >= lo) & (value < hi)
            if chosen.any():
                print(
                    f"  {name} {lo:g}-{hi:g}: {chosen.sum()} relations, mean "
                    f"{t[chosen].mean():.4f} m, median {np.median(t[chosen]):.4f} m"
                )


def _shifted(poses: FloatArray, shift: int) -> FloatArray:
    moved = np.full_like(poses, np.nan)
    if shift >= 0:
        moved[shift:] = poses[: len(poses) - shift]
    else:
        moved[:shift] = poses[-shift:]
    return moved


def _refined(poses: FloatArray, scans: list, segments: FloatArray) -> FloatArray:
    """Each posed scan's raw end points pulled onto the nearest map line (Gauss-Newton)."""
    a, d = segments[:, :2], segments[:, 2:] - segments[:, :2]
    length = np.hypot(d[:, 0], d[:, 1])
    a, d, length = a[length > 0.2], d[length > 0.2], length[length > 0.2]
    normal = np.stack([-d[:, 1], d[:, 0]], axis=1) / length[:, None]
    offset = np.sum(normal * a, axis=1)
    counts = np.ceil(length / SAMPLE_STEP).astype(int)
    owner = np.repeat(np.arange(len(length)), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    along = (np.arange(counts.sum()) - first + 0.5) / counts[owner]
    tree = cKDTree(a[owner] + along[:, None] * d[owner])
    out = poses.copy()
    for k, scan in enumerate(scans):
        if np.isfinite(poses[k]).all():
            out[k] = _refine_one(scan_points(scan).points, poses[k], tree, owner, normal, offset)
    return out


def _refine_one(points, pose, tree, owner, normal, offset) -> FloatArray:  # type: ignore[no-untyped-def]
    x = np.array(pose, dtype=np.float64)
    for _ in range(10):
        c, s = np.cos(x[2]), np.sin(x[2])
        q = points @ np.array([[c, s], [-s, c]]) + x[:2]
        distance, index = tree.query(q, distance_upper_bound=GATE)
        near = np.isfinite(distance)
        if near.sum() < 20:
            return np.array(pose, dtype=np.float64)
        line = owner[index[near]]
        n, p = normal[line], points[near]
        residual = np.sum(q[near] * n, axis=1) - offset[line]
        turn = np.stack([-s * p[:, 0] - c * p[:, 1], c * p[:, 0] - s * p[:, 1]], axis=1)
        J = np.stack([n[:, 0], n[:, 1], np.sum(n * turn, axis=1)], axis=1)
        w = 1.0 / (1.0 + (residual / CAUCHY) ** 2)
        step = -np.linalg.solve(
            (J * w[:, None]).T @ J + 1e-9 * np.eye(3), (J * w[:, None]).T @ residual
        )
        x += step
        if np.hypot(step[0], step[1]) < 1e-5 and abs(step[2]) < 1e-6:
            break
    return x


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--refine", action="store_true", help="also refine on the final map")
    args = parser.parse_args()
    (recording,) = with_beam_geometry(
        read_bags([BAGS / "mit-csail.bag"]), BeamGeometry.parse("carmen")
    ).values()
    config = RobotMapperConfig()
    mapper = LocalMapper(config.local_mapping)
    cpu = time.process_time()
    for scan in recording.scans:
        mapper.add_scan(scan.stamp, extract_scan(scan.scan, config.extraction)[0], scan.scan)
    print(f"mapped in {time.process_time() - cpu:.1f} CPU s, {mapper.pieces_started} pieces")
    bag_stamps = np.array([s.stamp for s in recording.scans])
    placed_stamps, placed = mapper.trajectory()
    poses = np.full((len(bag_stamps), 3), np.nan)
    poses[np.searchsorted(bag_stamps, placed_stamps)] = placed
    stamps = np.array([s.timestamp for s in read_carmen(BAGS / "mit-csail.clf.gz")])
    relations = read_relations(BAGS / "mit-csail.relations")
    print("as placed:", _summary(relations, stamps, poses))
    _breakdown(relations, stamps, poses)
    for shift in (-2, -1, 1, 2):
        print(f"shifted by {shift:+d} scans:", _summary(relations, stamps, _shifted(poses, shift)))
    if args.refine:
        refined = _refined(poses, [s.scan for s in recording.scans], mapper.map_segments)
        print("refined on the final map:", _summary(relations, stamps, refined))
    truth = read_truth_csv(BAGS / "mit-csail.truth.csv")
    reference = np.full_like(poses, np.nan)
    reference[truth.index] = truth.pose
    covered = np.isfinite(reference).all(axis=1)
    print("the corrected log's reference poses:", _summary(relations, stamps, reference))
    print(
        "this trajectory on the same relations:",
        _summary(relations, stamps, np.where(covered[:, None], poses, np.nan)),
    )


if __name__ == "__main__":
    main()
