"""The verdicts of a joint merge update (:mod:`~multi_robot_mapper.core.merging.joint`): every
pair of maps' place links weighed into one consistent set and its evidence
(:func:`~multi_robot_mapper.core.merging.consistency.consistent_set`), within the update's
time.

A verdict costs a third of a second (its evidence searches the whole of both maps for rival
placements, :mod:`~multi_robot_mapper.core.evidence.placement`), and while the robots drive
every map changes between two updates: with 8 robots, 18 pairs to judge again, 6-10 s, each
update (issue 50). So:

- a pair whose maps and candidates are those it was judged on keeps its verdict, and a set
  judged before on the same maps keeps its evidence and its walls in free space (a pair whose
  new candidates left its consistent set as it was);
- with a ``deadline`` (the node's ``update_budget``), pairs are judged until it passes (at
  least one each update): pairs never judged first, then those judged longest ago. A pair
  left for a later update keeps the verdict it was last given, made on its maps of then, as
  long as every keyframe its set links still exists: the merger publishes nothing it had not
  published before, and decides on the new maps a few updates later. Without a deadline (a
  replay, a whole merge) every pair is judged on the maps of the update.
"""

from __future__ import annotations

import dataclasses
import time
from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.merging.config import MergeConfig
from multi_robot_mapper.core.merging.consistency import (
    Pair,
    PairVerdict,
    consistent_set,
    seen_through_near,
)
from multi_robot_mapper.core.merging.free_space import MapViews
from multi_robot_mapper.core.merging.pair_evidence import PairEvidence, pair_evidence
from multi_robot_mapper.core.merging.place_links import LinkCandidate
from multi_robot_mapper.core.merging.place_matching import (
    MatchKey,
    MatchRecord,
    Targets,
    cached,
    target_of,
)
from multi_robot_mapper.core.merging.places import MapUnit, UnitKey

FloatArray = NDArray[np.float64]


@dataclasses.dataclass
class Judged:
    """What one update's verdicts leave to the next."""

    # Each pair's verdict, keyed by what it was made from (the maps' content, the candidates,
    # the settings): most updates change few maps' candidates, and the other pairs keep theirs.
    by_key: dict[Any, PairVerdict] = dataclasses.field(default_factory=dict)
    # Each pair's newest verdict and the update that made it (the age of a pair left waiting).
    latest: dict[Pair, tuple[int, PairVerdict]] = dataclasses.field(default_factory=dict)
    # Each set's walls in free space and its evidence, per the maps' content and the set.
    seen: OrderedDict[Any, tuple[float, float]] = dataclasses.field(default_factory=OrderedDict)
    evidence: OrderedDict[Any, PairEvidence] = dataclasses.field(default_factory=OrderedDict)
    update: int = 0  # this update's number, from 0
    pending: int = 0  # pairs left to judge in a later update

    def successor(self) -> Judged:
        """An empty record for the next update, with the sets' caches kept."""
        return Judged(seen=self.seen, evidence=self.evidence, update=self.update + 1)


def judge_pairs(
    units: Mapping[UnitKey, MapUnit],
    records: Mapping[MatchKey, MatchRecord],
    config: MergeConfig,
    model: LogisticModel,
    targets: Targets,
    last: Judged | None,
    deadline: float | None = None,
) -> tuple[dict[Pair, PairVerdict], Judged]:
    """Every pair of maps' verdict (module doc) from the place matches' ``records``, and what
    this update leaves to the next; ``deadline``: the ``time.perf_counter()`` after which the
    pairs still to judge keep their last verdict (None: every pair judged)."""
    by_pair = candidates_by_pair(units, records)
    judged = last.successor() if last is not None else Judged()
    weigh = _Weigher(units, config, targets, judged)
    chosen: dict[Pair, PairVerdict] = {}
    waiting: list[tuple[Pair, Any, list[LinkCandidate]]] = []
    for pair, found in by_pair.items():
        identities = tuple(c.identity() for c in found)
        key = (pair, weigh.digests[pair[0]], weigh.digests[pair[1]], identities, config, model)
        verdict = last.by_key.get(key) if last is not None else None
        if verdict is None:
            waiting.append((pair, key, found))
        else:
            chosen[pair] = judged.by_key[key] = verdict
            judged.latest[pair] = (judged.update, verdict)
    before = last.latest if last is not None else {}
    # Pairs never judged first, then the longest since judged (a stable sort: in pair order).
    waiting.sort(key=lambda item: (item[0] in before, before.get(item[0], (0,))[0]))
    for turn, (pair, key, found) in enumerate(waiting):
        if turn and deadline is not None and time.perf_counter() >= deadline:
            judged.pending += 1
            stale = before.get(pair)
            if stale is not None and still_linked(stale[1], units):
                chosen[pair], judged.latest[pair] = stale[1], stale
            continue
        verdict = consistent_set(pair, found, units, config, weigh.seen, weigh.evidence, model)
        chosen[pair] = judged.by_key[key] = verdict
        judged.latest[pair] = (judged.update, verdict)
    return {pair: chosen[pair] for pair in by_pair if pair in chosen}, judged


