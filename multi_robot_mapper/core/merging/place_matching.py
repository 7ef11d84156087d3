"""Places searched on other maps, results kept from one update to the next: the link-making
stage of the joint merger (:mod:`~multi_robot_mapper.core.merging.joint`, step 2).

Each place of each map of every pair is searched on the other map
(:func:`~multi_robot_mapper.core.merging.place_links.match_place`). A place is matched again
only when its keyframes or segments changed, or the other map grew by ``reuse_*``; at most a
time budget per update, places never matched first (the rest waits for the next update).
Targets and places of the maps seen most recently are cached per map content.
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any, cast

from multi_robot_mapper.core.evidence.correlation import Drawing
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.free_space import ViewRows
from multi_robot_mapper.core.merging.pairwise import MapSignature, reuse_change
from multi_robot_mapper.core.merging.place_links import (
    LinkCandidate,
    Target,
    match_place,
    place_drawing,
)
from multi_robot_mapper.core.merging.places import (
    MapUnit,
    Place,
    PlaceIndex,
    UnitKey,
    places_of,
)

MatchKey = tuple[UnitKey, int, UnitKey]  # (source map, place centre keyframe, target map)
# A place match to make: (priority, 0 for the smaller map's places, the place's rank in its
# map, order queued, key, place)
Work = tuple[int, int, int, int, MatchKey, Place]


@dataclasses.dataclass(frozen=True)
class MatchRecord:
    """One place searched for on one map, and what the search was made on."""

    place: str  # the place's digest
    target: MapSignature  # the target map's
    candidates: list[LinkCandidate]


# Targets (a map transformed for the correlation) and places of the maps seen most recently
# are kept in the merge's state (``JointState.targets``, ``.places``): building them costs more
# than a place match, and a merger sees the same maps for many updates (one robot's map changes
# at a time). Keyed by map, content and settings; at most KEPT of each.
KEPT = 32


def cached(store: OrderedDict[Any, Any], key: Any, make: Callable[[], Any]) -> Any:
    """``store[key]``, made (and the oldest entry beyond :data:`KEPT` dropped) if absent."""
    found = store.get(key)
    if found is None:
        found = store[key] = make()
        if len(store) > KEPT:
            store.popitem(last=False)
    else:
        store.move_to_end(key)
    return found


class Targets(OrderedDict[tuple[UnitKey, str, MergeConfig], Target]):
    """Each map as a target per content and, in ``views``, every view of a map cast so far
    by its pose and the walls in its reach (:data:`free_space.ViewRows`): a map that grew at
    its end casts only the views near its end again."""

    def __init__(self) -> None:
        super().__init__()
        self.views: ViewRows = OrderedDict()


class Places(OrderedDict[tuple[UnitKey, str, MergeConfig], list[Place]]):
    """Each map's places per content and, in ``index``, every place by its exact inputs
    (:data:`places.PlaceIndex`): one map's change remakes only the places it touched."""

    def __init__(self) -> None:
        super().__init__()
        self.index: PlaceIndex = OrderedDict()


# Places kept by their inputs: 8 robots' maps of a few hundred places each, twice over.
KEPT_PLACES = 8192


def target_of(unit: MapUnit, config: MergeConfig, kept: Targets) -> Target:
    """``unit`` as a target of place matches, made once per content (``kept``)."""
    key = (unit.key, unit.segment_map.digest, config)
    return cast(Target, cached(kept, key, lambda: Target.of(unit, config, kept.views)))


def places_of_unit(unit: MapUnit, config: MergeConfig, kept: Places) -> list[Place]:
    """``unit``'s places, made once per content (``kept``); of a map that changed, the places
    whose inputs did not change are taken from ``kept.index`` (:func:`places.places_of`)."""
    key = (unit.key, unit.content, config)
    found = cached(kept, key, lambda: places_of(unit, config, kept.index))
    # The places used most recently: KEPT_PLACES of them, the longest unused dropped first.
    while len(kept.index) > KEPT_PLACES:
        kept.index.popitem(last=False)
    return cast(list[Place], found)


