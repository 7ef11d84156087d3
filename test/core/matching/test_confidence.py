"""The match confidence model the package ships as data (core/matching/confidence_model.json):
loaded it holds exactly the numbers the generated module it replaced held, and a malformed file is
refused naming the file and what is wrong."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_fitted_models import shipped

from multi_robot_mapper.core.matching import confidence

# What core/matching/confidence_model.py held (fitted 2026-11-23, deleted when the model
# became confidence_model.json).
OLD_SCAN_FEATURES = (
    "agreement",
    "log_confirmed",
    "possible_overlap",
    "seen_through_share",
    "uniqueness",
    "log_support",
    "fraction",
    "log_score_ratio",
    "weaker_agreement",
    "weaker_overlap",
    "uniqueness_x_log_confirmed",
    "log_support_x_log_confirmed",
    "beam_margin",
    "ambiguity",
)


OLD_SCAN_INTERCEPT = -4.15674


OLD_SCAN_WEIGHTS = (
    1.12698,
    0.371448,
    2.64322,
    -11.2404,
    2.66771,
    -0.151869,
    1.11423,
    0.332633,
    1.34524,
    2.67463,
    0.514669,
    -0.0046083,
    0.747362,
    0.463421,
)


def test_the_match_confidence_model_is_the_deployed_one() -> None:
    model = confidence.installed_scan_model()
    assert confidence.FEATURES == OLD_SCAN_FEATURES
    assert model.intercept == OLD_SCAN_INTERCEPT  # exactly: converted, not refitted
    assert tuple(model.weights.tolist()) == OLD_SCAN_WEIGHTS
    assert confidence.installed_scan_model() is model  # read once
    with pytest.raises(ValueError, match="read-only"):
        model.weights[0] = 0.0
    # confidence() uses it: the features' log-odds by hand.
    features = np.linspace(0.0, 1.0, len(OLD_SCAN_FEATURES))
    z = OLD_SCAN_INTERCEPT + float(np.dot(features, OLD_SCAN_WEIGHTS))
    assert confidence.confidence(features) == pytest.approx(1.0 / (1.0 + np.exp(-z)), rel=1e-12)


def good_scan_model() -> dict[str, object]:
    return shipped("multi_robot_mapper.core.matching", "confidence_model.json")


def with_change(data: dict[str, object], key: str, value: object) -> str:
    return json.dumps({**data, key: value})


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("{not json", "not JSON"),
        ("[1, 2]", "expected an object"),
        (json.dumps({"features": list(OLD_SCAN_FEATURES)}), "missing intercept, weights"),
        (
            with_change(good_scan_model(), "features", list(OLD_SCAN_FEATURES[::-1])),
            "fitted on features",
        ),
        (with_change(good_scan_model(), "weights", [1.0, 2.0]), "expected 14 weights"),
        (with_change(good_scan_model(), "intercept", "high"), "intercept must be a finite"),
        (
            with_change(good_scan_model(), "weights", [*OLD_SCAN_WEIGHTS[:-1], float("nan")]),
            "weight 13 must be a finite",
        ),
    ],
)
def test_a_malformed_confidence_model_is_refused_by_name(text: str, says: str) -> None:
    with pytest.raises(ValueError, match=f"^somewhere/confidence_model.json: .*{says}"):
        confidence.load_scan_model(text, "somewhere/confidence_model.json")
