"""Fit and check the join model (issue 46): the probability that a placement of one map on
another is right, from its evidence (``core/evidence/model.py``).

    .venv/bin/python -m bench.fit_join [--work bench_output/decisions ...] [--write]
        [--figure docs/figures/join_reliability.png] [--decisions merger|closure|piece_join]

``--decisions closure`` (``piece_join``) fits the local back end's model of loop closures
(joins of pieces) instead, ``closure_model.json`` (``piece_join_model.json``), on the
decisions of that kind it weighed (``bench/backend_decisions.py``, or
``bench/decisions.py collect --maps own``), each judged by the truth; held out by scenario
as the merger's.

Reads every pair of maps' consistent set that ``bench/decisions.py collect`` (or ``judge``)
recorded, each with its evidence and whether its placement is right by the truth; a set seen
at several updates with the same evidence counts once. A wrong set that is the truth moved by
the building's own symmetry (a generated building whose wings are exact copies: robots in
two copies see the same walls, and no map can tell which copy is which) is left out: the
model is the probability that a placement is right where the maps can tell, and the
benchmark counts such placements apart (``bench/decisions.py``). Fits a logistic model (L2
penalty on
standardised features, the penalty chosen by held-out log loss) and checks it **held out by
building**: each scenario's sets are predicted by the fit on the other scenarios (ten folds
of whole scenarios). Prints, held out: the reliability table (predicted against observed, in
bins), and at ``join_probability`` 0.99 (and a few other thresholds) how many sets are
accepted and how many of those are wrong, per source. ``--write`` writes the fit on every
set to ``multi_robot_mapper/core/evidence/join_model.json``; ``--figure`` draws the
reliability diagram.
"""

from __future__ import annotations

import argparse
import itertools
import json
from datetime import date
from pathlib import Path
from typing import Any

import numpy as np
from scipy.optimize import minimize

from bench.harness import OUTPUT, REPO
from multi_robot_mapper.core.evidence.model import (
    CLOSURE_MODEL_FILE,
    FEATURES,
    MODEL_FILE,
    PIECE_JOIN_MODEL_FILE,
    PRIOR_FEATURE,
    join_features,
)
from multi_robot_mapper.core.evidence.placement import (
    EVIDENCE_CORRELATION,
    PlacementEvidence,
)
from multi_robot_mapper.core.logistic import LogisticModel

L2_GRID = (1e-4, 1e-3, 1e-2)
FOLDS = 10
THRESHOLDS = (0.5, 0.9, 0.99, 0.999)


def features_of(record: dict[str, Any]) -> list[float] | None:
    """The model's features of a recorded set (evidence.model.join_features, as the merger
    computes them: PairEvidence.features), None without evidence."""
    ways = [record.get("b_on_a"), record.get("a_on_b")]
    if any(w is None for w in ways):
        return None
    return _features(ways, record["seen_through"][1])  # type: ignore[arg-type]


def _features(ways: list[dict[str, float]], conflict: float) -> list[float]:
    """The features of a decision measured one or two ways, as the merger computes them
    (evidence.model.join_features); a record's matched wall is its score plus the free-space
    weight times its conflict (the score's two parts)."""
    weight = EVIDENCE_CORRELATION.free_space_weight
    evidence = [
        PlacementEvidence(
            w["score"],
            w["rival"],
            w.get("wall", 0.0),
            np.zeros(3),
            None,
            w.get("conflict", 0.0),
            w.get("matched", w["score"] + weight * w.get("conflict", 0.0)),
        )
        for w in ways
    ]
    values = join_features(evidence, conflict)
    return [values[name] for name in FEATURES]


