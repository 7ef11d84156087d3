"""Pipeline stage 4: odometry-free local mapping, one robot's scans in, its partial map out.

Modules, in the order a scan meets them: ``config`` (LocalMapperConfig), ``mapper`` (the front
end: match, confidence, integrate or start a new piece; LocalMapper; ``attempts``, its match
attempts; ``held``, the scans it could not place, until the next ones say whether they were
outliers or the robot is lost), ``keyframe_map``
(keyframes and the fused partial map they own), the back end: ``windows`` (keyframe windows
matched, what a closure records), ``joins`` (joins between pieces), ``loop_closer`` (local
edges, loop closures, one keyframe's whole step), ``backend`` (where it runs); the keyframe
graph itself is ``core.pose_graph`` (gtsam), shared with the merger.
"""

from multi_robot_mapper.core.local_mapping.config import LocalMapperConfig
from multi_robot_mapper.core.local_mapping.keyframe_map import Keyframe, KeyframeScan
from multi_robot_mapper.core.local_mapping.loop_closer import Closure
from multi_robot_mapper.core.local_mapping.mapper import LocalMapper, LocalUpdate

__all__ = ["Closure", "Keyframe", "KeyframeScan", "LocalMapper", "LocalMapperConfig", "LocalUpdate"]
