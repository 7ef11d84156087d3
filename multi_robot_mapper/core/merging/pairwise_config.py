"""The whole-map merge's parameters (pairwise.py, link_graph.py: every pair of partial maps
matched whole, the links that pass the validity thresholds, a spanning tree of them). Lengths
in metres."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate


@dataclasses.dataclass(frozen=True)
class PairwiseConfig:
    """Validity thresholds, hypothesis budget and reuse of the whole-map merge
    (``merge.pairwise.*``; :func:`~multi_robot_mapper.core.merging.link_graph.merge`)."""

    link_min_value: float = param(
        15.0,
        unit="m",
        doc="validity threshold: a link's best transformation must overlap at least this "
        "length of matching segments (more than the walls of one room: a single room or "
        "corner looks alike in many places)",
        minimum=0.0,
        maximum=1000000.0,
    )
    link_min_fraction: float = param(
        0.3,
        unit="",
        doc="validity threshold on segments alone (a robot without viewpoints): overlap at "
        "least this fraction of the shorter map's total segment length",
        minimum=0.0,
        maximum=1.0,
    )
    viewed_link_min_fraction: float = param(
        0.1,
        unit="",
        doc="link_min_fraction when both robots' viewpoints are known: free space and "
        "uniqueness (link_min_uniqueness) then tell look-alike places apart, and robots that "
        "share a small part of their maps can be linked",
        minimum=0.0,
        maximum=1.0,
    )
    link_min_cross_support: float = param(
        1.5,
        unit="m",
        doc="validity threshold: matched length across the least constrained direction "
        "(parallel walls alone cannot fix the offset along them)",
        minimum=0.0,
        maximum=1000.0,
    )
    link_min_tight_fraction: float = param(
        0.15,
        unit="",
        doc="validity threshold on segments alone: segments matched within tight_distance must "
        "overlap at least this fraction of the shorter map (the same walls coincide to "
        "centimetres, look-alike walls of other places only roughly)",
        minimum=0.0,
        maximum=1.0,
    )
    viewed_link_min_tight_fraction: float = param(
        0.05,
        unit="",
        doc="link_min_tight_fraction when both robots' viewpoints are known",
        minimum=0.0,
        maximum=1.0,
    )
    tight_distance: float = param(
        0.05,
        unit="m",
        doc="matching distance of the tight overlap (link_min_tight_fraction)",
        minimum=0.001,
        maximum=1.0,
    )
    hypothesis_segments: int = param(
        12,
        unit="segments",
        doc="the angles between every pair of this many longest segments of each map "
        "propose the transformations",
        minimum=2,
        maximum=1000,
    )
    coarse_segments: int = param(
        40,
        unit="segments",
        doc="hypotheses are ranked on this many longest segments of each map; the best are "
        "then refined and judged on the whole maps",
        minimum=2,
        maximum=10_000,
    )
    judge_segments: int = param(
        250,
        unit="segments",
        doc="the best hypotheses are refined and judged on this many longest segments of each "
        "map (short pieces add cost, not evidence)",
        minimum=2,
        maximum=100_000,
    )
    correlation_candidates: int = param(
        8,
        unit="",
        doc="the best placements of the map correlation (every translation, for each rotation "
        "the wall directions allow) that join INTEGRATE's own hypothesis as candidates; the "
        "best few distinct places among them are refined and judged",
        minimum=1,
        maximum=1000,
    )
    link_min_uniqueness: float = param(
        2.0,
        unit="",
        doc="validity threshold when both robots' viewpoints are known: the link's "
        "correlation score (matched wall minus wall in free space, m) must be at least this "
        "many times that of the best distinct placement (> 2 m or 10 degrees away): a place "
        "that fits twice is ambiguous (symmetric corridors, rows of equal rooms) and is "
        "refused",
        minimum=1.0,
        maximum=100.0,
    )
    max_hypotheses: int = param(
        150,
        unit="",
        doc="at most this many most-voted INTEGRATE hypotheses are ranked per pair of maps",
        minimum=1,
        maximum=100_000,
    )
    reuse_length_change: float = param(
        5.0,
        unit="%",
        doc="a pair's result is reused while each map's total segment length stays within "
        "this of the length it was computed on (and its segment count within "
        "reuse_count_change)",
        minimum=0.0,
        maximum=100.0,
    )
    reuse_count_change: float = param(
        10.0,
        unit="%",
        doc="a pair's result is reused while each map's segment count stays within this (or "
        "2 segments) of the count it was computed on",
        minimum=0.0,
        maximum=100.0,
    )
    stability_margin: float = param(
        0.25,
        unit="",
        doc="a link of the previous tree stays in the tree unless another link's value "
        "exceeds it by this fraction (placements do not flip between similar links)",
        minimum=0.0,
        maximum=10.0,
    )

    def __post_init__(self) -> None:
        validate(self)
