"""The probability that a decision to place one map on another is right, from its evidence
(:mod:`~multi_robot_mapper.core.evidence.placement`): a logistic model fitted on the decisions
of generated buildings and shared logs, whose truth is known, and checked held out by
building (``bench/fit_join.py``, docs/evidence_model.md).

The coefficients are data, not code (:mod:`~multi_robot_mapper.core.logistic`): a refit changes
no line of the merger. Three models share the features and the form, fitted on different
decisions:

- ``join_model.json``: a link between two robots' maps (the merger), whose placement nothing
  bounds;
- ``closure_model.json``: a loop closure within one robot's map (the local back end,
  ``bench/fit_join.py --decisions closure``), found where the robot's own graph predicts it,
  after the match's confidence and the graph's gate: most such candidates are right (a prior
  the merger's candidates do not have), so the same evidence means more;
- ``piece_join_model.json``: a join of two pieces of one robot's map after it was lost
  (``--decisions piece_join``), found only within the robot's reach: weaker than a closure
  (9 % of the first joins weighed are wrong), so it needs more wall that no rival explains.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from importlib import resources

import numpy as np
from numpy.typing import ArrayLike

from multi_robot_mapper.core.evidence.placement import PlacementEvidence
from multi_robot_mapper.core.logistic import LogisticModel, load_model

MODEL_FILE = "join_model.json"
CLOSURE_MODEL_FILE = "closure_model.json"
PIECE_JOIN_MODEL_FILE = "piece_join_model.json"

# The features, in the model's order (each a number of the decision's evidence):
FEATURES = (
    "margin",  # m of wall the placement explains and its best rival does not (weaker way)
    # log(1 + that margin, 0 when negative): the first metres no rival explains say more
    # than the hundredth (a model linear in the margin alone was under-sure above 0.9 and
    # over-sure below: bench/fit_join.py's reliability table)
    "log_margin",
    "log_score",  # log(1 + m of wall the placement explains, weaker way)
    "rival_ratio",  # the larger share of the placement's score a rival reaches (0-1+)
    "conflict",  # m of wall the placement puts in free space the robots saw, either way
    "conflict_share",  # that, as a share of the wall it matches (the larger way)
)
# A loop closure's alone (:func:`graph_prior`): how much better the robot's own graph predicts
# the closure than a look-alike found anywhere it was searched (nats).
PRIOR_FEATURE = "graph_prior"


def load_join_model(text: str, source: str = MODEL_FILE) -> LogisticModel:
    """A decision model of a model file's ``text`` (``source`` names the file in errors): any
    of :data:`FEATURES` and :data:`PRIOR_FEATURE`, in any order (weighed by name,
    :meth:`~multi_robot_mapper.core.logistic.LogisticModel.probability`). ValueError, naming
    ``source`` and what is wrong, otherwise."""
    names = (*FEATURES, PRIOR_FEATURE)
    return load_model(text, source, names, "bench/fit_join.py", in_order=False)


def installed_model(name: str = MODEL_FILE) -> LogisticModel:
    """A model shipped with the package: the join model (default), ``CLOSURE_MODEL_FILE`` or
    ``PIECE_JOIN_MODEL_FILE``."""
    path = resources.files(__package__).joinpath(name)
    return load_join_model(path.read_text(encoding="utf-8"), str(path))


def graph_prior(correction: ArrayLike, covariance: ArrayLike, search_radius: float) -> float:
    """The log-likelihood ratio (nats) of a loop closure's relative pose under the robot's
    own graph against a look-alike place: ``correction`` (dx, dy, dtheta; m, rad) is the
    closure's relative pose in the graph's prediction, Gaussian with ``covariance`` (3x3, the
    closure gate's) when the closure is right; a look-alike lies anywhere in the disc of
    ``search_radius`` (m) the closure was searched in, at any heading (uniform density
    1 / (pi r^2 * 2 pi)).

    A closure where a stiff graph predicts it, in a small search region, is right before any
    wall is weighed; one 10 m and 90 deg from the prediction of a graph that allows it (a
    pillar hall's loose front-end edges, a long drive since the last closure) is what a
    look-alike would be. The wall evidence alone cannot say which (generated building 119:
    8 closures 8.5-9.9 m / 90 deg off with 2-4 m of wall at P 0.998; issue 46)."""
    sigma = np.asarray(covariance, dtype=np.float64)
    delta = np.asarray(correction, dtype=np.float64)
    sign, log_det = np.linalg.slogdet(2.0 * math.pi * sigma)
    if sign <= 0:
        raise ValueError(f"graph_prior: covariance is not positive definite: {sigma.tolist()}")
    log_right = -0.5 * float(delta @ np.linalg.solve(sigma, delta)) - 0.5 * float(log_det)
    log_look_alike = -math.log(math.pi * max(search_radius, 1e-3) ** 2 * 2.0 * math.pi)
    return log_right - log_look_alike


def join_features(
    ways: Sequence[PlacementEvidence], conflict: float = 0.0, prior: float | None = None
) -> dict[str, float]:
    """The model's features of a decision from its evidence (:mod:`.placement`), measured one
    way or both (the weaker way counts): margin and score (m), the rival's share, the walls
    in free space (m; the larger of the ways' and ``conflict``, measured over more of the
    maps: of every map of the groups a join makes) and their share of the wall matched; with
    ``prior`` (a loop closure's :func:`graph_prior`) that too."""
    score = min(w.score for w in ways)
    margin = min(w.margin for w in ways)
    extra = {} if prior is None else {PRIOR_FEATURE: float(prior)}
    return {
        "margin": margin,
        "log_margin": math.log1p(max(margin, 0.0)),
        "log_score": math.log1p(max(score, 0.0)),
        "rival_ratio": max(w.rival_ratio for w in ways),
        "conflict": max(conflict, *(w.conflict for w in ways)),
        "conflict_share": max(w.conflict_share for w in ways),
        **extra,
    }