def load(
    works: list[str], decisions: str = "merger"
) -> tuple[np.ndarray, np.ndarray, list[str], list[str]]:
    """(features, right, scenario of each set, source of each set), each set once: the
    merger's sets, or with ``decisions`` "closure" or "piece_join" the back end's decisions of
    that kind ("loop" or "join")."""
    rows, labels, groups, sources = [], [], [], []
    seen: set[tuple[Any, ...]] = set()
    kind = {"closure": "loop", "piece_join": "join"}.get(decisions)  # a back-end kind, or None
    for work in works:
        for path in sorted((Path(work) / "records").glob("*.json")):
            case = json.loads(path.read_text())
            source = f"{case['description'].get('source', '?')}/{case['maps']}"
            bent: set[str] = set()  # robots a wrong decision has already bent (below)
            for item in case.get("closures", []) if kind else []:
                if item["kind"] != "weighed":
                    continue  # accepted closures and joins, judged (the weighed ones are here)
                if item["robot"] in bent:
                    # After a wrong decision was weighed (and, with the gate open, made), the
                    # robot's map is bent by it and every later decision is judged against a
                    # truth its map no longer holds: the first wrong one counts, not its
                    # consequences (generated building 1: 1 wrong join, then 100 "wrong").
                    continue
                if not item["right"]:
                    bent.add(item["robot"])
                if item["weighed_kind"] != kind:
                    continue
                keys = ("score", "rival", "conflict", "wall", "matched")
                way = {k: item[k] for k in keys if k in item}
                values = _features([way, way], 0.0)
                if PRIOR_FEATURE in item:  # a loop closure's graph prior
                    values.append(float(item[PRIOR_FEATURE]))
                rows.append(values)
                labels.append(bool(item["right"]))
                groups.append(case["scenario"])
                sources.append(f"{source}/{item['weighed_kind']}")
            for update in case["updates"] if decisions == "merger" else []:
                for record in update["verdicts"]:
                    values = features_of(record)
                    if values is None or not record.get("judged", True):
                        continue
                    if record.get("symmetry_image", False):
                        continue  # the building's own symmetry: no map can tell (module doc)
                    key = (path.stem, tuple(record["pair"]), tuple(np.round(values, 3)))
                    if key in seen:
                        continue
                    seen.add(key)
                    rows.append(values)
                    labels.append(bool(record["right"]))
                    groups.append(case["scenario"])
                    sources.append(source)
    if len({len(row) for row in rows}) > 1:
        raise SystemExit(
            f"the {decisions} decisions of {works} are recorded with and without "
            f"{PRIOR_FEATURE}: collect them again with one version of the back end"
        )
    return np.array(rows, dtype=np.float64), np.array(labels), groups, sources


# The sign each feature's weight may take: more wall no rival explains never makes a
# placement less likely, a rival closer in score or more wall in free space never more likely.
# Without it, correlated features (the conflict and its share) took opposite signs and a fit
# held out gave P 0.994 to a placement its rival outscored (aces 8).
SIGNS = {
    "margin": 1,
    "log_margin": 1,
    "log_score": 0,
    "rival_ratio": -1,
    "conflict": -1,
    "conflict_share": -1,
}
# The back end's decisions are mostly right whatever their evidence (most candidates the
# graph's prediction and the match's confidence let through are): free to take any sign, the
# score's weight went negative against the margin's, and a placement that explains no wall
# (score 0, 12.8 m of it in free space) was given 0.99 (csail 2). More wall explained never
# makes a decision less likely.
BACKEND_SIGNS = {**SIGNS, "log_score": 1}
# A loop closure the robot's graph predicts better than a look-alike is never less likely.
CLOSURE_SIGNS = {**BACKEND_SIGNS, PRIOR_FEATURE: 1}


def fit(x: np.ndarray, y: np.ndarray, l2: float, signs: dict[str, int] = SIGNS) -> LogisticModel:
    """Maximum-likelihood logistic regression, L2 penalty on standardised features, each
    weight of the sign ``signs`` allows (the features of ``x`` are ``signs``' keys in order,
    a prefix of FEATURES): the model on the raw features."""
    names = tuple(signs)[: x.shape[1]]
    mean, scale = x.mean(axis=0), x.std(axis=0) + 1e-9
    design = np.column_stack((np.ones(len(x)), (x - mean) / scale))
    target = y.astype(float)

    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        logits = design @ w
        p = 1.0 / (1.0 + np.exp(-np.clip(logits, -50, 50)))
        nll = np.sum(np.logaddexp(0.0, logits) - target * logits)
        penalty = 0.5 * l2 * len(y) * np.sum(w[1:] ** 2)
        grad = design.T @ (p - target) + l2 * len(y) * np.concatenate(([0.0], w[1:]))
        return float(nll + penalty), grad

    bounds = [(None, None)] + [
        (0.0, None) if signs[n] > 0 else (None, 0.0) if signs[n] < 0 else (None, None)
        for n in names
    ]
    w = minimize(loss, np.zeros(design.shape[1]), jac=True, method="L-BFGS-B", bounds=bounds).x
    weights = w[1:] / scale
    return LogisticModel(names, float(w[0] - weights @ mean), weights)


def held_out(
    x: np.ndarray, y: np.ndarray, groups: list[str], l2: float, signs: dict[str, int] = SIGNS
) -> np.ndarray:
    """Each set's probability from the fit on the folds without its scenario."""
    names = sorted(set(groups))
    rng = np.random.default_rng(0)
    fold_of = {
        name: int(k) for name, k in zip(names, rng.permutation(len(names)) % FOLDS, strict=True)
    }
    fold = np.array([fold_of[g] for g in groups])
    out = np.zeros(len(y))
    for k in range(FOLDS):
        test = fold == k
        if not test.any():
            continue
        train = ~test
        if y[train].all() or not y[train].any():
            out[test] = float(y[train].mean())
            continue
        out[test] = fit(x[train], y[train], l2, signs).probabilities(x[test])
    return out


def log_loss(p: np.ndarray, y: np.ndarray) -> float:
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return float(-np.mean(y * np.log(p) + (1 - y) * np.log(1 - p)))


