"""The fitted models the package ships as data (``core/matching/confidence_model.json``,
``core/local_mapping/context_model.json``): loaded they hold exactly the numbers the generated
modules they replace held, the fit scripts' writers round-trip through the loaders, and a
malformed file is refused with an error naming the file and what is wrong."""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pytest

from multi_robot_mapper.core.local_mapping import attempts
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
# What core/local_mapping/context_model.py held (fitted 2026-11-26): context -> (slope,
# intercept).
OLD_CALIBRATION = {
    "track": (0.989799, 0.308627),
    "search": (0.935029, 1.54902),
    "recent": (1.27437, 0.944932),
    "other": (0.772079, -0.827628),
}


def shipped(package: str, name: str) -> dict[str, object]:
    data: dict[str, object] = json.loads(resources.files(package).joinpath(name).read_text())
    return data


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


def test_the_context_calibration_is_the_deployed_one() -> None:
    model = attempts.installed_context_model()
    assert {c: (k.slope, k.intercept) for c, k in model.items()} == OLD_CALIBRATION
    assert attempts.installed_context_model() is model
    with pytest.raises(TypeError):
        model["track"] = attempts.ContextCalibration(1.0, 0.0)  # type: ignore[index]
    slope, intercept = OLD_CALIBRATION["search"]
    z = slope * np.log(0.6 / 0.4) + intercept
    assert attempts.in_context(0.6, "search") == pytest.approx(1.0 / (1.0 + np.exp(-z)))


def test_the_model_files_keep_their_provenance() -> None:
    for package, name in (
        ("multi_robot_mapper.core.matching", "confidence_model.json"),
        ("multi_robot_mapper.core.local_mapping", "context_model.json"),
    ):
        data = shipped(package, name)
        assert "bench/fit_" in str(data["fitted"]) and "fit --write" in str(data["command"])


def test_the_writers_round_trip_through_the_loaders() -> None:
    scan = confidence.installed_scan_model()
    text = confidence.scan_model_json(scan, "a test", "no command")
    again = confidence.load_scan_model(text)
    assert again.intercept == scan.intercept
    np.testing.assert_array_equal(again.weights, scan.weights)
    assert json.loads(text)["fitted"] == "a test"
    contexts = attempts.installed_context_model()
    text = attempts.context_model_json(contexts, "a test", "no command")
    assert attempts.load_context_model(text) == contexts
    assert json.loads(text)["command"] == "no command"


def good_scan_model() -> dict[str, object]:
    return shipped("multi_robot_mapper.core.matching", "confidence_model.json")


def good_context_model() -> dict[str, object]:
    return shipped("multi_robot_mapper.core.local_mapping", "context_model.json")


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
