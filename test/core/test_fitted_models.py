"""The fitted models the package ships as data (``core/matching/confidence_model.json``,
``core/local_mapping/context_model.json``): loaded they hold exactly the numbers the generated
modules they replace held, the fit scripts' writers round-trip through the loaders, and a
malformed file is refused with an error naming the file and what is wrong. Each model's own
numbers and malformed files: test/core/matching/test_confidence.py and
test/core/local_mapping/test_context.py; here what they share."""

from __future__ import annotations

import json
from importlib import resources

import numpy as np

from multi_robot_mapper.core.local_mapping import attempts
from multi_robot_mapper.core.matching import confidence


def shipped(package: str, name: str) -> dict[str, object]:
    data: dict[str, object] = json.loads(resources.files(package).joinpath(name).read_text())
    return data


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
