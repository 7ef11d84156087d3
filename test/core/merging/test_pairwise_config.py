"""The whole-map merge's settings (core/merging/pairwise_config.py): every declared range is
enforced at construction, naming the parameter, its value and its range; the ends of each range
are accepted."""

from __future__ import annotations

import pytest

from multi_robot_mapper.core.config import ConfigError, field_specs
from multi_robot_mapper.core.merging.pairwise_config import PairwiseConfig

NUMBERS = [s for s in field_specs(PairwiseConfig) if s.kind in (int, float)]


def test_every_range_is_refused_just_outside_and_accepted_at_its_ends() -> None:
    assert NUMBERS and all(s.minimum is not None and s.maximum is not None for s in NUMBERS)
    for spec in NUMBERS:
        step = 1 if spec.kind is int else 1e-6 * max(1.0, abs(spec.maximum))  # type: ignore[arg-type]
        for outside in (spec.minimum - step, spec.maximum + step):  # type: ignore[operator]
            with pytest.raises(ConfigError, match=rf"'{spec.name}' = .* outside its range"):
                PairwiseConfig(**{spec.name: spec.kind(outside)})
        ends = [spec.maximum] if spec.exclusive_minimum else [spec.minimum, spec.maximum]
        for end in ends:
            assert getattr(PairwiseConfig(**{spec.name: spec.kind(end)}), spec.name) == end


def test_a_count_must_be_a_whole_number_and_a_fraction_at_most_one() -> None:
    with pytest.raises(ConfigError, match=r"'hypothesis_segments' must be int, got 2\.5"):
        PairwiseConfig(hypothesis_segments=2.5)
    with pytest.raises(
        ConfigError, match=r"'link_min_fraction' = 1\.5 is outside its range \[0, 1\]"
    ):
        PairwiseConfig(link_min_fraction=1.5)
    with pytest.raises(ConfigError, match=r"'link_min_value' is NaN"):
        PairwiseConfig(link_min_value=float("nan"))
