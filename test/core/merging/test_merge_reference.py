"""Which map is ``map``: the reference of a merge (``core/merging/joint.py``, ``_reference``)."""

from __future__ import annotations

import dataclasses

import numpy as np
from test_joint import drives, stranger_keyframes

from multi_robot_mapper.core.merging import MergeConfig
from multi_robot_mapper.core.merging.joint import merge_joint


def test_a_lone_robot_lost_early_has_its_longest_piece_as_map() -> None:
    # One robot lost after three keyframes maps the rest of its run in a second piece that
    # nothing joins to the first (another building here). ``map`` is that longest piece, as
    # the robot's main piece is (the dense intel bag alone: piece 0 was ``map`` and the main
    # piece, unjoined, was reported "not placed").
    short = stranger_keyframes()[:3]
    _, office = drives("office", 1)
    start = len(short)
    long = [
        dataclasses.replace(kf, index=start + k, stamp=100.0 + k, piece=start)
        for k, kf in enumerate(office[0])
    ]
    result = merge_joint({"r1": [*short, *long]}, MergeConfig(), budget=0.0)
    assert result.reference == "r1"
    pieces = result.frames["r1"]
    assert pieces.get(start) is not None
    assert np.allclose(pieces[start], (0.0, 0.0, 0.0), atol=1e-9)
    assert pieces.get(0) is None
