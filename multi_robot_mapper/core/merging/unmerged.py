"""Why a robot is not placed in ``map``: said in a line for ``robots.json`` and
``/diagnostics`` (issue 46: "unmerged: <why>")."""

from __future__ import annotations

from collections.abc import Mapping

from multi_robot_mapper.core.merging.consistency import Accepted, PairVerdict
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey, unit_name


def unmerged_reason(
    robot: str,
    units: Mapping[UnitKey, MapUnit],
    verdicts: Mapping[tuple[UnitKey, UnitKey], PairVerdict],
    accepted: Accepted,
    chains: Mapping[UnitKey, float],
    ref_unit: UnitKey | None,
    join_probability: float,
) -> str:
    """The most telling reason the robot's map frame is not placed: its placement's
    probability below ``join_probability``, a join refused, the most probable placement
    with another robot and why it fell short, a group of its own, or no match at all."""
    main = (robot, 0)
    if main not in units:
        return "no map yet" if not any(k[0] == robot for k in units) else "its map frame is empty"
    if ref_unit is None:
        return "no robot is placed yet"
    if main in chains:
        return (
            f"placement probability {chains[main]:.3f} below join_probability "
            f"{join_probability:g} (its paths of joins to {ref_unit[0]})"
        )
    group = next((g for g in accepted.groups if main in g), [main])
    others = sorted({key[0] for key in group} - {robot})
    if others:
        return (
            f"joined to {', '.join(others)}, a group with no join to the reference {ref_unit[0]}'s"
        )
    refused = [v for v in accepted.refused if main in v.pair and _across(v)]
    if refused:
        best = max(refused, key=lambda v: v.probability)
        return f"with {_other(best, main)}: {best.reason}"
    weighed = [v for v in verdicts.values() if main in v.pair and _across(v) and v.links]
    if weighed:
        best = max(weighed, key=lambda v: v.probability)
        return f"with {_other(best, main)}: {best.reason}"
    return "no place of its map matches another robot's map"


def _across(verdict: PairVerdict) -> bool:
    return verdict.pair[0][0] != verdict.pair[1][0]


def _other(verdict: PairVerdict, mine: UnitKey) -> str:
    a, b = verdict.pair
    return unit_name(b if a == mine else a)
