"""Fusion of two segment sets that are already aligned (Amigoni Alg. 5, greedy version).

Matching segments of S1 and S2 form *matching chains*: the connected components of the graph
whose edges are the pairs with a positive matching value (Alg. 4 l. 24-30). Each chain is
replaced by one polyline that stays within FUSIONTOLERANCE of every segment in it; unmatched
segments are kept as they are (Alg. 5 l. 2). The result has no duplicate walls, so a partial
map grows with the area seen, not with the number of scans.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from multi_robot_mapper.core.geometry import lines_of
from multi_robot_mapper.core.matching.scoring import PairTolerance, score_pairs

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]

MIN_PIECE_M = 1e-3  # polyline pieces shorter than this are dropped (duplicate vertices)


def pair_distance(segments1: FloatArray, segments2: FloatArray) -> FloatArray:
    """Amigoni's d(s1, s2) for row-aligned pairs: the smaller of the two one-sided distances,
    each the larger distance of one segment's end points to the other's supporting line."""
    lines1, lines2 = lines_of(segments1), lines_of(segments2)

    def to_line(lines_dir: FloatArray, offset: FloatArray, points: FloatArray) -> FloatArray:
        return np.asarray(
            np.abs(-lines_dir[:, 1] * points[:, 0] + lines_dir[:, 0] * points[:, 1] - offset)
        )

    d2_on_1 = np.maximum(
        to_line(lines1.direction, lines1.normal_offset, segments2[:, :2]),
        to_line(lines1.direction, lines1.normal_offset, segments2[:, 2:]),
    )
    d1_on_2 = np.maximum(
        to_line(lines2.direction, lines2.normal_offset, segments1[:, :2]),
        to_line(lines2.direction, lines2.normal_offset, segments1[:, 2:]),
    )
    return np.asarray(np.minimum(d2_on_1, d1_on_2))


def matching_chains(
    segments1: FloatArray,
    segments2: FloatArray,
    pairs: PairTolerance,
    max_distance: float,
) -> tuple[IntArray, IntArray, int]:
    """Chain label of every S1 and every S2 segment (-1 = unmatched), and the chain count.

    Pairs are the matching pairs of Alg. 4 under the identity (S2 already moved), kept only
    when d(s1, s2) <= ``max_distance``: the evaluation's SEGMENTDISTANCETHRESHOLD is generous
    on purpose, fusion must not merge a wall with the cupboard in front of it.
    """
    n1, n2 = len(segments1), len(segments2)
    none1, none2 = np.full(n1, -1, dtype=np.int64), np.full(n2, -1, dtype=np.int64)
    if n1 == 0 or n2 == 0:
        return none1, none2, 0
    scores = score_pairs(segments1, segments2, np.zeros((1, 3)), pairs)
    a, b = scores.first, scores.second
    close = pair_distance(segments1[a], segments2[b]) <= max_distance
    a, b = a[close], b[close]
    if a.size == 0:
        return none1, none2, 0
    # Bipartite graph on n1 + n2 nodes; chains = its connected components (Alg. 4 l. 24-30).
    graph = coo_matrix((np.ones(a.size), (a, n1 + b)), shape=(n1 + n2, n1 + n2))
    _, label = connected_components(graph, directed=False)
    matched = np.zeros(n1 + n2, dtype=bool)
    matched[a] = True
    matched[n1 + b] = True
    # Renumber the components that contain a pair 0..k-1; single segments get -1.
    used, chain = np.unique(label[matched], return_inverse=True)
    out = np.full(n1 + n2, -1, dtype=np.int64)
    out[matched] = chain
    return out[:n1], out[n1:], len(used)


def chain_polyline(members: FloatArray, tolerance: float) -> FloatArray:
    """The greedy polyline of one matching chain (Alg. 5 l. 4-11), as (K, 4) pieces.

    P0 joins the two farthest end points of the chain (l. 4). Then, each segment considered
    once (the greedy version): the segment farthest from the current polyline replaces the
    part of the polyline it spans, joined to the rest at its end points (l. 9), until the
    farthest one is within ``tolerance`` (l. 7).
    """
    ends = members.reshape(-1, 2)
    # The common case first: every member within tolerance of one total-least-squares line
    # (the same wall seen twice) becomes that line over the members' whole extent, instead of
    # following whichever member the greedy pass inserts last.
    centre = ends.mean(axis=0)
    _, _, vt = np.linalg.svd(ends - centre, full_matrices=False)
    direction, normal = vt[0], vt[1]
    if float(np.abs((ends - centre) @ normal).max()) <= tolerance:
        t = (ends - centre) @ direction
        return np.concatenate((centre + t.min() * direction, centre + t.max() * direction))[None]
    gap = ends[:, None, :] - ends[None, :, :]
    i, j = np.unravel_index(int(np.argmax(np.einsum("ijk,ijk->ij", gap, gap))), gap.shape[:2])
    origin, far = ends[i], ends[j]
    axis = (far - origin) / max(float(np.hypot(*(far - origin))), 1e-12)

    def along(points: FloatArray) -> FloatArray:
        return np.asarray((points - origin) @ axis)

    vertices = np.vstack((origin, far))
    considered = np.zeros(len(members), dtype=bool)
    while not considered.all():
        distance = _distance_to_polyline(members, vertices)
        distance[considered] = -1.0
        worst = int(np.argmax(distance))
        if distance[worst] <= tolerance:
            break
        considered[worst] = True
        piece = members[worst].reshape(2, 2)
        t_piece = along(piece)
        t_vertices = along(vertices)
        keep = (t_vertices < t_piece.min()) | (t_vertices > t_piece.max())
        vertices = np.vstack((vertices[keep], piece))
        vertices = vertices[np.argsort(along(vertices), kind="stable")]
    vertices = _simplified(vertices, tolerance)
    pieces = np.hstack((vertices[:-1], vertices[1:]))
    length = np.hypot(pieces[:, 2] - pieces[:, 0], pieces[:, 3] - pieces[:, 1])
    return np.asarray(pieces[length >= MIN_PIECE_M])


def _covered(segments: FloatArray, reference: FloatArray, distance: float) -> BoolArray:
    """Segments whose two end points both lie within ``distance`` of one reference segment."""
    if len(segments) == 0 or len(reference) == 0:
        return np.zeros(len(segments), dtype=bool)
    a, b = reference[None, :, :2], reference[None, :, 2:]
    ab = b - a
    span = np.maximum(np.einsum("ijk,ijk->ij", ab, ab), 1e-18)
    near = np.ones((len(segments), len(reference)), dtype=bool)
    for end in (segments[:, None, :2], segments[:, None, 2:]):
        t = np.clip(np.einsum("ijk,ijk->ij", end - a, ab) / span, 0.0, 1.0)
        gap = end - (a + t[..., None] * ab)
        near &= np.hypot(gap[..., 0], gap[..., 1]) <= distance
    return np.asarray(near.any(axis=1))


def _simplified(vertices: FloatArray, tolerance: float) -> FloatArray:
    """Douglas-Peucker on the polyline's vertices: the greedy insertion joins each inserted
    segment to its neighbours, which leaves centimetre zig-zags across a wall seen with
    noise; vertices within ``tolerance`` of the chord are dropped (the polyline moves by at
    most ``tolerance``)."""
    keep = np.zeros(len(vertices), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(vertices) - 1)]
    while stack:
        first, last = stack.pop()
        if last - first < 2:
            continue
        chord = vertices[last] - vertices[first]
        span = max(float(np.hypot(*chord)), 1e-12)
        inner = vertices[first + 1 : last] - vertices[first]
        distance = np.abs(inner[:, 0] * chord[1] - inner[:, 1] * chord[0]) / span
        worst = int(np.argmax(distance))
        if distance[worst] > tolerance:
            keep[first + 1 + worst] = True
            stack.extend(((first, first + 1 + worst), (first + 1 + worst, last)))
    return np.asarray(vertices[keep])


def _roughly_straight(members: FloatArray, max_angle: float = np.radians(30.0)) -> bool:
    """Every member within ``max_angle`` of the axis through the chain's farthest end points."""
    ends = members.reshape(-1, 2)
    gap = ends[:, None, :] - ends[None, :, :]
    i, j = np.unravel_index(int(np.argmax(np.einsum("ijk,ijk->ij", gap, gap))), gap.shape[:2])
    axis = ends[j] - ends[i]
    axis = axis / max(float(np.hypot(*axis)), 1e-12)
    d = members[:, 2:] - members[:, :2]
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    return bool((np.abs(d @ axis) / length >= np.cos(max_angle)).all())