def candidates_by_pair(
    units: Mapping[UnitKey, MapUnit], records: Mapping[MatchKey, MatchRecord]
) -> dict[Pair, list[LinkCandidate]]:
    """Each pair of maps' link candidates, those of keyframes that still exist."""
    by_pair: dict[Pair, list[LinkCandidate]] = {}
    for (source, _, target), record in records.items():
        if source not in units or target not in units:
            continue
        for candidate in record.candidates:
            if not (
                has_keyframe(units[source], candidate.centre)
                and has_keyframe(units[target], candidate.keyframe)
            ):
                continue
            pair = (min(source, target), max(source, target))
            by_pair.setdefault(pair, []).append(candidate)
    return by_pair


def still_linked(verdict: PairVerdict, units: Mapping[UnitKey, MapUnit]) -> bool:
    """Does every keyframe ``verdict``'s set links still exist (a verdict kept while its pair
    waits must not link a keyframe a map dropped)?"""
    return all(
        c.source in units
        and c.target in units
        and has_keyframe(units[c.source], c.centre)
        and has_keyframe(units[c.target], c.keyframe)
        for c in verdict.links
    )


def has_keyframe(unit: MapUnit, keyframe: int) -> bool:
    row = int(np.searchsorted(unit.index, keyframe))
    return row < len(unit.index) and int(unit.index[row]) == keyframe


class _Weigher:
    """A set's walls in free space and its evidence, for :func:`consistent_set`, each kept
    per the maps' content and the set (``judged.seen``, ``judged.evidence``)."""

    def __init__(
        self,
        units: Mapping[UnitKey, MapUnit],
        config: MergeConfig,
        targets: Targets,
        judged: Judged,
    ) -> None:
        self.units, self.config, self.targets, self.judged = units, config, targets, judged
        self.digests = {key: unit.content for key, unit in units.items()}

    def _set_key(self, links: Sequence[LinkCandidate]) -> tuple[Any, ...]:
        members = tuple(
            sorted((c.source, c.centre, c.target, c.keyframe, c.T_keyframe_centre) for c in links)
        )
        maps = tuple(sorted({c.source for c in links} | {c.target for c in links}))
        return (maps, tuple(self.digests[m] for m in maps), members, self.config)

    def _views(self, key: UnitKey) -> MapViews | None:
        return target_of(self.units[key], self.config, self.targets).views

    def seen(self, links: Sequence[LinkCandidate]) -> tuple[float, float]:
        def measure() -> tuple[float, float]:
            return seen_through_near(links, self.units, self._views, self.config)

        return cast(tuple[float, float], cached(self.judged.seen, self._set_key(links), measure))

    def evidence(self, links: Sequence[LinkCandidate], T_first_second: FloatArray) -> PairEvidence:
        maps = (min(links[0].source, links[0].target), max(links[0].source, links[0].target))
        key = (self._set_key(links), np.asarray(T_first_second).tobytes())

        def weigh() -> PairEvidence:
            found = {m: target_of(self.units[m], self.config, self.targets) for m in maps}
            return pair_evidence(maps, links, T_first_second, self.units, found, self.config)

        return cast(PairEvidence, cached(self.judged.evidence, key, weigh))
