"""Confidence in context: a context's prior shifts the odds (Bayes' rule), monotone in the
evidence."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from test_fitted_models import shipped

from multi_robot_mapper.core.local_mapping import (
    attempts,
)


@pytest.mark.parametrize("context", attempts.CONTEXTS)
def test_a_context_shifts_the_odds_by_its_prior(context: str) -> None:
    # Bayes' rule: a context whose matches are right four times as often at the same evidence
    # multiplies the odds by 4 (intercept log 4, slope 1); no shift keeps the confidence.
    prior = {context: attempts.ContextCalibration(1.0, float(np.log(4.0)))}
    assert attempts.in_context(0.5, context, prior) == pytest.approx(0.8)
    assert attempts.in_context(0.2, context, prior) == pytest.approx(0.5)  # odds 1/4 -> 1
    unshifted = {context: attempts.ContextCalibration(1.0, 0.0)}
    for p in (0.01, 0.3, 0.77, 0.999):
        assert attempts.in_context(p, context, unshifted) == pytest.approx(p)


@given(
    st.sampled_from(attempts.CONTEXTS),
    st.floats(0.0, 1.0),
    st.floats(0.0, 1.0),
)
def test_more_evidence_never_means_less_confidence_in_any_context(
    context: str, p: float, q: float
) -> None:
    # The fitted calibration is monotone (a positive slope in every context), and a
    # probability stays one.
    low, high = sorted((p, q))
    assert attempts.installed_context_model()[context].slope > 0.0
    assert 0.0 <= attempts.in_context(low, context) <= attempts.in_context(high, context) <= 1.0


# What core/local_mapping/context_model.py held (fitted 2026-11-26): context -> (slope,
# intercept).
OLD_CALIBRATION = {
    "track": (0.989799, 0.308627),
    "search": (0.935029, 1.54902),
    "recent": (1.27437, 0.944932),
    "other": (0.772079, -0.827628),
}


def test_the_context_calibration_is_the_deployed_one() -> None:
    model = attempts.installed_context_model()
    assert {c: (k.slope, k.intercept) for c, k in model.items()} == OLD_CALIBRATION
    assert attempts.installed_context_model() is model
    with pytest.raises(TypeError):
        model["track"] = attempts.ContextCalibration(1.0, 0.0)  # type: ignore[index]
    slope, intercept = OLD_CALIBRATION["search"]
    z = slope * np.log(0.6 / 0.4) + intercept
    assert attempts.in_context(0.6, "search") == pytest.approx(1.0 / (1.0 + np.exp(-z)))


def good_context_model() -> dict[str, object]:
    return shipped("multi_robot_mapper.core.local_mapping", "context_model.json")


def contexts_with(context: str, entry: object) -> str:
    data = good_context_model()
    return json.dumps({**data, "contexts": {**data["contexts"], context: entry}})  # type: ignore[dict-item]


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("", "not JSON"),
        (json.dumps({"calibration": {}}), "expected an object with 'contexts'"),
        (contexts_with("elsewhere", {"slope": 1.0, "intercept": 0.0}), "the front end asks"),
        (contexts_with("track", {"slope": 1.0}), "track intercept must be a finite number"),
        (contexts_with("search", [1.0, 0.0]), "search slope must be a finite number"),
        (contexts_with("other", {"slope": -0.5, "intercept": 0.0}), "other slope -0.5 must be"),
    ],
)
def test_a_malformed_context_model_is_refused_by_name(text: str, says: str) -> None:
    with pytest.raises(ValueError, match=f"^somewhere/context_model.json: .*{says}"):
        attempts.load_context_model(text, "somewhere/context_model.json")
