"""Configuration of the map merger: everything ``map_merger`` reads."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import ConfigError, param, validate
from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.methods import MERGE_METHODS
from multi_robot_mapper.core.merging.occupancy import GridConfig

# The node's choices: the merging registry's names, the one list of merging methods.
METHODS = tuple(MERGE_METHODS)


@dataclasses.dataclass(frozen=True)
class MapMergerConfig:
    """Map merger node. ROS parameter names are the dotted field names (``merge.*``,
    ``merge.integrate.*``)."""

    robots: str = param(
        "",
        unit="",
        doc="comma-separated robot namespaces to merge (e.g. 'robot1,robot2'); empty: "
        "discover every '<namespace>/partial_map' topic as it appears",
        tune="to merge exactly the robots listed (empty discovers every '*/partial_map')",
    )
    discovery_period: float = param(
        2.0,
        unit="s",
        doc="how often the topic list is searched for new '<namespace>/partial_map' topics "
        "(only when robots is empty)",
        minimum=0.05,
        maximum=3600.0,
        tune="shorter to find robots that join the team sooner",
    )
    merge_period: float = param(
        1.0,
        unit="s",
        doc="how often the partial maps are merged again, when one of them changed",
        minimum=0.05,
        maximum=3600.0,
        tune="longer with many robots or a slow computer; shorter to see merges sooner",
    )
    map_frame: str = param(
        "map",
        unit="",
        doc="frame of global_map and of every robot frame's pose (the reference robot's map)",
        tune="your fleet's global frame has another name",
    )
    method: str = param(
        "pivot",
        unit="",
        doc="merging method: 'pivot' (the joint graph: every robot's keyframes linked where "
        "their places match, consistent links only, optimised together) or 'ffs' (the same, "
        "then Force Field Simulation moves every merged keyframe at once: merge.ffs.*)",
        choices=METHODS,
        tune="to try Force Field Simulation after the joint graph (no gain measured yet): 'ffs'",
    )
    marker_width: float = param(
        0.05,
        unit="m",
        doc="line width of the global map's segment markers (visualisation only)",
        minimum=0.001,
        maximum=10.0,
        tune="the global map looks too thin or too thick in RViz at your zoom",
    )
    merge_worker: bool = param(
        True,
        unit="",
        doc="merge in a worker process: a merge is seconds of numpy work, and in this "
        "process it would take Python's interpreter lock from the subscriptions (and from "
        "any node spun in the same process, as in tests); false: merge in this process",
        tune="a computer with one core or little memory, or to debug a merge in one process: false",
    )
    warning_period: float = param(
        10.0,
        unit="s",
        doc="the same kind of message (a robot still unmerged, a failed merge) is logged at "
        "most once per this period",
        minimum=0.0,
        maximum=3600.0,
        tune="shorter while you chase bad input, longer for quieter logs",
    )
    max_keyframes_per_map: int = param(
        50_000,
        unit="keyframes",
        doc="a partial map with more keyframe markers is refused before it is read (a robot "
        "keeps its last good map)",
        minimum=1,
        maximum=10_000_000,
    )
    max_segments_per_map: int = param(
        200_000,
        unit="segments",
        doc="a partial map with more segments (line-list point pairs) is refused before it is read",
        minimum=1,
        maximum=10_000_000,
    )
    max_map_extent: float = param(
        200.0,
        unit="m",
        doc="a partial map (or pose) reaching farther from its robot's map origin is refused: "
        "the map correlation's memory grows with the square of the extent (two 300-segment "
        "maps reaching 200 m from their origins: 0.8 GB and 13 s on one core)",
        minimum=1.0,
        maximum=100_000.0,
        tune="a site reaching farther than 200 m from a robot's start: raise it (memory grows "
        "with its square)",
    )
    stale_timeout: float = param(
        5.0,
        unit="s",
        doc="a robot whose partial map and pose have not arrived for this long is STALE in "
        "/diagnostics (its map stays in the global map; node clock: sim time when "
        "use_sim_time is set)",
        minimum=0.01,
        maximum=86400.0,
        tune="longer for robots that publish rarely (a thin radio link, a long partial_map_period)",
    )
    diagnostics_period: float = param(
        1.0,
        unit="s",
        doc="how often every robot's status (OK merged / WARN unmerged / STALE silent, pose "
        "rate, merge score) goes out on /diagnostics",
        minimum=0.01,
        maximum=3600.0,
        tune="your diagnostics aggregator or monitor expects another rate",
    )
    map_file: str = param(
        "~/.ros/multi_robot_mapper/global_map.json",
        unit="",
        doc="file the save_map and load_map services (std_srvs/Trigger) write and read: every "
        "robot's partial map and placement, and the global map",
        tune="to keep saved maps elsewhere (one file per site)",
    )
    save_on_shutdown: bool = param(
        False,
        unit="",
        doc="save the map to map_file when the node shuts down, and every 10 s while merges "
        "change it (a killed merger leaves a recent file)",
        tune="to keep the map when the merger stops or is killed: true",
    )
    load_on_start: bool = param(
        False,
        unit="",
        doc="load map_file at start-up when it exists (live robots' maps then replace the "
        "saved ones of the same session)",
        tune="to go on from the saved map (a team continuing yesterday's map): true",
    )
    keep_sessions: int = param(
        2,
        unit="",
        doc="a robot that restarts (its map begins again with another first keyframe) keeps "
        "its earlier maps as '<robot>_session<k>', merged like any robot; at most this many "
        "per robot (the oldest goes first)",
        minimum=0,
        maximum=100,
        tune="fewer for robots that restart often (memory and merge time); 0 drops a restarted "
        "robot's earlier map",
    )
    grid: GridConfig = dataclasses.field(default_factory=GridConfig)
    merge: MergeConfig = dataclasses.field(default_factory=MergeConfig)

    def __post_init__(self) -> None:
        validate(self)

    def robot_names(self) -> list[str]:
        """The ``robots`` list as robot names: namespaces without leading/trailing slashes,
        blanks and repeats dropped, in the given order."""
        names: list[str] = []
        for item in self.robots.split(","):
            name = item.strip().strip("/")
            if name and name not in names:
                names.append(name)
        return names

    def require_implemented(self) -> None:
        """Raise :class:`ConfigError` when ``method`` names a method not implemented yet."""
        if self.method not in MERGE_METHODS:
            raise ConfigError(
                f"parameter 'method' = {self.method!r} is not a merging method; use one of: "
                f"{', '.join(MERGE_METHODS)}"
            )
