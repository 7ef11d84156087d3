"""The relations metric of Kümmerle et al., "On measuring the accuracy of SLAM algorithms"
(Autonomous Robots 27(4), 2009): a trajectory scored by the relative motions it estimates
between pairs of scans, against hand-checked true ones.

A relations file has one relation per line, ``t1 t2 x y z roll pitch yaw``: the true motion
``T_1_2`` of the robot from the scan stamped ``t1`` to the scan stamped ``t2``, in the first
scan's frame (metres, radians; lines starting with ``#`` are comments). Per relation the
trajectory's own estimate ``T_1_2_est = T_map_1^-1 T_map_2`` is composed with the inverse of
the true one, ``E = T_1_2^-1 T_1_2_est``; the translational error is ``|E|``'s translation
(m), the rotational error its angle (rad), both absolute. The paper's tables give the mean ±
standard deviation over the relations. Only the motion between the two scans counts, so the
metric needs no alignment of frames and no reference pose of any scan.

A relation is matched when both its stamps are stamps of scans the method posed (within
``RELATION_MATCH_S``); one whose stamps name no scan, or a scan the method left unposed, is
counted apart and never scored.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# A relation's stamp names the scan stamped within this (the benchmark's files give stamps to
# 5 or 6 decimals; scans are tens of milliseconds apart).
RELATION_MATCH_S = 1e-3


class RelationsFormatError(ValueError):
    """A relations file that cannot be read (the message names the file and line)."""


@dataclasses.dataclass(frozen=True)
class Relations:
    """True relative motions: stamps of both scans (s) and ``T_first_second`` (x, y, yaw)."""

    first: FloatArray  # (N,)
    second: FloatArray  # (N,)
    motion: FloatArray  # (N, 3)

    def __len__(self) -> int:
        return len(self.first)


def read_relations(path: str | Path) -> Relations:
    """Every relation of a relations file (``t1 t2 x y z roll pitch yaw`` per line)."""
    path = Path(path)
    rows: list[list[float]] = []
    try:
        with path.open(encoding="utf-8") as stream:
            for number, line in enumerate(stream, start=1):
                words = line.split()
                if not words or words[0].startswith("#"):
                    continue
                try:
                    values = [float(w) for w in words]
                except ValueError:
                    values = []
                if len(values) != 8 or not all(map(math.isfinite, values)):
                    raise RelationsFormatError(
                        f"{path}, line {number}: expected 8 finite numbers "
                        f"(t1 t2 x y z roll pitch yaw), got {line.strip()[:80]!r}"
                    )
                rows.append(values)
    except (OSError, UnicodeError) as exc:
        raise RelationsFormatError(f"{path}: cannot read the relations file ({exc})") from None
    if not rows:
        raise RelationsFormatError(f"{path}: no relation in the file")
    table = np.array(rows, dtype=np.float64)
    return Relations(table[:, 0], table[:, 1], table[:, [2, 3, 7]])


# Why a relation was or was not scored (lower is better: the best of several robots counts).
MATCHED, UNPOSED, WITHOUT_SCAN = 0, 1, 2


@dataclasses.dataclass(frozen=True)
class RelationErrors:
    """Each relation's errors (NaN where it was not scored) and its status: MATCHED, UNPOSED
    (both stamps name scans, the method left one or both unposed) or WITHOUT_SCAN (a stamp
    names no scan)."""

    translation_m: FloatArray  # (N,)
    rotation_rad: FloatArray  # (N,)
    status: NDArray[np.int8]  # (N,)

    def summary(self) -> dict[str, float | int]:
        """The paper's figures: mean and standard deviation of the absolute translational (m)
        and rotational (deg) errors over the matched relations, and the counts."""
        matched = self.status == MATCHED
        t = self.translation_m[matched]
        r = np.degrees(self.rotation_rad[matched])
        nan = math.nan
        return {
            "relations": len(self.status),
            "matched": int(t.size),
            "without_scan": int(np.count_nonzero(self.status == WITHOUT_SCAN)),
            "unposed": int(np.count_nonzero(self.status == UNPOSED)),
            "translation_mean_m": float(t.mean()) if t.size else nan,
            "translation_std_m": float(t.std()) if t.size else nan,
            "rotation_mean_deg": float(r.mean()) if r.size else nan,
            "rotation_std_deg": float(r.std()) if r.size else nan,
        }


def _nearest(
    sorted_stamps: FloatArray, query: FloatArray, tolerance: float
) -> tuple[NDArray[np.int64], BoolArray]:
    """Index of the nearest sorted stamp per query, and whether it lies within ``tolerance``."""
    if len(sorted_stamps) == 0:
        return np.zeros(len(query), dtype=np.int64), np.zeros(len(query), dtype=bool)
    right = np.clip(np.searchsorted(sorted_stamps, query), 0, len(sorted_stamps) - 1)
    left = np.maximum(right - 1, 0)
    use_left = np.abs(sorted_stamps[left] - query) <= np.abs(sorted_stamps[right] - query)
    index = np.where(use_left, left, right).astype(np.int64)
    return index, np.abs(sorted_stamps[index] - query) <= tolerance


def relation_errors(
    relations: Relations,
    scan_stamps: FloatArray,
    poses: FloatArray,
    tolerance: float = RELATION_MATCH_S,
) -> RelationErrors:
    """The errors of one robot's trajectory on ``relations``.

    ``scan_stamps`` (N,) are the stamps of every scan the robot recorded, on the relations'
    clock, and ``poses`` (N, 3) the method's pose of each (any one frame; NaN rows for scans
    left unposed).
    """
    scan_stamps = np.asarray(scan_stamps, dtype=np.float64).ravel()
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    order = np.argsort(scan_stamps, kind="stable")
    stamps, poses = scan_stamps[order], poses[order]
    i, found_1 = _nearest(stamps, relations.first, tolerance)
    j, found_2 = _nearest(stamps, relations.second, tolerance)
    found = found_1 & found_2
    posed = found.copy()
    if len(poses):
        posed &= np.isfinite(poses[i]).all(axis=1) & np.isfinite(poses[j]).all(axis=1)
    translation = np.full(len(relations), np.nan)
    rotation = np.full(len(relations), np.nan)
    if np.any(posed):
        estimated = se2.between_each(poses[i[posed]], poses[j[posed]])
        error = se2.between_each(relations.motion[posed], estimated)
        translation[posed] = np.hypot(error[:, 0], error[:, 1])
        rotation[posed] = np.abs(se2.wrap_angle(error[:, 2]))
    status = np.where(posed, MATCHED, np.where(found, UNPOSED, WITHOUT_SCAN)).astype(np.int8)
    return RelationErrors(translation, rotation, status)


def combine(errors: list[RelationErrors]) -> RelationErrors:
    """Several robots' errors on the same relations as one: each relation scored by the first
    robot that matched it (a relation lies within one robot's run); needs at least one."""
    status = np.min([e.status for e in errors], axis=0).astype(np.int8)
    translation = np.full(len(status), np.nan)
    rotation = np.full(len(status), np.nan)
    for e in reversed(errors):  # the first robot's scores written last
        matched = e.status == MATCHED
        translation[matched], rotation[matched] = e.translation_m[matched], e.rotation_rad[matched]
    return RelationErrors(translation, rotation, status)
