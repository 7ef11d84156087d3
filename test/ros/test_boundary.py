"""What "reject" means in the nodes (ros/boundary.py): a rejection counted per robot and reason
with a throttled warning naming the field; a callback's error caught, counted and logged, the
callback's fallback returned; no report while the node is shutting down."""

from __future__ import annotations

from rclpy.exceptions import InvalidHandle

from multi_robot_mapper.ros.boundary import CallbackGuard, Rejections
from multi_robot_mapper.ros.throttle import ThrottledWarnings


def warnings(logged: list[str]) -> ThrottledWarnings:
    return ThrottledWarnings(logged.append, period=10.0, clock=lambda: 0.0)


def test_rejections_are_counted_per_robot_and_reason_and_warned_once_per_period() -> None:
    logged: list[str] = []
    rejections = Rejections(warnings(logged))
    rejections.reject("robot1", "nan_pose", "pose.position.x", "is NaN", "pose")
    rejections.reject("robot1", "nan_pose", "pose.position.x", "is NaN", "pose")
    rejections.reject("robot1", "too_many_keyframes", "", "2001 > 2000", "partial map")
    rejections.reject("robot2", "nan_pose", "pose.position.y", "is NaN", "pose")
    assert rejections.of("robot1") == {"nan_pose": 2, "too_many_keyframes": 1}
    assert rejections.of("robot3") == {}
    assert rejections.total() == 4 and rejections.total("nan_pose") == 3
    assert logged == [
        "robot1: pose rejected (nan_pose) [pose.position.x]: is NaN",  # the repeat is throttled
        "robot1: partial map rejected (too_many_keyframes): 2001 > 2000",
        "robot2: pose rejected (nan_pose) [pose.position.y]: is NaN",
    ]


def test_a_callbacks_error_is_survived_counted_and_logged_with_its_traceback() -> None:
    logged: list[str] = []
    guard = CallbackGuard(warnings(logged))

    def on_scan(message: object) -> str:
        """The callback's own docstring, which rclpy may read."""
        if message is None:
            raise ZeroDivisionError("no scan")
        return "mapped"

    guarded = guard("on_scan", on_scan, fallback="kept")
    assert guarded.__name__ == "on_scan" and guarded.__doc__ == on_scan.__doc__
    assert guarded(object()) == "mapped"
    assert guarded(None) == "kept"
    assert guard.errors == {"on_scan": 1}
    assert len(logged) == 1
    assert logged[0].startswith("error in on_scan (survived; the node goes on):")
    assert "ZeroDivisionError: no scan" in logged[0]


def test_nothing_is_reported_while_the_node_is_torn_down() -> None:
    logged: list[str] = []
    running = [True]
    guard = CallbackGuard(warnings(logged), running=lambda: running[0])

    def destroyed() -> None:
        raise InvalidHandle("destroyed")

    def failing() -> None:
        raise RuntimeError("publish after shutdown")

    assert guard("timer", destroyed, fallback=0)() == 0  # a destroyed handle: never an error
    running[0] = False
    assert guard("timer", failing)() is None
    assert guard.errors == {} and logged == []
