"""Odometry-free local mapping: one robot's scans in, its segment partial map out.

Frames: ``robotmap`` is the robot's own map frame (the laser frame of its first accepted
scan); ``T_robotmap_laser`` places a scan in it. Each new scan is matched by INTEGRATE against
the partial map near the robot's last pose, with the constant-velocity prediction as one more
hypothesis (never a requirement). A scan the last scan cannot place is searched on the partial
map around the last pose, within reach of it. A scan whose best transformation fails the
validity threshold is set aside and counted: a wrong integration is worse than a missing one.
Scans that moved more than ``keyframe_distance`` or turned more than ``keyframe_angle`` since the
last keyframe become keyframes and are fused into the partial map (Amigoni Alg. 5).

Modules: ``config`` (LocalMapperConfig), ``mapper`` (LocalMapper: scans -> keyframes).
"""

from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.mapper import Keyframe, LocalMapper, LocalUpdate

__all__ = ["Keyframe", "LocalMapper", "LocalMapperConfig", "LocalUpdate"]
