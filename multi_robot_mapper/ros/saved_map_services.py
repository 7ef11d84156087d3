"""The map merger's saved maps: the ``save_map`` and ``load_map`` services (std_srvs/Trigger),
saving on shutdown and loading at start-up (``map_file``; the file format is io/saved_map.py)."""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable
from typing import Any

from std_srvs.srv import Trigger

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.io.saved_map import SavedMapError, read_saved_map, write_saved_map
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.merger_state import (
    MergeInputs,
    RobotState,
    merge_inputs,
    merge_pending,
    restore_saved_map,
    result_of_saved,
    saved_map_of,
)

# Seconds (wall clock) between two saves while the merges change the maps, with
# save_on_shutdown: a merger killed without a shutdown (SIGKILL, a power cut) leaves a file at
# most this old, whose placements a restarted merger publishes at once (docs/results.md, a
# merger restarted mid-run). A save of eight robots' maps is a few hundred kB of JSON. A merge
# that places or withdraws a robot is saved at once.
AUTOSAVE_PERIOD = 10.0


class SavedMapServices:
    """Mixed into :class:`~multi_robot_mapper.ros.map_merger.MapMerger` (before ``Node``, which
    provides ``get_logger``): what it saves and loads, under its lock."""

    robots: dict[str, RobotState]
    result: MergeResult | None
    config: MapMergerConfig
    _lock: threading.Lock
    _merged_versions: dict[str, Any]
    _saved_at = float("-inf")  # time.monotonic() of the last save
    _saved_placed: frozenset[str] = frozenset()  # the robots placed in it
    _publish_result: Callable[[MergeResult, MergeInputs, bool], None]  # MapMerger's

    def save_map(self, path: str | None = None) -> str:
        """Write every robot's partial map and placement and the global map to ``path``
        (default ``map_file``); raises :class:`SavedMapError`."""
        with self._lock:
            saved = saved_map_of(self.robots, self.result, self.config.map_frame)
        written = str(write_saved_map(path or self.config.map_file, saved))
        self._saved_at = time.monotonic()
        self._saved_placed = _placed(self.result)
        return written

    def autosave(self) -> None:
        """After a merge: save the map (``save_on_shutdown``) when the robots placed changed
        or the last save is :data:`AUTOSAVE_PERIOD` old; a failed save is a warning, the map is
        kept. An update that left work pending (places unmatched, pairs unjudged) may lack
        placements it is about to make (a robot placed before and not yet matched again): it
        is saved only when it places every robot the last save did and more, so that a restart
        never finds fewer."""
        if not self.config.save_on_shutdown:
            return
        placed = _placed(self.result)
        if merge_pending(self.result) and not placed > self._saved_placed:
            return
        recent = time.monotonic() - self._saved_at < AUTOSAVE_PERIOD
        if recent and placed == self._saved_placed:
            return
        try:
            self.save_map()
        except SavedMapError as exc:
            self.get_logger().warning(f"map not saved: {exc}")
            self._saved_at = time.monotonic()  # not retried at every merge

    def save_on_exit(self) -> None:
        """The map saved on shutdown (``save_on_shutdown``), unless the last update left
        work pending (places unmatched, pairs unjudged) and placed fewer robots than the file
        holds: then the file, of the last save, keeps them for the next start (each robot's map
        comes back from its latched snapshot)."""
        placed = _placed(self.result)
        if merge_pending(self.result) and not placed >= self._saved_placed:
            self.get_logger().warning(
                f"map not saved on shutdown: the last update left work pending and placed "
                f"{len(placed)} of the {len(self._saved_placed)} robots {self.config.map_file} "
                "holds; that file is kept"
            )
            return
        try:
            path = self.save_map()
            self.get_logger().info(f"map saved to {path} on shutdown")
        except SavedMapError as exc:
            self.get_logger().error(f"map not saved on shutdown: {exc}")

    def load_map(self, path: str | None = None) -> list[str]:
        """Read a saved map (default ``map_file``) and merge its robots with the live ones;
        returns the robots loaded. Raises :class:`SavedMapError`.

        With no merge yet, the saved placements are published at once (each robot's frame
        is fixed in its own map, so a placement made before stays right while its robot maps
        on): those whose probability was saved, and the reference's. The next merge
        publishes its own."""
        saved = read_saved_map(path or self.config.map_file)
        with self._lock:
            loaded = restore_saved_map(self.robots, saved, self.config.keep_sessions)
            restored = self.result is None
            if restored:
                self.result = result_of_saved(saved)  # its reference stays the map frame
                self._saved_placed = _placed(self.result)  # what the file holds
            self._merged_versions = {}
            inputs = merge_inputs(self.robots)
        if restored and self.result is not None:
            self._publish_result(_known_placements(self.result), inputs, True)
        return loaded

    def _on_save(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        return _answer(response, lambda: f"map saved to {self.save_map()}")

    def _on_load(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        def load() -> str:
            loaded = self.load_map()
            return f"loaded {len(loaded)} robots' maps: {', '.join(loaded) or 'none'}"

        return _answer(response, load)

    def _load_at_start(self) -> None:
        try:
            loaded = self.load_map()
        except SavedMapError as exc:
            self.get_logger().warning(f"load_on_start: nothing loaded: {exc}")
            return
        self.get_logger().info(
            f"loaded {', '.join(loaded) or 'no robot'} from {self.config.map_file}"
        )


def _placed(result: MergeResult | None) -> frozenset[str]:
    return frozenset(
        () if result is None else (n for n, p in result.placements.items() if p is not None)
    )


def _known_placements(result: MergeResult) -> MergeResult:
    """``result`` with the placements of unknown probability left out (none is withdrawn:
    nothing was published before)."""
    known = {
        name: pose if name == result.reference or name in result.probabilities else None
        for name, pose in result.placements.items()
    }
    return dataclasses.replace(result, placements=known)


def _answer(response: Trigger.Response, action: Callable[[], str]) -> Trigger.Response:
    """A Trigger answer: success and what ``action`` says, or failure and why."""
    try:
        response.message = action()
        response.success = True
    except SavedMapError as exc:
        response.success, response.message = False, str(exc)
    return response
