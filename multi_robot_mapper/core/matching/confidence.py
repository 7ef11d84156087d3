"""Match confidence: the probability that a match is right (within 0.30 m and 5 degrees).

INTEGRATE's value (overlap length of matching segments) says how much two segment sets agree
under the best transformation, not whether the transformation is right: in clutter most
returns make no segment, in corridors a wrong offset overlaps as much as the right one, and a
small overlap is often the true one. The confidence combines evidence that holds in those
cases too, each a number with a meaning:

- **beam agreement** (:func:`beam_agreement`): every return of one scan tested against the
  other scan's beams, both ways. A return where the other's beam ended is *confirmed*; one
  lying where the other's beam passed on is *seen through* (a contradiction: the other laser
  saw free space there); one behind what the other saw is *occluded*; one outside its field
  of view or range is *outside* (neither for nor against). Clusters too small for a segment
  (chairs, table legs, people) are returns like any other, so a cluttered hall keeps its
  evidence;
- **possible overlap**: the share of both scans that the other could have seen at all
  (confirmed + seen through), given both fields of view and what occludes them;
- **uniqueness**: the net score of the best placement against that of the best *rival*, a
  distinct placement more than the correctness tolerance away (a corridor that fits twice);
- **spread of the fit**: the matched length across the least constrained direction (the
  smallest eigenvalue of the point-to-line information, :func:`scoring.information`): zero in
  a bare corridor, whose offset along the walls nothing fixes.

A logistic model (:class:`~multi_robot_mapper.core.logistic.LogisticModel`) turns them into a
probability. Its weights are fitted on the shared logs by ``bench/fit_confidence.py`` (leave
one log out to check calibration) and written, with the command and data they came from, into
``confidence_model.json`` beside this module (data the package ships, loaded once by
:func:`installed_scan_model`); the thresholds that decide each use (integrate a scan, close a
loop, link two robots) are in the configs of those stages, chosen from the precision/recall
curve (README).
"""

from __future__ import annotations

import dataclasses
import functools
from importlib import resources

import numpy as np
from numpy.typing import NDArray

from multi_robot_mapper.core import se2
from multi_robot_mapper.core.logistic import LogisticModel, load_model
from multi_robot_mapper.core.matching.beams import BeamAgreement

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

# A match is right when it is within these of the truth: what the confidence estimates.
RIGHT_DISTANCE = 0.30  # m
RIGHT_ANGLE = float(np.radians(5.0))
# A match more likely right than wrong. Two such matches of different scan pairs that agree on
# a placement corroborate each other: wrong matches rarely agree from two scans (when they do,
# one structure misleads both, and their confidence is low).
LIKELY = 0.5
# Refining one prediction finds the nearest minimum, right or not, and no rival to doubt it: a
# prediction is refined turned by these (rad) too, so that a wrong minimum has rivals (a turn
# that starts between two scans is the usual miss of a constant-velocity prediction).
TRACK_TURNS = (-0.4, -0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3, 0.4)
# Buildings are made of right angles: a room or a crossing fits a quarter or a half turn away
# as well as the right way. A prediction refined turned by these (rad) as well finds that
# look-alike's rival, or the right placement when a wrong prediction found the look-alike.
LOOK_ALIKE_TURNS = (np.pi / 2, -np.pi / 2, np.pi)


@dataclasses.dataclass(frozen=True)
class MatchEvidence:
    """Everything the confidence is computed from (lengths in metres)."""

    second_in_first: BeamAgreement  # S2's returns judged by S1's beams
    first_in_second: BeamAgreement  # S1's returns judged by S2's beams
    score: float  # INTEGRATE's net score of the chosen placement
    rival_score: float  # net score of the best distinct rival placement (0: none)
    support: float  # matched length across the least constrained direction
    fraction: float  # INTEGRATE's net value / shorter set's segment length
    # both sets' returns judged with the best rival placement (all zero: no rival)
    rival: BeamAgreement = dataclasses.field(default_factory=BeamAgreement.nothing)
    # metres of wall a motion prior adds across the least constrained direction (tracking:
    # core.matching.prior; not stored by as_array: the model is fitted on matches without one)
    prior_support: float = 0.0

    def as_array(self) -> FloatArray:
        """The raw evidence as 19 numbers (:meth:`from_array` inverts it): what the fitting
        script stores, so that features can change without matching again."""
        return np.concatenate(
            (
                self.second_in_first.as_array(),
                self.first_in_second.as_array(),
                [self.score, self.rival_score, self.support, self.fraction],
                self.rival.as_array(),
            )
        )

    @staticmethod
    def from_array(raw: FloatArray) -> MatchEvidence:
        score, rival_score, support, fraction = (float(v) for v in raw[10:14])
        return MatchEvidence(
            BeamAgreement(*(float(v) for v in raw[0:5])),
            BeamAgreement(*(float(v) for v in raw[5:10])),
            score,
            rival_score,
            support,
            fraction,
            BeamAgreement(*(float(v) for v in raw[14:19])),
        )

    def features(self) -> FloatArray:
        """The model's inputs, each bounded and of one meaning (see :data:`FEATURES`).

        Agreement is no evidence of a unique placement when a rival explains the beams as
        well and nothing constrains the slide between them: the agreement terms are
        discounted by that ambiguity (a logistic model cannot learn the AND itself; on the
        logs, ties without support are right 4 % of the time, and a bare corridor, where
        everything agrees, lies beyond every sample)."""
        both = self.second_in_first + self.first_in_second
        confirmed = np.log1p(both.confirmed)
        score, rival = max(self.score, 0.0), max(self.rival_score, 0.0)
        uniqueness = (score - rival) / score if score > 0.0 else 0.0
        fixed = max(self.support, 0.0) + max(self.prior_support, 0.0)  # across the weakest
        support = np.log1p(fixed)
        sides = (self.second_in_first, self.first_in_second)
        margin = _beam_margin(both, self.rival)
        ambiguity = (1.0 - float(np.clip(margin / TIE_MARGIN, 0.0, 1.0))) / (
            1.0 + fixed / SLIDE_SUPPORT
        )
        kept = 1.0 - ambiguity
        return np.array(
            [
                kept * _agreement(both),
                kept * confirmed,
                kept * _possible(both),
                both.seen_through / both.total if both.total > 0.0 else 0.0,
                uniqueness,
                support,
                float(np.clip(self.fraction, -1.0, 1.0)),
                float(np.clip(np.log(max(score, 1e-3) / max(rival, 1e-3)), -3.0, 3.0)),
                kept * min(_agreement(side) for side in sides),
                kept * min(_possible(side) for side in sides),
                kept * uniqueness * confirmed,
                kept * support * confirmed,
                margin,
                ambiguity,
            ]
        )


