"""Pipeline stage 4: odometry-free local mapping, one robot's scans in, its partial map out.

Modules, in the order a scan meets them: ``config`` (LocalMapperConfig), ``mapper`` (the front
end: match, confidence, integrate or start a new piece; LocalMapper), ``keyframe_map``
(keyframes and the fused partial map they own), ``loop_closer`` (the back end: local edges,
loop closures, joins between pieces); the keyframe graph itself is ``core.pose_graph`` (gtsam),
shared with the merger.
"""

from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import Keyframe, KeyframeScan
from multi_robot_mapper.core.local_mapping.loop_closer import Closure
from multi_robot_mapper.core.local_mapping.mapper import LocalMapper, LocalUpdate

__all__ = ["Closure", "Keyframe", "KeyframeScan", "LocalMapper", "LocalMapperConfig", "LocalUpdate"]
