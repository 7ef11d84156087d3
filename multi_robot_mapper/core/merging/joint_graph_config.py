"""The joint graph's parameters (joint_graph.py): how much a robot's own map may bend between
its keyframes, and how far a link between robots is trusted. Lengths in metres, angles in
radians."""

from __future__ import annotations

import dataclasses

from multi_robot_mapper.core.config import param, validate


@dataclasses.dataclass(frozen=True)
class JointGraphConfig:
    """The graph of every keyframe of the maps joined to the reference (``merge.graph.*``):
    edges inside a map from its published poses, links between maps."""

    sigma: float = param(
        0.02,
        unit="m",
        doc="an edge between two keyframes of one robot's map (their published poses) has this "
        "standard deviation, plus drift per metre between them",
        minimum=1e-4,
        maximum=10.0,
    )
    drift: float = param(
        0.02,
        unit="m/m",
        doc="see sigma: how much a robot's own map may bend per metre",
        minimum=0.0,
        maximum=1.0,
    )
    angle_sigma: float = param(
        0.005,
        unit="rad",
        doc="rotation of an edge between two keyframes of one robot's map, plus "
        "angle_drift per metre",
        minimum=1e-5,
        maximum=1.0,
    )
    angle_drift: float = param(
        0.005,
        unit="rad/m",
        doc="see angle_sigma",
        minimum=0.0,
        maximum=1.0,
    )
    radius: float = param(
        2.0,
        unit="m",
        doc="besides consecutive keyframes, keyframes of one robot's map this close to each "
        "other get an edge (the wire carries no loop closures: this keeps what the robot's own "
        "closures made of its map)",
        minimum=0.0,
        maximum=100.0,
    )
    link_sigma: float = param(
        0.05,
        unit="m",
        doc="no link between robots is trusted to better than this (and link_angle_sigma) in "
        "the joint graph: places are fused maps, a little bent",
        minimum=1e-4,
        maximum=10.0,
    )
    link_angle_sigma: float = param(
        0.01,
        unit="rad",
        doc="see link_sigma, for the rotation",
        minimum=1e-5,
        maximum=1.0,
    )
    link_robust_scale: float = param(
        1.0,
        unit="",
        doc="Dynamic Covariance Scaling parameter of the links in the joint graph (squared "
        "Mahalanobis units): a link whose error grows far beyond it is switched off",
        minimum=0.0,
        maximum=1000.0,
    )

    def __post_init__(self) -> None:
        validate(self)
