"""Generated buildings for the simulator (``mrm simulate --world generated --seed N``).

:func:`generate_building` draws a floor plan from a seed: its kind (:data:`PLAN_KINDS`: rows
of equal rooms, mirror- and rotation-symmetric wings, long bare corridors, pillared halls, and
mixes of them) and its size (20-200 m, the plan's largest extent), unless given. The result,
a :class:`Building`, holds the walls a laser sees, the glass panes that stop its beam without
a return, optional furniture and walking people (:class:`~core.simulation.Clutter`), and the
waypoint graph robots drive on: every edge keeps :data:`CLEARANCE_M` from every wall, pane and
piece of furniture, and every waypoint is reachable from every other. The same arguments
always give the same building, bit for bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from multi_robot_mapper.core.building_kinds import PLAN_KINDS
from multi_robot_mapper.core.floor_plans import (
    HALL,
    NODE_KINDS,
    ROOM,
    SPACE_KINDS,
    walls_and_glass,
    waypoint_graph,
)
from multi_robot_mapper.core.segment_grid import clearances
from multi_robot_mapper.core.simulation import Clutter, furniture_piece

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

MIN_SIZE_M, MAX_SIZE_M = 20.0, 200.0  # a plan's largest extent
CLEARANCE_M = 0.3  # every waypoint edge keeps this far from walls, glass and furniture
MAX_PEOPLE = 1000
MAX_CLUTTER = 2.0  # objects per square metre, as clutter_for
# Furniture is placed this far from every wall (its reach: a table's corner leg is 0.75 m
# from where it stands), and its reach plus CLEARANCE_M from every waypoint edge.
_FURNITURE_REACH_M = 0.8
_PERSON_WALK_M = (2.0, 6.0)  # a person walks to and fro along this much of a waypoint edge
# Independent random streams of a seed (robot k's laser noise uses spawn key k).
_DRAWS, _PLAN, _FURNITURE, _PEOPLE = 3000, 3001, 3002, 3003

__all__ = [
    "MAX_SIZE_M",
    "MIN_SIZE_M",
    "NODE_KINDS",
    "PLAN_KINDS",
    "SPACE_KINDS",
    "Building",
    "generate_building",
]


@dataclasses.dataclass(frozen=True)
class Building:
    """A generated floor plan in the ``world`` frame (metres)."""

    seed: int
    kind: str  # one of PLAN_KINDS
    size: float  # m, the size it was drawn at: the walls' largest extent (to rounding)
    # "mirror" (its own mirror image about the y axis), "rotation_180" or "rotation_90"
    # (its own copy turned about the origin), or "none"; walls and glass both have it.
    symmetry: str
    walls: FloatArray  # (W, 4) segments that return a beam: walls, pillars, cabinets
    glass: FloatArray  # (G, 4) panes that stop a beam and return nothing
    clutter: Clutter  # furniture (returns, stays put) and people walking to and fro
    nodes: FloatArray  # (N, 2) waypoints
    node_kinds: IntArray  # (N,) index into NODE_KINDS: room, door, corridor, hall
    edges: IntArray  # (E, 2) waypoint pairs, each a straight leg a robot can drive
    spaces: FloatArray  # (S, 4) x0, y0, x1, y1 of each room, corridor and hall
    space_kinds: IntArray  # (S,) index into SPACE_KINDS

    @property
    def obstacles(self) -> FloatArray:
        """Everything a robot must keep clear of: walls, glass and furniture ``(M, 4)``."""
        return np.vstack((self.walls, self.glass, self.clutter.static))

    @property
    def edge_segments(self) -> FloatArray:
        """The waypoint edges as segments ``(E, 4)``."""
        return np.hstack((self.nodes[self.edges[:, 0]], self.nodes[self.edges[:, 1]]))


def generate_building(
    seed: int,
    kind: str | None = None,
    size: float | None = None,
    glass: bool = False,
    clutter: float = 0.0,
    people: int = 0,
) -> Building:
    """The building of ``seed``.

    ``kind``: one of :data:`PLAN_KINDS` (default: drawn from the seed, each equally likely).
    ``size``: the plan's largest extent, m (default: drawn from the seed, log-uniform in
    20-200 m). ``glass``: glass fronts and back windows on some rooms and a glass stretch
    of an outer wall (walls there without it: the plan is the same). ``clutter``: pieces of
    furniture (chairs, tables, round pillars) per square metre of room and hall floor, kept
    off the robots' lanes. ``people``: people walking to and fro along waypoint edges. A
    kind or size given by hand leaves the rest of the draw unchanged.
    """
    _check(seed, kind, size, clutter, people)
    draws = _stream(seed, _DRAWS)
    names = list(PLAN_KINDS)
    drawn_kind = names[int(draws.integers(len(names)))]
    drawn_size = float(np.exp(draws.uniform(np.log(MIN_SIZE_M), np.log(MAX_SIZE_M))))
    kind = drawn_kind if kind is None else kind
    target = drawn_size if size is None else float(size)
    plan, symmetry = PLAN_KINDS[kind](_stream(seed, _PLAN), target)
    if not glass:  # walls where the panes would be
        plan = dataclasses.replace(plan, glass=np.zeros((0, 4)))
    walls, panes = walls_and_glass(plan)
    nodes, node_kinds, edges = waypoint_graph(plan)
    edge_segments = np.hstack((nodes[edges[:, 0]], nodes[edges[:, 1]]))
    clear = clearances(edge_segments, np.vstack((walls, panes)), CLEARANCE_M) >= CLEARANCE_M
    edges, edge_segments = edges[clear], edge_segments[clear]  # e.g. hall links past a pillar
    parts, _ = connected_components(_adjacency(len(nodes), edges), directed=False)
    if parts != 1:  # a fault in a plan builder, never in the caller's arguments
        raise RuntimeError(
            f"generated {kind} plan (seed {seed}, {target:.1f} m) falls into {parts} parts"
        )
    rooms = plan.rects[(plan.kinds == ROOM) | (plan.kinds == HALL)]
    static = _furniture(_stream(seed, _FURNITURE), rooms, clutter, walls, panes, edge_segments)
    walkers = _walkers(_stream(seed, _PEOPLE), edge_segments, people)
    return Building(
        seed=seed,
        kind=kind,
        size=target,
        symmetry=symmetry,
        walls=walls,
        glass=panes,
        clutter=Clutter(static, walkers),
        nodes=nodes,
        node_kinds=node_kinds,
        edges=edges,
        spaces=plan.rects,
        space_kinds=plan.kinds,
    )


def _check(seed: int, kind: str | None, size: float | None, clutter: float, people: int) -> None:
    if not 0 <= seed < 2**63:
        raise ValueError(f"seed must be a non-negative integer, got {seed}")
    if kind is not None and kind not in PLAN_KINDS:
        raise ValueError(f"unknown plan kind {kind!r}; known: {', '.join(PLAN_KINDS)}")
    if size is not None and not MIN_SIZE_M <= size <= MAX_SIZE_M:
        raise ValueError(f"size must be in [{MIN_SIZE_M:g}, {MAX_SIZE_M:g}] m, got {size}")
    if not 0.0 <= clutter <= MAX_CLUTTER:
        raise ValueError(f"clutter must be in [0, {MAX_CLUTTER:g}] objects per m^2, got {clutter}")
    if not 0 <= people <= MAX_PEOPLE:
        raise ValueError(f"people must be in [0, {MAX_PEOPLE}], got {people}")


def _stream(seed: int, key: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(key,)))


def _adjacency(count: int, edges: IntArray) -> coo_matrix:
    ones = np.ones(len(edges))
    return coo_matrix((ones, (edges[:, 0], edges[:, 1])), shape=(count, count))


def _furniture(
    rng: np.random.Generator,
    rooms: FloatArray,
    density: float,
    walls: FloatArray,
    panes: FloatArray,
    lanes: FloatArray,
) -> FloatArray:
    """``density`` pieces per square metre of ``rooms`` (and halls), placed at random where
    they cross no wall and keep CLEARANCE_M from every lane; a piece that finds no such place
    in a few tries is left out."""
    area = (rooms[:, 2] - rooms[:, 0]) * (rooms[:, 3] - rooms[:, 1])
    wanted = round(density * float(area.sum())) if len(rooms) else 0
    if wanted == 0:
        return np.zeros((0, 4))
    tries = 8 * wanted
    which = rng.choice(len(rooms), size=tries, p=area / area.sum())
    where = rooms[which, :2] + rng.random((tries, 2)) * (rooms[which, 2:] - rooms[which, :2])
    spots = np.hstack((where, where))  # points as segments of no length
    reach = _FURNITURE_REACH_M
    near_wall = clearances(spots, np.vstack((walls, panes)), reach) < np.inf
    near_lane = clearances(spots, lanes, reach + CLEARANCE_M) < np.inf
    chosen = where[~near_wall & ~near_lane][:wanted]
    pieces = [furniture_piece(rng, float(x), float(y)) for x, y in chosen]
    return np.vstack(pieces) if pieces else np.zeros((0, 4))


def _walkers(rng: np.random.Generator, lanes: FloatArray, people: int) -> FloatArray:
    """Lines ``(people, 4)`` people walk to and fro along: a stretch of a random waypoint edge
    at least 1 m long (a longer edge is likelier), where robots drive too."""
    length = np.hypot(lanes[:, 2] - lanes[:, 0], lanes[:, 3] - lanes[:, 1])
    usable = np.flatnonzero(length >= 1.0)
    if people == 0 or usable.size == 0:
        return np.zeros((0, 4))
    edge = rng.choice(usable, size=people, p=length[usable] / length[usable].sum())
    walk = np.minimum(length[edge], rng.uniform(*_PERSON_WALK_M, size=people))
    start = rng.random(people) * (length[edge] - walk)
    a, b = lanes[edge, :2], lanes[edge, 2:]
    unit = (b - a) / length[edge, None]
    first = a + start[:, None] * unit
    return np.hstack((first, first + walk[:, None] * unit))
