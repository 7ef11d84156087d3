"""Map merging's parameters, one typed config."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from multi_robot_mapper.core.config import param, validate
from multi_robot_mapper.core.evidence.correlation import CorrelationConfig
from multi_robot_mapper.core.matching import IntegrateConfig
from multi_robot_mapper.core.merging.ffs.config import FfsConfig
from multi_robot_mapper.core.merging.free_space import FreeDrawing, FreeSpaceLimits, ViewFan
from multi_robot_mapper.core.merging.joint_graph_config import JointGraphConfig
from multi_robot_mapper.core.merging.pairwise_config import PairwiseConfig


@dataclasses.dataclass(frozen=True)
class MergeConfig:
    """Map merging. Lengths in metres, angles in radians.

    ``integrate`` holds INTEGRATE's matching tolerances; for links between maps its validity
    thresholds (``min_match_value``, ``min_match_fraction``, ``min_cross_support``) and its
    hypothesis budget (``max_hypotheses``, ``all_pairs_below``, ``refine_candidates``) are
    replaced by ``pairwise``'s (:meth:`link_config`): partial maps are larger than scans and
    overlap by a smaller fraction.
    """

    reference: str = param(
        "",
        unit="",
        doc="robot whose map frame is 'map'; empty: the robot with the largest map (total "
        "segment length) among the largest group of linked robots",
        tune="one robot's map should be 'map' (one that starts at a known place): name it",
    )
    correlation_cell: float = param(
        0.3,
        unit="m",
        doc="grid cell of the map correlation (its walls are blurred by one cell)",
        minimum=0.05,
        maximum=10.0,
    )
    free_space_weight: float = param(
        2.0,
        unit="",
        doc="in the correlation score, a metre of wall lying in the other robot's free space "
        "counts against as this many metres of matched wall",
        minimum=0.0,
        maximum=100.0,
    )
    link_max_seen_through: float = param(
        1.0,
        unit="m",
        doc="validity threshold: a link is refused when more than this length of either map "
        "(and more than link_max_seen_through_fraction of its value) lies in free space the "
        "other robot saw from its keyframes (only when keyframe poses are given); the joint "
        "merger (pivot) refuses a pair's consistent set of links when it puts more than this "
        "per link_min_support places it links (at least this) of the walls near its places "
        "there, both with the maps rigid and with each wall placed by its nearest confident "
        "link (not a fraction of the value: so placed, the maps' own drift is small, but "
        "the walls near the places grow with the places)",
        minimum=0.0,
        maximum=1000000.0,
    )
    link_max_seen_through_fraction: float = param(
        0.1,
        unit="",
        doc="see link_max_seen_through: the allowance as a fraction of the link's value (large "
        "overlaps of drifting maps tolerate a little more)",
        minimum=0.0,
        maximum=10.0,
    )
    free_space_margin: float = param(
        0.5,
        unit="m",
        doc="a wall of the other map is in a robot's free space when it lies at least this much "
        "nearer a viewpoint than the robot's own map along the same bearing",
        minimum=0.0,
        maximum=10.0,
    )
    free_space_min_length: float = param(
        1.0,
        unit="m",
        doc="only segments at least this long are tested against the other robot's free space "
        "(walls; short pieces are furniture, exhibits and people, which move or are seen from "
        "one side only)",
        minimum=0.0,
        maximum=100.0,
    )
    view_spacing: float = param(
        1.0,
        unit="m",
        doc="viewpoints (keyframe poses) closer than this to one already kept add no evidence",
        minimum=0.0,
        maximum=100.0,
    )
    max_views: int = param(
        60,
        unit="",
        doc="at most this many viewpoints per map, evenly spread over the kept ones",
        minimum=1,
        maximum=10_000,
    )
    view_range: float = param(
        8.0,
        unit="m",
        doc="free space reaches at most this far from a viewpoint (a wall must be seen in the "
        "robot's own map within it)",
        minimum=0.1,
        maximum=1000.0,
    )
    view_spread: int = param(
        6,
        unit="bearings",
        doc="free space along a bearing reaches only the nearest wall within this many "
        "bearings either side (gaps between a map's segments are not seen through)",
        minimum=0,
        maximum=360,
    )
    view_field: float = param(
        float(np.pi),
        unit="rad",
        doc="field of view claimed around each keyframe's heading (the laser's forward "
        "direction; 180 degrees is the narrowest common laser: wider ones claim less than they "
        "saw, never more)",
        minimum=0.01,
        maximum=2.0 * math.pi,
        tune="a sensor narrower than 180 degrees (a depth camera): its field of view, or merges "
        "are judged on free space it never saw",
    )
    view_beams: int = param(
        360,
        unit="",
        doc="bearings per full turn at which the robot's own map is ray cast",
        minimum=8,
        maximum=36_000,
    )
    fusion_tolerance: float = param(
        0.05,
        unit="m",
        doc="FUSIONTOLERANCE of the global map: a fused polyline stays this close to every "
        "segment it replaces",
        minimum=0.001,
        maximum=1.0,
    )
    place_radius: float = param(
        6.0,
        unit="m",
        doc="a place (what one link matches) is a keyframe and its robot's walls within this "
        "distance: small enough that a map's drift across it is negligible, large enough to "
        "hold more than one room's walls",
        minimum=0.5,
        maximum=100.0,
    )
    place_spacing: float = param(
        3.0,
        unit="m",
        doc="places are keyframes at least this far apart (greedily, oldest first)",
        minimum=0.1,
        maximum=100.0,
    )
    place_min_length: float = param(
        12.0,
        unit="m",
        doc="a place with less wall than this is never matched (too little to tell places apart)",
        minimum=0.0,
        maximum=1000.0,
    )
    link_hypotheses: int = param(
        4,
        unit="",
        doc="the best distinct placements of a place on another robot's map (map correlation) "
        "verified by INTEGRATE; the best two become link candidates",
        minimum=1,
        maximum=20,
    )
    shape_hypotheses: int = param(
        0,
        unit="",
        doc="more placements of a place to verify, from Wolter's shape matching of the "
        "place's synthetic all-round scan on this many of the other map's views (those that "
        "share the most shape with it); 0: the correlation's placements only (it raised merge "
        "success on no shared log: README, 'Wolter's shape-based matching')",
        minimum=0,
        maximum=20,
    )
    link_min_overlap: float = param(
        0.25,
        unit="",
        doc="a place whose best correlation score is below this fraction of its wall length "
        "is not verified (it lies nowhere on the other map)",
        minimum=0.0,
        maximum=1.0,
    )
    link_min_wall: float = param(
        5.0,
        unit="m",
        doc="a link candidate (a place found on another robot's map) must match at least this "
        "length of wall (link_min_value is for whole maps)",
        minimum=0.0,
        maximum=1000.0,
    )
    link_confidence: float = param(
        0.9,
        unit="",
        doc="a link between robots counts as confident when INTEGRATE's calibrated confidence "
        "(P right within 0.30 m / 5 deg, its rival placements included) reaches this; chosen "
        "from the precision/recall curve of bench/link_bench.py (README, 'Joint merging')",
        minimum=0.0,
        maximum=1.0,
    )
    link_fit: float = param(
        0.5,
        unit="",
        doc="a link candidate whose confidence without its rivals (how well the place fits "
        "there at all) is below this is dropped; above it, an ambiguous link (a rival fits "
        "about as well) is accepted only inside a consistent set of links",
        minimum=0.0,
        maximum=1.0,
    )
    link_min_support: int = param(
        3,
        unit="places",
        doc="a consistent set of links of one pair of maps with no confident link is accepted "
        "when it links at least this many places",
        minimum=1,
        maximum=1000,
    )
    link_confident_support: int = param(
        2,
        unit="places",
        doc="a consistent set of links of one pair of maps holding a confident link is accepted "
        "when it links at least this many places: one place that fits well can still be a "
        "look-alike of another building",
        minimum=1,
        maximum=1000,
    )
    join_probability: float = param(
        0.99,
        unit="",
        doc="the probability that a placement is right (the join model's, fitted on generated "
        "buildings and shared logs: docs/evidence_model.md) that joining two maps needs, and "
        "that a robot's placement (over its "
        "paths of joins to the reference) needs to be published; below it a robot is "
        "unmerged, with the reason. The one threshold of every merge decision: lower it to "
        "merge sooner at more risk of a wrong map",
        minimum=0.5,
        maximum=0.999999,
        tune="lower merges sooner and places wrong more often (held out at 0.9: 18 wrong per 1000"
        " joins accepted)",
    )
    link_set_uniqueness: float = param(
        2.0,
        unit="",
        doc="the accepted set of consistent links of a pair of maps must weigh (sum of link "
        "fits) at least this many times the best set inconsistent with it, when that set has the "
        "support link_min_support / link_confident_support ask: a building that fits two ways "
        "is refused",
        minimum=1.0,
        maximum=100.0,
    )
    link_pair_slack: float = param(
        0.03,
        unit="m/m",
        doc="two links of one pair of maps agree when the cycle through both robots' maps "
        "closes within 0.30 m and 5 deg plus this much per metre between the links' places "
        "(each robot's own drift)",
        minimum=0.0,
        maximum=1.0,
    )
    link_pair_angle_slack: float = param(
        0.005,
        unit="rad/m",
        doc="see link_pair_slack, for the rotation",
        minimum=0.0,
        maximum=1.0,
    )
    max_speed: float = param(
        2.0,
        unit="m/s",
        doc="the fastest any robot drives: a merge that puts two keyframes of one robot, in "
        "two of its pieces, farther apart than it can have driven between their stamps is "
        "refused (a piece placed at a look-alike of the place it followed)",
        minimum=0.01,
        maximum=100.0,
        tune="a robot of the team faster than 2 m/s: its top speed",
    )
    update_budget: float = param(
        1.0,
        unit="s",
        doc="seconds a merge update may take in the node (a replay matches and judges "
        "everything): place matching, then the verdicts on pairs of maps, get what the graph "
        "and fusion of the last update left; places not matched and pairs not judged again "
        "wait for the next update (new places, never-judged pairs first; a waiting pair keeps "
        "its last verdict); 0: no limit",
        minimum=0.0,
        maximum=3600.0,
        tune="more with more robots or a slow computer; 0: every place matched each update (slow)",
    )
    integrate: IntegrateConfig = dataclasses.field(default_factory=IntegrateConfig)
    # the whole-map merge (merge(): every pair of maps matched whole, a spanning tree of links)
    pairwise: PairwiseConfig = dataclasses.field(default_factory=PairwiseConfig)
    # the joint graph of every robot's keyframes (method 'pivot' and 'ffs')
    graph: JointGraphConfig = dataclasses.field(default_factory=JointGraphConfig)
    # Force Field Simulation after the joint graph's placement (method 'ffs' only)
    ffs: FfsConfig = dataclasses.field(default_factory=FfsConfig)

    def __post_init__(self) -> None:
        validate(self)

    def correlation(self) -> CorrelationConfig:
        """The map correlation's settings from this config."""
        return CorrelationConfig(
            cell=self.correlation_cell, free_space_weight=self.free_space_weight
        )

    def view_fan(self) -> ViewFan:
        """How a map's views are cast (``view_spacing``, ``max_views``, ``view_beams``,
        ``view_field``, ``view_range``)."""
        return ViewFan(
            self.view_spacing, self.max_views, self.view_beams, self.view_field, self.view_range
        )

    def free_space_limits(self) -> FreeSpaceLimits:
        """What a wall in free space is (``free_space_min_length``, ``view_spread``,
        ``free_space_margin``)."""
        return FreeSpaceLimits(self.free_space_min_length, self.view_spread, self.free_space_margin)

    def free_drawing(self) -> FreeDrawing:
        """How free space is drawn for the correlation (``correlation_cell``, ``view_spread``,
        ``free_space_margin``, ``view_range``)."""
        return FreeDrawing(
            self.correlation_cell, self.view_spread, self.free_space_margin, self.view_range
        )

    def link_config(self, hypotheses: int | None = None, viewed: bool = False) -> IntegrateConfig:
        """``integrate`` with the whole-map merge's validity thresholds (``viewed``: those for
        two robots whose viewpoints are known) and hypothesis budget (``pairwise``)."""
        pairwise = self.pairwise
        return dataclasses.replace(
            self.integrate,
            min_match_value=pairwise.link_min_value,
            min_match_fraction=(
                pairwise.viewed_link_min_fraction if viewed else pairwise.link_min_fraction
            ),
            min_cross_support=pairwise.link_min_cross_support,
            max_hypotheses=pairwise.max_hypotheses if hypotheses is None else hypotheses,
            all_pairs_below=pairwise.hypothesis_segments,
            refine_candidates=min(self.integrate.refine_candidates, 3),
        )
