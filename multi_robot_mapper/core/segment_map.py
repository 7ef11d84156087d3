"""One map type: a set of wall segments and what the matcher and the merger derive from it.

A :class:`SegmentMap` is built once from an ``(N, 4)`` array of segments ``(x1, y1, x2, y2)``
(the edges, messages, files and tests, keep raw arrays) and computes what every stage reads of
it once, on first use: the lines (direction, angle, length, normal offset), the total length,
the columns and midpoints the pair scoring gathers from, the order of the longest segments (and
the maps of the longest few), and a content signature for "did this map change". What is
derived lives on the instance, never in a module-level cache keyed on the array's bytes: pass
the same instance along to reuse it. What is built on two maps (the matcher's pair geometry) is
held on a map only for the length of a ``with`` block (:meth:`SegmentMap.holding`), so that a
map that lives long (a keyframe's scan) never accumulates what was built with others.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import threading
from collections.abc import Callable, Hashable, Iterator
from typing import TypeAlias, TypeVar, cast

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.geometry import Lines, lines_of

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

_Held = TypeVar("_Held")

# Maps of the longest segments kept per map: one per count asked (the matcher asks two, the
# merger a few more); beyond this many counts the oldest is dropped.
_KEPT_LONGEST = 8


@dataclasses.dataclass(frozen=True, eq=False)
class SegmentMap:
    """Wall segments ``(N, 4)`` (x1, y1, x2, y2; read only) and their derived geometry.

    Equality and hashing are by identity: two maps of equal content are equal in
    :attr:`digest`. Build one with :meth:`of` (a read-only copy of the caller's array).
    """

    segments: FloatArray
    _longest: dict[int, SegmentMap] = dataclasses.field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    # key -> [what is held, how many blocks hold it] (:meth:`holding`)
    _held: dict[Hashable, list[object]] = dataclasses.field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    # A node's front end and back end share keyframes' maps: these dicts change under a lock.
    _lock: threading.Lock = dataclasses.field(
        default_factory=threading.Lock, init=False, repr=False, compare=False
    )

    @staticmethod
    def of(segments: SegmentMap | FloatArray) -> SegmentMap:
        """``segments`` as a map: itself when already one, else a read-only copy of the
        array as contiguous float64 ``(N, 4)`` (the caller may change its own array later)."""
        if isinstance(segments, SegmentMap):
            return segments
        array = np.array(segments, dtype=np.float64, order="C", copy=True).reshape(-1, 4)
        array.flags.writeable = False
        return SegmentMap(array)

    def __len__(self) -> int:
        return len(self.segments)

    def __reduce__(self) -> tuple[Callable[[FloatArray], SegmentMap], tuple[FloatArray]]:
        # Pickled (and deep-copied) as its segments alone: what is derived is made again.
        return SegmentMap.of, (np.asarray(self.segments),)

    @functools.cached_property
    def lines(self) -> Lines:
        """Direction, angle, length and normal offset of each segment (read only)."""
        lines = lines_of(self.segments)
        for field in dataclasses.fields(lines):
            getattr(lines, field.name).flags.writeable = False
        return lines

    @property
    def length(self) -> FloatArray:
        """Length of each segment (m)."""
        return self.lines.length

    @functools.cached_property
    def total_length(self) -> float:
        """Summed length of the segments (m; 0 for no segment)."""
        return float(self.lines.length.sum()) if len(self.segments) else 0.0

    @functools.cached_property
    def columns(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """x1, y1, x2, y2 as contiguous columns (they gather faster than a 2-D index)."""
        x1, y1, x2, y2 = (_read_only(self.segments[:, k]) for k in range(4))
        return x1, y1, x2, y2

    @functools.cached_property
    def direction_columns(self) -> tuple[FloatArray, FloatArray]:
        """ux, uy of each segment's unit direction as contiguous columns."""
        return _read_only(self.lines.direction[:, 0]), _read_only(self.lines.direction[:, 1])

    @functools.cached_property
    def centres(self) -> tuple[FloatArray, FloatArray]:
        """x, y of each segment's midpoint as contiguous columns."""
        mid = 0.5 * (self.segments[:, :2] + self.segments[:, 2:])
        return _read_only(mid[:, 0]), _read_only(mid[:, 1])

    @functools.cached_property
    def longest_first(self) -> IntArray:
        """Segment indices by decreasing length (ties in index order)."""
        order = np.argsort(-self.lines.length, kind="stable").astype(np.int64)
        order.flags.writeable = False
        return order

    def longest(self, count: int) -> SegmentMap:
        """The map of the ``count`` longest segments, longest first (kept on this map)."""
        with self._lock:
            found = self._longest.get(count)
        if found is not None:
            return found
        made = self.subset(self.longest_first[:count])
        with self._lock:
            while len(self._longest) >= _KEPT_LONGEST:
                del self._longest[next(iter(self._longest))]
            return self._longest.setdefault(count, made)

    def subset(self, index: IntArray) -> SegmentMap:
        """The map of the segments at ``index`` (a new map: nothing derived is shared)."""
        array = np.ascontiguousarray(self.segments[index])
        array.flags.writeable = False
        return SegmentMap(array)

    @functools.cached_property
    def digest(self) -> str:
        """Content hash of the segments (computed once per map): equal digests, equal maps."""
        return hashlib.sha1(self.segments.tobytes()).hexdigest()

    def held(self, key: Hashable) -> object | None:
        """What a :meth:`holding` block now holds on this map under ``key`` (None: nothing)."""
        with self._lock:
            entry = self._held.get(key)
        return None if entry is None else entry[0]

    @contextlib.contextmanager
    def holding(self, key: Hashable, make: Callable[[], _Held]) -> Iterator[_Held]:
        """Within the block, ``make()`` (made once, or the one an enclosing block holds) is
        held on this map under ``key`` for :meth:`held`; dropped when the last block ends.
        ``make`` runs under the map's lock: it should only set up (build lazily)."""
        with self._lock:
            entry = self._held.get(key)
            if entry is None:
                entry = self._held[key] = [make(), 0]
            entry[1] = cast(int, entry[1]) + 1
        try:
            yield cast(_Held, entry[0])
        finally:
            with self._lock:
                entry[1] = cast(int, entry[1]) - 1
                if entry[1] == 0:
                    del self._held[key]


# What the matching functions take: a map, or an array of segments converted at the call (an
# edge: tests, benches, one-off calls); pass the map to reuse what is derived from it.
MapLike: TypeAlias = "SegmentMap | FloatArray"


def _read_only(column: FloatArray) -> FloatArray:
    array = np.ascontiguousarray(column)
    array.flags.writeable = False
    return array


__all__ = ["MapLike", "SegmentMap"]