def _distance_to_polyline(segments: FloatArray, vertices: FloatArray) -> FloatArray:
    """For each segment, the larger distance of its two end points to the polyline."""
    points = segments.reshape(-1, 2)
    a, b = vertices[:-1], vertices[1:]
    ab = b - a
    span = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    t = np.clip(np.einsum("pij,ij->pi", points[:, None, :] - a[None], ab) / span, 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    d = np.hypot(*(points[:, None, :] - nearest).transpose(2, 0, 1)).min(axis=1)
    return np.asarray(d.reshape(-1, 2).max(axis=1))


def fuse(
    segments1: FloatArray,
    owner1: IntArray,
    segments2: FloatArray,
    owner2: IntArray,
    pairs: PairTolerance,
    tolerance: float,
    max_distance: float | None = None,
) -> tuple[FloatArray, IntArray]:
    """S_{1,2}: S1 fused with S2 (already in S1's frame), Alg. 5.

    ``owner1`` and ``owner2`` label every segment (a keyframe, a robot); a polyline belongs to
    the smallest owner among its S1 members (every chain has one: its pairs join S1 to S2),
    so the part of the map that existed first keeps it. Pairs farther apart than
    ``max_distance`` (default three tolerances) are not fused. Returns segments and owners.
    """
    limit = 3.0 * tolerance if max_distance is None else max_distance
    chain1, chain2, count = matching_chains(segments1, segments2, pairs, limit)
    # An unmatched S2 piece lying along S1 within the fusion distance adds nothing (a corner
    # sliver or a short piece the matching value ignores); keeping it would grow the map with
    # every keyframe of the same place.
    fresh = (chain2 < 0) & ~_covered(segments2, segments1, limit)
    parts = [segments1[chain1 < 0], segments2[fresh]]
    owners = [owner1[chain1 < 0], owner2[fresh]]
    if count == 0:
        return np.vstack(parts).reshape(-1, 4), np.concatenate(owners).astype(np.int64)
    in1, in2 = np.flatnonzero(chain1 >= 0), np.flatnonzero(chain2 >= 0)
    members = np.vstack((segments1[in1], segments2[in2]))
    label = np.concatenate((chain1[in1], chain2[in2]))
    owner = np.full(count, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(owner, chain1[in1], owner1[in1])
    lines, straight = _chain_lines(members, label, count, tolerance)
    for chain in range(count):
        if straight[chain]:
            parts.append(lines[chain : chain + 1])
            owners.append(owner[chain : chain + 1])
            continue
        first = segments1[chain1 == chain]
        second = segments2[chain2 == chain]
        chain_members = np.vstack((first, second))
        if not _roughly_straight(chain_members):
            # A long curved wall chains into a shape the projection in chain_polyline cannot
            # order; leave its pieces as they are rather than draw chords through the room.
            parts.extend((first, second))
            owners.extend((owner1[chain1 == chain], owner2[chain2 == chain]))
            continue
        polyline = chain_polyline(chain_members, tolerance)
        parts.append(polyline)
        owners.append(np.full(len(polyline), owner[chain], dtype=np.int64))
    return np.vstack(parts).reshape(-1, 4), np.concatenate(owners).astype(np.int64)


def _chain_lines(
    members: FloatArray, label: IntArray, count: int, tolerance: float
) -> tuple[FloatArray, BoolArray]:
    """The common case of :func:`chain_polyline` for every chain at once: the chain's
    total-least-squares line over its members' extent, and whether the chain is that case
    (every end point within ``tolerance`` of the line, every member within 30 degrees of it:
    :func:`_roughly_straight` along that line). Most chains are one wall seen twice; the
    rest go through the greedy polyline one by one."""
    ends = members.reshape(-1, 2)
    of_end = np.repeat(label, 2)
    size = np.bincount(of_end, minlength=count).astype(np.float64)
    centre = np.stack(
        [np.bincount(of_end, ends[:, k], minlength=count) / size for k in range(2)], axis=1
    )
    offset = ends - centre[of_end]
    sxx = np.bincount(of_end, offset[:, 0] ** 2, minlength=count)
    syy = np.bincount(of_end, offset[:, 1] ** 2, minlength=count)
    sxy = np.bincount(of_end, offset[:, 0] * offset[:, 1], minlength=count)
    heading = 0.5 * np.arctan2(2.0 * sxy, sxx - syy)  # the scatter's principal axis
    direction = np.stack((np.cos(heading), np.sin(heading)), axis=1)
    normal = np.stack((-direction[:, 1], direction[:, 0]), axis=1)
    across = np.abs(np.einsum("ij,ij->i", offset, normal[of_end]))
    worst = np.zeros(count)
    np.maximum.at(worst, of_end, across)
    along = np.einsum("ij,ij->i", offset, direction[of_end])
    low, high = np.full(count, np.inf), np.full(count, -np.inf)
    np.minimum.at(low, of_end, along)
    np.maximum.at(high, of_end, along)
    d = members[:, 2:] - members[:, :2]
    length = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-12)
    aligned = np.abs(np.einsum("ij,ij->i", d, direction[label])) / length >= np.cos(
        np.radians(30.0)
    )
    every_aligned = np.bincount(label, ~aligned, minlength=count) == 0
    lines = np.hstack((centre + low[:, None] * direction, centre + high[:, None] * direction))
    return lines, (worst <= tolerance) & every_aligned
