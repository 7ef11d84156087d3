"""Every node of a multi-robot mapping system in one process, without launch files.

One ``robot_mapper`` per robot namespace and one ``map_merger`` that merges exactly those
robots: what ``mrm run --in-process`` spins on a multi-threaded executor (as a component
container would), and what tests build in their own contexts. (``mrm run``, ``mrm demo`` and
``bench/live_load.py`` run the robots' mappers in processes of their own instead:
``ros/processes.py``.)
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Iterable, Sequence

from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter

from multi_robot_mapper.core.config import ConfigError
from multi_robot_mapper.ros.map_merger import MapMerger
from multi_robot_mapper.ros.robot_mapper import RobotMapper

_NAMESPACE = re.compile(r"[A-Za-z][A-Za-z0-9_]*(/[A-Za-z][A-Za-z0-9_]*)*")


def robot_names(text: str | Iterable[str]) -> list[str]:
    """Robot namespaces from ``"robot1,/robot2, robot3/"`` (or a list): slashes at the ends
    and repeats dropped; raises :class:`ConfigError` for a name ROS cannot use as a
    namespace or for an empty list."""
    items = text.split(",") if isinstance(text, str) else list(text)
    names: list[str] = []
    for item in items:
        name = item.strip().strip("/")
        if not name:
            continue
        if not _NAMESPACE.fullmatch(name):
            raise ConfigError(
                f"robot {item.strip()!r} is not a ROS namespace (letters, digits and '_', "
                "starting with a letter; '/' between parts)"
            )
        if name not in names:
            names.append(name)
    if not names:
        raise ConfigError("no robot given (e.g. --robots robot1,robot2)")
    return names


@dataclasses.dataclass
class System:
    """The nodes of one mapping system."""

    mappers: dict[str, RobotMapper]
    merger: MapMerger

    @property
    def nodes(self) -> list[Node]:
        return [*self.mappers.values(), self.merger]

    def destroy(self) -> None:
        for node in reversed(self.nodes):
            node.destroy_node()


def build_system(
    robots: Sequence[str],
    method: str | None = None,
    context: Context | None = None,
    mapper_parameters: Sequence[Parameter] = (),
    merger_parameters: Sequence[Parameter] = (),
) -> System:
    """A ``robot_mapper`` in each robot's namespace and a ``map_merger`` of those robots
    (``method`` when given). Parameters come from the context's ``--params-file`` and
    ``-p`` arguments, then from the ``*_parameters`` given here. Raises
    :class:`ConfigError` for invalid parameters (no node is left behind)."""
    names = robot_names(robots)
    overrides = [Parameter("robots", value=",".join(names)), *merger_parameters]
    if method is not None:
        overrides.append(Parameter("method", value=method))
    merger = MapMerger(context=context, parameter_overrides=overrides)
    mappers: dict[str, RobotMapper] = {}
    try:
        for name in names:
            mappers[name] = RobotMapper(
                context=context, namespace=f"/{name}", parameter_overrides=list(mapper_parameters)
            )
    except BaseException:
        for node in (*mappers.values(), merger):
            node.destroy_node()
        raise
    return System(mappers, merger)
