"""The fitted logistic model: the form of every probability the package learns from data, and
the one reader of the JSON files it ships them in.

Three callers use it, each with its own file and the features its own code computes: the match
confidence (:mod:`~multi_robot_mapper.core.matching.confidence`, ``confidence_model.json``), its
calibration in each front-end context (:mod:`~multi_robot_mapper.core.local_mapping.attempts`,
``context_model.json``: one feature, the confidence's log-odds) and the back end's placement
decisions (:mod:`~multi_robot_mapper.core.evidence.model`, ``join_model.json`` and its kin).
The coefficients are data, not code: a refit changes no line of the callers. A file fitted on
other features than the code computes is refused, naming the file and the features, rather
than weighing numbers that mean something else.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclasses.dataclass(frozen=True, eq=False)
class LogisticModel:
    """P(right) = 1 / (1 + exp(-(intercept + weights . features)))."""

    features: tuple[str, ...]  # what each weight weighs, in the weights' order
    intercept: float
    # One per feature; a read-only copy, because a loaded model is shared (cached) by every
    # caller and nothing may change it under them.
    weights: FloatArray
    fitted: str = ""  # how and on what it was fitted (the fit's own words)
    command: str = ""  # the command that fitted it ("": the file does not say)

    def __post_init__(self) -> None:
        weights = np.array(self.weights, dtype=np.float64)
        if weights.shape != (len(self.features),):
            raise ValueError(f"{len(self.features)} features, weights of shape {weights.shape}")
        weights.flags.writeable = False
        # Frozen: the normalised fields are set the way the dataclass sets them.
        object.__setattr__(self, "features", tuple(self.features))
        object.__setattr__(self, "intercept", float(self.intercept))
        object.__setattr__(self, "weights", weights)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LogisticModel):
            return NotImplemented
        return (
            self.features == other.features
            and self.intercept == other.intercept
            and bool(np.array_equal(self.weights, other.weights))
            and self.fitted == other.fitted
            and self.command == other.command
        )

    def __hash__(self) -> int:
        # A model is part of the key of the merger's cached verdicts (merging/joint.py).
        weights = tuple(self.weights.tolist())
        return hash((self.features, self.intercept, weights, self.fitted, self.command))

    # The two ways keep the arithmetic each caller always had, so that no probability moves by
    # a rounding: a decision's features by name, summed in order in Python floats; rows of
    # match features at once, with numpy.
    def probability(self, values: Mapping[str, float]) -> float:
        """P(right) of one decision whose features ``values`` names (others are ignored)."""
        z = self.intercept + sum(
            w * float(values[name])
            for name, w in zip(self.features, self.weights.tolist(), strict=True)
        )
        return 1.0 / (1.0 + math.exp(-max(-50.0, min(50.0, z))))

    def probabilities(self, rows: ArrayLike) -> FloatArray:
        """P(right) of each row of ``rows`` (its features in the model's order), or of one
        feature vector."""
        z = self.intercept + np.asarray(rows, dtype=np.float64) @ self.weights
        return np.asarray(1.0 / (1.0 + np.exp(-np.clip(z, -50.0, 50.0))))

    def dumps(self) -> str:
        """The model file's text (what :func:`load_model` reads); the command when known."""
        data: dict[str, Any] = {
            "features": list(self.features),
            "intercept": self.intercept,
            "weights": self.weights.tolist(),
            "fitted": self.fitted,
        }
        if self.command:
            data["command"] = self.command
        return json.dumps(data, indent=2) + "\n"


def load_model(
    text: str, source: str, known: Sequence[str], refit: str, in_order: bool = True
) -> LogisticModel:
    """The model of a model file's ``text``. ``source`` names the file in errors, ``known``
    are the features the caller's code computes and ``refit`` the command that refits the
    model. With ``in_order`` the model must weigh all of them, in that order (its callers
    pass rows of features); otherwise any of them, in any order (a feature left out weighs
    nothing). ValueError, naming ``source`` and what is wrong, otherwise."""
    data = read_object(text, source, "features, intercept and weights")
    missing = [key for key in ("features", "intercept", "weights") if key not in data]
    if missing:
        raise ValueError(f"{source}: missing {', '.join(missing)}")
    features = _features(data["features"], source, known, refit, in_order)
    intercept = model_number(data["intercept"], f"{source}: intercept")
    weights = data["weights"]
    if not isinstance(weights, list) or len(weights) != len(features):
        raise ValueError(f"{source}: expected {len(features)} weights, one per feature")
    values = [model_number(w, f"{source}: weight {i}") for i, w in enumerate(weights)]
    fitted, command = (str(data.get(key, "")) for key in ("fitted", "command"))
    return LogisticModel(features, intercept, np.array(values), fitted, command)


def _features(
    value: object, source: str, known: Sequence[str], refit: str, in_order: bool
) -> tuple[str, ...]:
    """A model file's feature names, checked against the ``known`` ones (:func:`load_model`)."""
    names = tuple(str(v) for v in value) if isinstance(value, list) else ()
    unknown = [name for name in names if name not in known]
    absent = [name for name in known if name not in names] if in_order else []
    if isinstance(value, list) and not unknown and (not in_order or names == tuple(known)):
        return names
    named = [
        f"{what} {listed}" for what, listed in (("unknown", unknown), ("missing", absent)) if listed
    ]
    raise ValueError(
        f"{source}: fitted on features {value}, the code computes {list(known)}"
        + (f" ({', '.join(named)})" if named else "")
        + f"; refit with {refit}"
    )


def read_object(text: str, source: str, expected: str) -> dict[str, Any]:
    """The JSON object of a model file's ``text``; ValueError naming ``source`` when it is not
    JSON, or not an object (which should hold ``expected``)."""
    try:
        data: Any = json.loads(text)
    except json.JSONDecodeError as error:
        raise ValueError(f"{source}: not JSON ({error})") from None
    if not isinstance(data, dict):
        raise ValueError(f"{source}: expected an object with {expected}")
    return data


def model_number(value: object, what: str) -> float:
    """A fitted model file's number: ``value`` as a float, or ValueError saying ``what`` is
    not a finite number."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{what} must be a finite number, not {value!r}")
    return float(value)