def reliability(p: np.ndarray, y: np.ndarray) -> list[tuple[float, float, float, int]]:
    """(bin low, bin high, mean predicted, observed share right, count) over probability bins."""
    edges = [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 0.99, 0.999, 1.0 + 1e-9]
    out = []
    for lo, hi in itertools.pairwise(edges):
        inside = (p >= lo) & (p < hi)
        if inside.any():
            out.append(
                (
                    lo,
                    min(hi, 1.0),
                    float(p[inside].mean()),
                    float(y[inside].mean()),
                    int(inside.sum()),
                )
            )
    return out


def print_held_out(p: np.ndarray, y: np.ndarray, sources: list[str]) -> None:
    """The held-out reliability table, and per source what each threshold accepts."""
    print("\n| predicted | mean predicted | observed right | sets |\n| --- | --- | --- | --- |")
    for lo, hi, mean, observed, count in reliability(p, y):
        print(f"| {lo:g}-{hi:g} | {mean:.4f} | {observed:.4f} | {count} |")
    print(
        "\n| source | threshold | accepted | wrong among accepted | right sets accepted (recall) |"
    )
    print("| --- | --- | --- | --- | --- |")
    for source in [*sorted(set(sources)), "all"]:
        mine = np.array([s == source or source == "all" for s in sources])
        for threshold in THRESHOLDS:
            accepted = mine & (p >= threshold)
            wrong = int((accepted & ~y).sum())
            recall = (accepted & y).sum() / max(1, (mine & y).sum())
            print(f"| {source} | {threshold:g} | {int(accepted.sum())} | {wrong} | {recall:.3f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", nargs="*", default=[str(OUTPUT / "decisions")])
    parser.add_argument("--write", action="store_true")
    parser.add_argument("--figure", default="")
    parser.add_argument(
        "--show", type=float, default=0.99, help="list the wrong sets held out at least this sure"
    )
    parser.add_argument(
        "--decisions", choices=("merger", "closure", "piece_join"), default="merger"
    )
    args = parser.parse_args()
    x, y, groups, sources = load(args.work, args.decisions)
    if len(y) == 0:
        raise SystemExit("no recorded sets: run bench/decisions.py collect first")
    print(
        f"{len(y)} sets ({int(y.sum())} right, {int((~y).sum())} wrong) from "
        f"{len(set(groups))} scenarios"
    )
    signs = {"merger": SIGNS, "closure": CLOSURE_SIGNS}.get(args.decisions, BACKEND_SIGNS)
    names = tuple(signs)[: x.shape[1]]
    losses = {l2: log_loss(held_out(x, y, groups, l2, signs), y) for l2 in L2_GRID}
    l2 = min(losses, key=losses.__getitem__)
    print(
        "held-out log loss by penalty: " + ", ".join(f"{k:g}: {v:.4f}" for k, v in losses.items())
    )
    p = held_out(x, y, groups, l2, signs)
    print_held_out(p, y, sources)
    doubtful = np.flatnonzero((p >= args.show) & ~y)
    for k in doubtful:
        print(
            f"held out, P {p[k]:.4f} but wrong: {groups[k]} ({sources[k]}), features "
            + ", ".join(f"{n} {v:.2f}" for n, v in zip(names, x[k], strict=True))
        )
    model = fit(x, y, l2, signs)
    print(
        "\nfit on every set: intercept "
        + f"{model.intercept:.5g}, "
        + ", ".join(f"{n} {w:.5g}" for n, w in zip(model.features, model.weights, strict=True))
    )
    if args.write:
        written = LogisticModel(
            names,
            round(model.intercept, 6),
            tuple(round(float(w), 6) for w in model.weights),
            f"bench/fit_join.py on {date.today().isoformat()}: {len(y)} sets of "
            f"{len(set(groups))} scenarios ({', '.join(sorted(set(sources)))}), L2 {l2:g}",
        )
        name = {
            "merger": MODEL_FILE,
            "closure": CLOSURE_MODEL_FILE,
            "piece_join": PIECE_JOIN_MODEL_FILE,
        }[args.decisions]
        path = REPO / "multi_robot_mapper" / "core" / "evidence" / name
        path.write_text(written.dumps())
        print(f"wrote {path}")
    if args.figure:
        title = {"merger": "join model", "closure": "loop closure model"}.get(
            args.decisions, "join-of-pieces model"
        )
        draw(p, y, args.figure, f"{title} reliability")


def draw(p: np.ndarray, y: np.ndarray, path: str, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bins = reliability(p, y)
    fig, ax = plt.subplots(figsize=(5, 5))
    ax.plot([0, 1], [0, 1], color="grey", lw=0.8)
    ax.plot([b[2] for b in bins], [b[3] for b in bins], "o-")
    for b in bins:
        ax.annotate(
            str(b[4]), (b[2], b[3]), textcoords="offset points", xytext=(4, -10), fontsize=7
        )
    ax.set_xlabel("predicted P(right), held out by scenario")
    ax.set_ylabel("observed share right")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