def _beam_margin(best: BeamAgreement, rival: BeamAgreement) -> float:
    """How much better the beams judge the best placement than its best rival: the share of
    judged returns they confirm (:func:`_agreement`) for the best, less that for the rival
    (0 without a rival). Returns the beams cannot judge (occluded, out of range) are no
    evidence either way: a slide along a bare corridor, or a room that fits turned round,
    is a tie however much agrees."""
    if rival.total <= 0.0:
        return 0.0
    return _agreement(best) - _agreement(rival)


def _agreement(agreement: BeamAgreement) -> float:
    """Confirmed / (confirmed + seen through): how the other side's beams judge what they
    could see."""
    judged = agreement.confirmed + agreement.seen_through
    return agreement.confirmed / judged if judged > 0.0 else 0.0


def _possible(agreement: BeamAgreement) -> float:
    """(Confirmed + seen through) / all: the share the other side could see at all."""
    judged = agreement.confirmed + agreement.seen_through
    return judged / agreement.total if agreement.total > 0.0 else 0.0


# A rival whose share of confirmed returns is within this of the best one's ties with it.
TIE_MARGIN = 0.1
# Matched length across the weakest direction (m) at which a slide counts half constrained:
# most wrong scan matches on the logs have less than this (bench/scan_gate.py).
SLIDE_SUPPORT = 0.1

# The first three and the agreement products are discounted by the ambiguity (see features).
FEATURES = (
    "agreement",  # confirmed / (confirmed + seen through), both sides
    "log_confirmed",  # log(1 + metres confirmed)
    "possible_overlap",  # (confirmed + seen through) / all returns
    "seen_through_share",  # seen through / all returns
    "uniqueness",  # (score - rival) / score
    "log_support",  # log(1 + cross support in metres)
    "fraction",  # INTEGRATE's net fraction
    "log_score_ratio",  # log(score / rival), within +-3
    "weaker_agreement",  # the lower agreement of the two sides
    "weaker_overlap",  # the lower possible overlap of the two sides
    "uniqueness_x_log_confirmed",  # a tie is suspect however much agrees
    "log_support_x_log_confirmed",  # a corridor is suspect however much agrees
    "beam_margin",  # how much better the beams explain the best placement than its rival
    "ambiguity",  # a tie with the rival (beam margin < TIE_MARGIN) and no support to break it
)


MODEL_FILE = "confidence_model.json"


def load_scan_model(text: str, source: str = MODEL_FILE) -> LogisticModel:
    """The match-confidence model of a ``confidence_model.json`` text (``source`` names the
    file in errors): its features must be :data:`FEATURES` in that order (the rows of
    :meth:`MatchEvidence.features` are weighed as they come), one finite weight each.
    ValueError, naming ``source`` and what is wrong, otherwise."""
    return load_model(text, source, FEATURES, "bench/fit_confidence.py")


def scan_model_json(model: LogisticModel, fitted: str, command: str) -> str:
    """``confidence_model.json``'s text for ``model`` (what :func:`load_scan_model` reads),
    with how and on what it was ``fitted`` and the ``command`` that fitted it."""
    return dataclasses.replace(model, fitted=fitted, command=command).dumps()


@functools.cache
def installed_scan_model() -> LogisticModel:
    """The fitted model shipped with the package (``confidence_model.json``), read once."""
    path = resources.files(__package__).joinpath(MODEL_FILE)
    return load_scan_model(path.read_text(encoding="utf-8"), str(path))


def confidence(features: FloatArray, model: LogisticModel | None = None) -> float:
    """P(right) of a match with these :meth:`MatchEvidence.features` (the fitted model unless
    ``model`` is given)."""
    return float((installed_scan_model() if model is None else model).probabilities(features))


def is_right(T_estimate: FloatArray, T_truth: FloatArray) -> bool:
    """Is an estimated ``T_a_b`` (3x3) within the correctness tolerance of the truth?"""
    dx, dy, dtheta = se2.pose_from_matrix(se2.invert(T_truth) @ T_estimate)
    return bool(np.hypot(dx, dy) < RIGHT_DISTANCE and abs(dtheta) < RIGHT_ANGLE)
