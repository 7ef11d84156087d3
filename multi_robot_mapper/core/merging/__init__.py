"""Map merging: partial maps of robots that never met, in one global ``map`` frame.

Amigoni, Gasparini & Gini 2006, Sec. IV merge an *ordered* sequence of partial maps by
repeated INTEGRATE: sequentially (IV-A), as a tree (IV-B) or with the pivot method (IV-C,
Algorithm 6). :func:`merge_sequential`, :func:`merge_tree` and :func:`merge_pivot` implement
the three over an ordered list, for comparison on a known order; the pivot method uses the
cleaner variant the paper recommends (fuse ``S_1..i-1`` with ``S_i`` moved by the composed
``t_1,i``, not with ``S_i-1,i``).

Robots do not come in an order, and the order is what the paper leaves as future work.
:func:`merge` is the pivot idea without it: INTEGRATE every pair of partial maps, keep the
pairs whose best transformation passes the validity threshold (*links*), take the
maximum-value spanning tree of the links and place every robot frame by composing the links'
transforms along the tree from a reference robot (the pivots are the tree's edges). A robot
with no valid link to the reference stays unmerged (``None``): a wrong placement is worse than
none. ``merge(..., previous=result)`` re-runs cheaply as the maps grow: a pair whose two maps
barely changed keeps its earlier result, and the previous tree is kept unless a clearly
better link appears.

Segment overlap alone cannot tell two look-alike places apart (a grid of equal rooms, a ring
of equal corridors, two rectilinear buildings drawn on the same grid): a wrong link can score
as high as the true one. Free space separates them: given each robot's keyframe poses
(``viewpoints``, on the wire with every partial map), :class:`MapViews` ray casts the robot's
own map from where its laser stood, and a link is refused when the other map's walls lie in
that free space (:func:`free_space_conflict`), both for the pair alone and, when two groups of
already linked robots join in the spanning tree, against every viewpoint of the other group
(:func:`free_space_join`).

Frames: each robot's partial map is in its own map frame ``robot``; ``T_map_robot`` places it
in the global ``map`` frame, which is the reference robot's map frame. Poses are ``(x, y,
theta)`` triples (metres, radians), matrices ``T_a_b`` map frame-b coordinates into frame

Modules: ``config`` (MergeConfig), ``correlation`` (every placement of one map on another),
``free_space`` (what a robot saw), ``pairwise`` (one pair of maps), ``link_graph`` (every
pair, the spanning tree, placement: :func:`merge`), ``compose`` (the fused global map),
``ordered`` (the paper's three methods on a known order), ``joint`` (method ``pivot``), ``ffs``
(Force Field Simulation; ``ffs.method`` is method ``ffs``: FFS after ``joint``), ``methods``
(the registry of both).
"""

from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import (
    MapViews,
    free_space_conflict,
    seen_through_length,
)
from multi_robot_mapper.core.merging.link_graph import MergeResult, merge, spanning_tree
from multi_robot_mapper.core.merging.ordered import (
    OrderedMerge,
    merge_pivot,
    merge_sequential,
    merge_tree,
)
from multi_robot_mapper.core.merging.pairwise import Link, MapMatch, longest, match_maps

__all__ = [
    "Link",
    "MapMatch",
    "MapViews",
    "MergeConfig",
    "MergeResult",
    "OrderedMerge",
    "free_space_conflict",
    "longest",
    "match_maps",
    "merge",
    "merge_pivot",
    "merge_sequential",
    "merge_tree",
    "seen_through_length",
    "spanning_tree",
]
