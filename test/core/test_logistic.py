"""The one logistic model type and loader (core/logistic.py) behind every model file the
package ships: each file loads to the probabilities the code that read it before computed,
bit for bit, each writer gives the shipped file back byte for byte, and a file fitted on other
features is refused naming the file and those features."""

from __future__ import annotations

import json
import math
from importlib import resources

import numpy as np
import pytest

from multi_robot_mapper.core.evidence import model as evidence_model
from multi_robot_mapper.core.local_mapping import attempts
from multi_robot_mapper.core.logistic import LogisticModel
from multi_robot_mapper.core.matching import confidence

EVIDENCE = "multi_robot_mapper.core.evidence"
DECISION_FILES = ("join_model.json", "closure_model.json", "piece_join_model.json")


def shipped_text(package: str, name: str) -> str:
    return resources.files(package).joinpath(name).read_text(encoding="utf-8")


def feature_rows(count: int, width: int) -> np.ndarray:
    """Seeded rows over the features' ranges and past them, and the all-zero row."""
    rng = np.random.default_rng(49)
    return np.vstack((np.zeros(width), rng.normal(0.0, 3.0, (count, width))))


@pytest.mark.parametrize("name", DECISION_FILES)
def test_a_decision_model_weighs_as_the_join_model_did(name: str) -> None:
    data = json.loads(shipped_text(EVIDENCE, name))
    model = evidence_model.installed_model(name)
    names = (*evidence_model.FEATURES, evidence_model.PRIOR_FEATURE)
    for row in feature_rows(50, len(names)):
        values = dict(zip(names, row.tolist(), strict=True))
        # the join model's probability before core/logistic.py, on the file's own numbers.
        z = float(data["intercept"]) + sum(
            float(w) * values[f] for f, w in zip(data["features"], data["weights"], strict=True)
        )
        assert model.probability(values) == 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, z))))


def test_the_match_confidence_weighs_as_its_logistic_model_did() -> None:
    data = json.loads(shipped_text("multi_robot_mapper.core.matching", "confidence_model.json"))
    weights = np.array(data["weights"])

    def old(rows: np.ndarray) -> np.ndarray:
        """The old LogisticModel.probability, on the file's own numbers."""
        z = data["intercept"] + rows @ weights
        return np.asarray(1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0))))

    rows = feature_rows(50, len(confidence.FEATURES))
    np.testing.assert_array_equal(confidence.installed_scan_model().probabilities(rows), old(rows))
    # One match at a time, as the matcher asks (a vector's sum may round unlike a matrix row's).
    assert [confidence.confidence(row) for row in rows] == [float(old(row)) for row in rows]


def test_the_context_calibration_weighs_as_its_platt_scaling_did() -> None:
    data = json.loads(shipped_text("multi_robot_mapper.core.local_mapping", "context_model.json"))
    for context, entry in data["contexts"].items():
        for p in (0.0, 1e-12, 0.01, 0.2, 0.5, 0.77, 0.99, 1.0 - 1e-12, 1.0):
            # The old in_context, on the file's own numbers.
            q = min(max(p, 1e-9), 1.0 - 1e-9)
            z = entry["slope"] * float(np.log(q / (1.0 - q))) + entry["intercept"]
            old = float(1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0))))
            assert attempts.in_context(p, context) == old


def test_the_writers_give_the_shipped_files_back() -> None:
    for name in DECISION_FILES:
        assert evidence_model.installed_model(name).dumps() == shipped_text(EVIDENCE, name)
    scan = confidence.installed_scan_model()
    text = shipped_text("multi_robot_mapper.core.matching", "confidence_model.json")
    assert confidence.scan_model_json(scan, scan.fitted, scan.command) == text
    text = shipped_text("multi_robot_mapper.core.local_mapping", "context_model.json")
    data = json.loads(text)
    contexts = attempts.installed_context_model()
    assert attempts.context_model_json(contexts, data["fitted"], data["command"]) == text


def test_equal_models_are_one_key() -> None:
    # The merger keys its cached verdicts by the model (merging/joint.py).
    a = LogisticModel(("margin", "log_score"), -1.0, (0.5, 2.0), "fit")
    b = LogisticModel(("margin", "log_score"), -1.0, np.array([0.5, 2.0]), "fit")
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    assert a != LogisticModel(("margin", "log_score"), -1.0, (0.5, 2.5), "fit")
    with pytest.raises(ValueError, match="2 features"):
        LogisticModel(("margin", "log_score"), -1.0, (0.5,))


def test_a_model_fitted_on_other_features_is_refused_naming_them() -> None:
    decision = evidence_model.installed_model().dumps().replace('"log_margin"', '"log_margn"')
    with pytest.raises(ValueError, match=r"^there/closure_model.json: .*unknown \['log_margn'\]"):
        evidence_model.load_join_model(decision, "there/closure_model.json")
    scan = confidence.installed_scan_model().dumps().replace('"ambiguity"', '"ambiguty"')
    with pytest.raises(
        ValueError,
        match=r"^here/confidence_model.json: .*unknown \['ambiguty'\], missing \['ambiguity'\]",
    ):
        confidence.load_scan_model(scan, "here/confidence_model.json")
