"""What "reject" means in every node, and the guard that keeps any error inside a callback.

A rejected input is not used; a counter per robot and reason goes up; a throttled warning
names the robot, the message field and the problem; the node goes on, and later good input is
used as usual. ``robot_mapper`` rejects scans this way and ``map_merger`` partial maps and
poses: one mechanism for both.
"""

from __future__ import annotations

import functools
import traceback
from collections import Counter
from collections.abc import Callable
from typing import Any, TypeVar

from rclpy.exceptions import InvalidHandle

from multi_robot_mapper.ros.throttle import ThrottledWarnings

F = TypeVar("F", bound=Callable[..., Any])


class Rejections:
    """Counters of rejected input per robot and reason, with throttled warnings."""

    def __init__(self, warnings: ThrottledWarnings) -> None:
        self.warnings = warnings
        self.counts: Counter[tuple[str, str]] = Counter()  # (robot, reason) -> inputs

    def reject(self, robot: str, kind: str, field: str, message: str, what: str) -> None:
        """Count one ``what`` (e.g. "scan", "partial map") of ``robot`` rejected for ``kind``."""
        self.counts[(robot, kind)] += 1
        where = f" [{field}]" if field else ""
        self.warnings.warn(
            f"{kind}:{robot}", f"{robot}: {what} rejected ({kind}){where}: {message}"
        )

    def of(self, robot: str) -> dict[str, int]:
        """Reasons and counts of ``robot``'s rejected input."""
        return {kind: n for (name, kind), n in self.counts.items() if name == robot}

    def total(self, kind: str | None = None) -> int:
        return sum(n for (_, k), n in self.counts.items() if kind is None or k == kind)


class CallbackGuard:
    """Wraps node callbacks so that no exception escapes into the executor: it is logged
    (throttled per callback, with the traceback) and counted, and the node goes on."""

    def __init__(
        self, warnings: ThrottledWarnings, running: Callable[[], bool] | None = None
    ) -> None:
        self.warnings = warnings
        # False once the node's context is shut down: a timer that fires while the node is
        # being torn down fails to publish, which is no error of the node's.
        self.running = running or (lambda: True)
        self.errors: Counter[str] = Counter()  # callback name -> exceptions caught

    def __call__(self, name: str, callback: F, fallback: Any = None) -> F:
        @functools.wraps(callback)  # keeps the signature: rclpy reads it (message info or not)
        def guarded(*args: Any) -> Any:
            try:
                return callback(*args)
            except InvalidHandle:  # the node is being destroyed: nothing to report
                return fallback
            except Exception:
                if not self.running():
                    return fallback
                self.errors[name] += 1
                self.warnings.warn(
                    f"callback_error:{name}",
                    f"error in {name} (survived; the node goes on):\n{traceback.format_exc()}",
                )
                return fallback

        return guarded  # type: ignore[return-value]
