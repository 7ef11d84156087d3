"""Confidence in context: a front-end match's probability of being right given the question
it answered (the last keyframe from the prediction, the last scan with no guess, an older
keyframe of the robot's piece, another piece's keyframe), by one Platt scaling per context
fitted on the front end's own matches (``context_model.json``, ``bench/fit_placement.py``)."""

from __future__ import annotations

import functools
import json
from collections.abc import Mapping
from importlib import resources
from types import MappingProxyType

import numpy as np

from multi_robot_mapper.core.logistic import LogisticModel, model_number, read_object

# What a front-end match was asked, each with its own base rate of right answers: the last
# keyframe from the prediction, the last scan with no guess, an older keyframe of the robot's
# piece, a keyframe of another piece (where the robot was before it got lost).
CONTEXTS = ("track", "search", "recent", "other")


CONTEXT_MODEL_FILE = "context_model.json"


# What a context's calibration weighs: the match confidence's log-odds, its one feature.
CONTEXT_FEATURES = ("confidence_log_odds",)


class ContextCalibration(LogisticModel):
    """Platt scaling of one context, a logistic model of the match confidence's log-odds:
    log-odds in context = slope * log-odds of the match confidence + intercept."""

    def __init__(self, slope: float, intercept: float) -> None:
        super().__init__(CONTEXT_FEATURES, intercept, np.array([slope]))

    @property
    def slope(self) -> float:
        return float(self.weights[0])


def load_context_model(
    text: str, source: str = CONTEXT_MODEL_FILE
) -> Mapping[str, ContextCalibration]:
    """The calibration of each of :data:`CONTEXTS` in a ``context_model.json`` text (``source``
    names the file in errors), read-only. Every context needs a finite intercept and a
    positive finite slope (more evidence never means less confidence); ValueError, naming
    ``source`` and what is wrong, otherwise."""
    contexts = read_object(text, source, "'contexts'").get("contexts")
    if not isinstance(contexts, dict):
        raise ValueError(f"{source}: expected an object with 'contexts'")
    if set(contexts) != set(CONTEXTS):
        raise ValueError(
            f"{source}: calibrates contexts {sorted(contexts)}, the front end asks {list(CONTEXTS)}"
        )
    model = {}
    for context in CONTEXTS:
        entry = contexts[context] if isinstance(contexts[context], dict) else {}
        slope, intercept = (
            model_number(entry.get(key), f"{source}: {context} {key}")
            for key in ("slope", "intercept")
        )
        if slope <= 0.0:
            raise ValueError(f"{source}: {context} slope {slope} must be positive")
        model[context] = ContextCalibration(slope, intercept)
    return MappingProxyType(model)


def context_model_json(model: Mapping[str, ContextCalibration], fitted: str, command: str) -> str:
    """``context_model.json``'s text for ``model`` (what :func:`load_context_model` reads),
    with how and on what it was ``fitted`` and the ``command`` that fitted it."""
    contexts = {c: {"slope": model[c].slope, "intercept": model[c].intercept} for c in CONTEXTS}
    data = {"contexts": contexts, "fitted": fitted, "command": command}
    return json.dumps(data, indent=2) + "\n"


@functools.cache
def installed_context_model() -> Mapping[str, ContextCalibration]:
    """The calibration shipped with the package (``context_model.json``), read once."""
    path = resources.files(__package__).joinpath(CONTEXT_MODEL_FILE)
    return load_context_model(path.read_text(encoding="utf-8"), str(path))


def in_context(
    confidence: float, context: str, model: Mapping[str, ContextCalibration] | None = None
) -> float:
    """P(right) of a front-end match with this :mod:`~core.matching.confidence`, given its
    context (:data:`CONTEXTS`).

    The confidence model is fitted on a mixture of scan pairs (consecutive, revisits,
    unrelated places: ``bench/fit_confidence.py``), so its base rate is the mixture's. The
    front end asks narrower questions: at a match confidence of 0.5-0.8, a search against the
    last scan, one scan interval before, was right 93 % of the time on the shared logs, a
    match against another piece's keyframe 23 % (``bench/fit_placement.py``, README
    "Confidence in context"). Bayes' rule moves the log-odds by each context's prior; a
    slope lets the evidence count more or less there too (Platt scaling, fitted per context
    on the front end's own matches with the reference, written into ``context_model.json``:
    :func:`installed_context_model`, unless ``model`` is given)."""
    calibration = (installed_context_model() if model is None else model)[context]
    p = min(max(confidence, 1e-9), 1.0 - 1e-9)
    return float(calibration.probabilities([float(np.log(p / (1.0 - p)))]))