# --- links --------------------------------------------------------------------------------


def _directions(a: MapUnit, b: MapUnit) -> list[tuple[MapUnit, MapUnit]]:
    """(source, target) of a pair, both ways, the smaller map's places first. Where two maps
    overlap, the places that lie wholly inside the other map find it best: at the end of
    one robot's stretch its places reach past the other's map and score less there than on a
    look-alike corridor the other robot mapped whole (the demo's office: robot1's places
    ranked the right placement 5th to 15th on robot2's map, robot2's places ranked it 0th to
    2nd on robot1's). Searching one way only left such pairs unmerged."""
    first = (a, b) if (a.length, a.key) <= (b.length, b.key) else (b, a)
    return [first, (first[1], first[0])]


def match_places(
    units: Mapping[UnitKey, MapUnit],
    config: MergeConfig,
    old: Mapping[MatchKey, MatchRecord],
    budget: float | None,
    kept: tuple[Targets, Places],
) -> tuple[dict[MatchKey, MatchRecord], dict[str, int]]:
    """Every place of each map of every pair searched on the other map: results kept while
    the place and the target map are unchanged, the rest matched within ``budget`` seconds,
    places never matched first, then changed places, then places of grown targets; the
    smaller maps' places before the larger maps', each pair's k-th place before any pair's
    (k+1)-th. Targets and places are made once per content (``kept``: the merge state's)."""
    keys = sorted(k for k, u in units.items() if u.length >= config.place_min_length)
    targets, kept_places = kept
    places = {key: places_of_unit(units[key], config, kept_places) for key in keys}
    signatures = {key: MapSignature.of(units[key].segment_map) for key in keys}
    records: dict[MatchKey, MatchRecord] = {}
    work: list[Work] = []
    for i, a in enumerate(keys):
        for b in keys[i + 1 :]:
            for way, (source, target) in enumerate(_directions(units[a], units[b])):
                _plan_matches(
                    places[source.key],
                    source.key,
                    target.key,
                    way,
                    old,
                    signatures[target.key],
                    records,
                    work,
                    reuse_change(config),
                )
    work.sort(key=lambda item: item[:4])
    started = time.perf_counter()
    computed = 0
    drawings: dict[str, Drawing] = {}
    for *_, key, place in work:
        elapsed = time.perf_counter() - started
        if budget and computed and elapsed * (computed + 1) / computed > budget:
            # The next match would end past the budget (at this update's mean time per
            # match); one match at least, so that every update makes progress.
            break
        drawing = drawings.get(place.digest)
        if drawing is None:
            drawing = drawings[place.digest] = place_drawing(
                place, config.free_drawing(), config.place_radius
            )
        found = match_place(place, target_of(units[key[2]], config, targets), config, drawing)
        records[key] = MatchRecord(place.digest, signatures[key[2]], found)
        computed += 1
    counts = {
        "maps": len(units),
        "places": sum(len(p) for p in places.values()),
        "place_matches": len({w[4] for w in work} | set(records)),
        "matches_computed": computed,
        "matches_pending": len(work) - computed,
    }
    return records, counts


def _plan_matches(
    places: Sequence[Place],
    source: UnitKey,
    target: UnitKey,
    way: int,
    old: Mapping[MatchKey, MatchRecord],
    signature: MapSignature,
    records: dict[MatchKey, MatchRecord],
    work: list[Work],
    change: tuple[float, float],
) -> None:
    """Each place of ``source`` on ``target``: its record kept in ``records`` when still
    fresh, else queued in ``work`` (and its old record kept until it is matched again;
    ``change``: how much the target may change, :func:`~core.merging.pairwise.reuse_change`)."""
    for rank, place in enumerate(places):
        key = (source, place.centre, target)
        record = old.get(key)
        if record is None:
            priority = 0
        elif record.place != place.digest:
            priority = 1
        elif not signature.close_to(record.target, change):
            priority = 2
        else:
            records[key] = record  # fresh
            continue
        if record is not None:
            records[key] = record  # kept until matched again
        work.append((priority, way, rank, len(work), key, place))
