"""The front end of an offline run: every robot's scans to segments, each robot's stream
checked as ``robot_mapper`` checks it, with the counts every placement method reports."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Iterator, Sequence

from multi_robot_mapper.core.extraction import SegmentScan, extract_scan
from multi_robot_mapper.core.extraction_config import ExtractionConfig
from multi_robot_mapper.core.offline import TimedLaserScan
from multi_robot_mapper.core.scan import ScanError
from multi_robot_mapper.core.scan_stream import ScanStreamConfig, ScanStreamGuard

# (stage, done, total): stage "mapping <robot>" with scans done of every robot's scans,
# then "merging" 0 of 1, 1 of 1.
Progress = Callable[[str, int, int], None]


@dataclasses.dataclass
class FrontEnd:
    """Scans to segments for every placement method, each robot's stream checked by a
    :class:`ScanStreamGuard` as ``robot_mapper`` checks it, with the counts they all report."""

    extraction: ExtractionConfig
    stream: ScanStreamConfig
    progress: Progress | None
    total: int  # scans of every robot
    done: int = 0
    seconds: float = 0.0  # spent extracting
    # scans refused, by reason: ScanError kinds and the stream's rules (core.scan_stream)
    rejected: dict[str, int] = dataclasses.field(default_factory=dict)
    map_resets: int = 0  # a robot's map started over (its stamps jumped back and stayed)
    notices: list[str] = dataclasses.field(default_factory=list)  # e.g. a laser reconfigured

    def scans(
        self, robot: str, items: Sequence[TimedLaserScan], needs_reference: bool = False
    ) -> Iterator[tuple[TimedLaserScan, SegmentScan, bool]]:
        """Each usable scan of ``robot`` with its segments, in the order to map them, and
        whether the robot's map starts over before it; unusable ones are counted."""
        guard: ScanStreamGuard[tuple[TimedLaserScan, SegmentScan]] = ScanStreamGuard(self.stream)
        for item in items:
            self.step(robot)
            if needs_reference and item.reference_pose is None:
                continue
            started = time.perf_counter()
            try:
                segments, _ = extract_scan(item.scan, self.extraction)
            except ScanError as exc:
                self._refused(exc.kind)
                continue
            finally:
                self.seconds += time.perf_counter() - started
            verdict = guard.check(item.stamp, item.scan, (item, segments))
            for kind, _ in verdict.refused:
                self._refused(kind)
            self.notices += [f"{robot}: {notice}" for _, notice in verdict.notices]
            if not verdict.maps:
                continue
            reset = verdict.action == "reset"
            self.map_resets += reset
            for held in verdict.release:
                yield (*held.item, reset)
                reset = False
            yield item, segments, reset
        for kind, _ in guard.finish():
            self._refused(kind)

    def step(self, robot: str) -> None:
        self.done += 1
        if self.progress is not None:
            self.progress(f"mapping {robot}", self.done, self.total)

    def _refused(self, kind: str) -> None:
        self.rejected[kind] = self.rejected.get(kind, 0) + 1

    def counts(self) -> dict[str, object]:
        """The front end's part of ``stats.json``."""
        return {
            "scans_total": self.total,
            "scans_rejected": dict(self.rejected),
            "map_resets": self.map_resets,
            "stream_notices": list(self.notices),
            "front_end_s": round(self.seconds, 4),
        }
