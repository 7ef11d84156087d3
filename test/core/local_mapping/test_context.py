"""Confidence in context: a context's prior shifts the odds (Bayes' rule), monotone in the
evidence."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

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
