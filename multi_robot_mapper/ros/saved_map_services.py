"""The map merger's saved maps: the ``save_map`` and ``load_map`` services (std_srvs/Trigger),
saving on shutdown and loading at start-up (``map_file``; the file format is io/saved_map.py)."""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from std_srvs.srv import Trigger

from multi_robot_mapper.core.merging import MergeResult
from multi_robot_mapper.io.saved_map import SavedMapError, read_saved_map, write_saved_map
from multi_robot_mapper.ros.merger_config import MapMergerConfig
from multi_robot_mapper.ros.merger_state import (
    RobotState,
    restore_saved_map,
    result_of_saved,
    saved_map_of,
)


class SavedMapServices:
    """Mixed into :class:`~multi_robot_mapper.ros.map_merger.MapMerger` (before ``Node``, which
    provides ``get_logger``): what it saves and loads, under its lock."""

    robots: dict[str, RobotState]
    result: MergeResult | None
    config: MapMergerConfig
    _lock: threading.Lock
    _merged_versions: dict[str, Any]

    def save_map(self, path: str | None = None) -> str:
        """Write every robot's partial map and placement and the global map to ``path``
        (default ``map_file``); raises :class:`SavedMapError`."""
        with self._lock:
            saved = saved_map_of(self.robots, self.result, self.config.map_frame)
        return str(write_saved_map(path or self.config.map_file, saved))

    def load_map(self, path: str | None = None) -> list[str]:
        """Read a saved map (default ``map_file``) and merge its robots with the live ones;
        returns the robots loaded. Raises :class:`SavedMapError`."""
        saved = read_saved_map(path or self.config.map_file)
        with self._lock:
            loaded = restore_saved_map(self.robots, saved, self.config.keep_sessions)
            if self.result is None:
                self.result = result_of_saved(saved)  # its reference stays the map frame
            self._merged_versions = {}
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


def _answer(response: Trigger.Response, action: Callable[[], str]) -> Trigger.Response:
    """A Trigger answer: success and what ``action`` says, or failure and why."""
    try:
        response.message = action()
        response.success = True
    except SavedMapError as exc:
        response.success, response.message = False, str(exc)
    return response
