"""Fit and check the match confidence (issue 11): a logistic model of P(right) from evidence.

Two steps, each its own command:

    .venv/bin/python -m bench.fit_confidence collect [--logs intel aces ...] [--jobs 2]
    .venv/bin/python -m bench.fit_confidence fit [--write] [--out bench_output/confidence]

``collect`` matches pairs of every shared log with INTEGRATE (no guess, both sides' views)
and stores each pair's raw evidence (:meth:`MatchEvidence.as_array`), its kind and whether the
match is right (within 0.30 m / 5 deg of the reference) in ``OUT/<log>.npz``. Pair kinds, so
that the model sees what the mappers ask of it:

- ``consecutive``: scan k and k+1 (the pair bench; on the dense freiburg-079, every 3rd k);
- ``gap2``, ``gap3``: k and k+2, k+3 (a scan set aside in between; larger motions). On the
  dense freiburg-079 the gaps are 5 and 10 scans (0.5 and 1 m: keyframe spacing);
- ``revisit``: scans far apart in time whose reference poses are within 1.5 m and 60 deg
  (what a loop closure matches);
- ``unrelated``: scans whose reference poses are more than 15 m apart (no overlap: any
  answer is wrong; an unrelated room must get a low confidence);
- ``predicted``: consecutive scans refined from a prediction alone (the true motion off by
  10 cm and 3 deg), no search: what a tracker asks;
- ``window_adjacent``, ``window_revisit``, ``window_unrelated``: windows of three scans
  (keyframe-spaced on freiburg-079), each fused in its first scan's frame with all three
  scans' beams: the end of a stretch against the start of the next (a join after the robot
  was lost), revisits, unrelated places (what a join of pieces and a merger match).

``fit`` fits the model (L2-regularised logistic regression, scipy) on all logs but one and
checks it on the one left out, in turn. The penalty is ``--l2`` (default :data:`L2`, the
deployed model's); ``--l2 cv`` takes the one of :data:`L2_GRID` whose fits predict the logs
they were not fitted on best (mean held-out log loss, leaving each training log out in turn),
chosen on the training logs alone for each log checked, and on every log for a model written
(README, "Match confidence": it predicts the held-out pairs better, and was not deployed, as
the merger and the joins of pieces did worse with it end to end). The check reports: log
loss, Brier score, and precision / recall of "confidence >= threshold" for each use's
threshold, on the consecutive pairs (the pair
bench) and on all pairs, and at the integration threshold the precision **judged** on both:
pairs wrong only by the reference (``reference_check.ReferenceJudge``) counted right. It
draws the reliability diagram (predicted against observed success, in bins, every log left
out in turn) and the precision/recall curves to
``OUT/reliability.png`` and ``OUT/precision_recall.png``. ``--write`` writes the model fitted
on every log into ``multi_robot_mapper/core/matching/confidence_model.json`` (data the
package loads, with how and on what it was fitted).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import datetime  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

from bench.harness import FIT_LOGS, OUTPUT, REPO, carmen_log  # noqa: E402
from bench.reference_check import ReferenceJudge, judge_of_log  # noqa: E402
from multi_robot_mapper.core import se2  # noqa: E402
from multi_robot_mapper.core.extraction import extract_scan  # noqa: E402
from multi_robot_mapper.core.extraction_config import ExtractionConfig  # noqa: E402
from multi_robot_mapper.core.fusion import fuse  # noqa: E402
from multi_robot_mapper.core.local_mapping import LocalMapperConfig  # noqa: E402
from multi_robot_mapper.core.logistic import LogisticModel  # noqa: E402
from multi_robot_mapper.core.matching import IntegrateConfig, integrate  # noqa: E402
from multi_robot_mapper.core.matching.beams import Viewpoint, Views  # noqa: E402
from multi_robot_mapper.core.matching.confidence import (  # noqa: E402
    FEATURES,
    MatchEvidence,
    is_right,
    scan_model_json,
)
from multi_robot_mapper.core.matching.confidence import (  # noqa: E402
    MODEL_FILE as CONFIDENCE_MODEL_FILE,
)
from multi_robot_mapper.core.matching.integrate import match_evidence  # noqa: E402
from multi_robot_mapper.core.matching.scoring import pair_tolerance  # noqa: E402
from multi_robot_mapper.io.carmen import carmen_scan_data, read_carmen  # noqa: E402

DENSE = ("freiburg-079",)
# The fitted model, data the package loads (core/matching/confidence.installed_scan_model).
MODEL_FILE = REPO / "multi_robot_mapper" / "core" / "matching" / CONFIDENCE_MODEL_FILE
KINDS = (
    "consecutive",
    "gap2",
    "gap3",
    "revisit",
    "unrelated",
    "predicted",
    "window_adjacent",
    "window_revisit",
    "window_unrelated",
)
WINDOW = 3  # scans per window
WINDOW_SAMPLES = 150  # revisit and unrelated window pairs per log
RAW = 19  # numbers of MatchEvidence.as_array
SAMPLES = 300  # revisit and unrelated pairs per log
# The local mapper's threshold for integrating a scan, where precision is judged.
INTEGRATE_CONFIDENCE = LocalMapperConfig().integrate_confidence
L2 = 1e-2  # regularisation of the logistic fit (per pair, on standardised features)
# Penalties tried by ``--l2 cv`` (choose_l2): held-out log loss is least at 1e-4-3e-4, but the
# model fitted so cost the merger its links on freiburg-079 (README, "Match confidence").
L2_GRID = (1e-5, 3e-5, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1)


Pair = tuple[str, tuple[int, ...], tuple[int, ...]]  # kind, scans of A (anchor first), of B


def pairs_of(name: str, poses: np.ndarray) -> list[Pair]:
    """Every (kind, A, B) pair of one log (deterministic): A and B are windows of scans, the
    first of each its anchor (single scans for the scan kinds)."""
    n = len(poses)
    rng = np.random.default_rng(7)
    out: list[Pair] = []
    dense = name in DENSE
    if dense:
        steps = {"consecutive": (1, 3), "gap2": (5, 3), "gap3": (10, 3)}
        for kind, (gap, every) in steps.items():
            out += [(kind, (k,), (k + gap,)) for k in range(0, n - gap, every)]
    else:
        for kind, gap in (("consecutive", 1), ("gap2", 2), ("gap3", 3)):
            out += [(kind, (k,), (k + gap,)) for k in range(n - gap)]
    # What a tracker asks: the motion refined from a prediction (the true motion, off by a
    # constant-velocity error), no search.
    consecutive = [(a, b) for kind, a, b in out if kind == "consecutive"]
    out += [("predicted", a, b) for a, b in consecutive[:: 2 if dense else 1]]
    xy = poses[:, :2]
    distance = np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])
    turn = np.abs(se2.wrap_angle(poses[:, None, 2] - poses[None, :, 2]))
    i, j = np.triu_indices(n, k=1)
    apart = j - i > (100 if dense else 20)
    revisit = np.flatnonzero(apart & (distance[i, j] < 1.5) & (turn[i, j] < np.radians(60)))
    unrelated = np.flatnonzero(distance[i, j] > 15.0)
    for kind, chosen in (("revisit", revisit), ("unrelated", unrelated)):
        if chosen.size > SAMPLES:
            chosen = rng.choice(chosen, SAMPLES, replace=False)
        out += [(kind, (int(i[c]),), (int(j[c]),)) for c in np.sort(chosen)]
    # Windows of WINDOW scans (keyframe-spaced on the dense log): the end of one stretch
    # against the start of the next (a join after the robot was lost), revisits, unrelated.
    step = 5 if dense else 1
    span = step * (WINDOW - 1)

    def around(k: int) -> tuple[int, ...]:
        return tuple(int(v) for v in np.clip(k + step * np.arange(WINDOW) - span // 2, 0, n - 1))

    for k in range(span, n - span - step, 15 if dense else 2):
        a = tuple(range(k, k - span - 1, -step))  # anchor k, then the scans before it
        b = tuple(range(k + step, k + step + span + 1, step))
        out.append(("window_adjacent", a, b))
    for kind, chosen in (("window_revisit", revisit), ("window_unrelated", unrelated)):
        if chosen.size > WINDOW_SAMPLES:
            chosen = rng.choice(chosen, WINDOW_SAMPLES, replace=False)
        out += [(kind, around(int(i[c])), around(int(j[c]))) for c in np.sort(chosen)]
    return out


def collect_log(name: str, out_dir: Path) -> str:
    path = carmen_log(name)
    if not path.is_file():
        return f"{name}: skipped, {path} not found"
    started = time.perf_counter()
    scans = list(read_carmen(path))
    views = [carmen_scan_data(s) for s in scans]
    segments = [extract_scan(v, ExtractionConfig())[0].segments for v in views]
    poses = np.array([s.reference_pose for s in scans])
    config = IntegrateConfig()
    rows, at_truth, kinds, right, times, errors = [], [], [], [], [], []
    anchors, found = [], []  # (scan of A, scan of B) and the placement found, per pair
    nothing = MatchEvidence.from_array(np.zeros(RAW))
    rng = np.random.default_rng(11)

    def window(scans_: tuple[int, ...]) -> tuple[np.ndarray, list[Viewpoint]]:
        """The window's segments fused in its anchor's frame, and its viewpoints."""
        anchor = se2.invert(se2.matrix_from_pose(*poses[scans_[0]]))
        fused, owner = np.zeros((0, 4)), np.zeros(0, dtype=np.int64)
        viewpoints = []
        for k in scans_:
            T = anchor @ se2.matrix_from_pose(*poses[k])
            placed = se2.transform_segments(T, segments[k])
            fused, owner = fuse(
                fused, owner, placed, np.full(len(placed), k), pair_tolerance(config), 0.02
            )
            viewpoints.append(Viewpoint(views[k], T))
        return fused, viewpoints

    for kind, a, b in pairs_of(name, poses):
        T_truth = se2.invert(se2.matrix_from_pose(*poses[a[0]])) @ se2.matrix_from_pose(
            *poses[b[0]]
        )
        x, y, theta = se2.pose_from_matrix(T_truth)
        if len(a) == 1:
            seg_a, seg_b = segments[a[0]], segments[b[0]]
            view_a: Views = views[a[0]]
            view_b: Views = views[b[0]]
        else:
            seg_a, view_a = window(a)
            seg_b, view_b = window(b)
        t0 = time.perf_counter()
        if kind == "predicted":
            # A constant-velocity prediction is off by about a tenth of the motion, and turns.
            off = np.array([theta, x, y]) + rng.normal(0.0, [0.05, 0.1, 0.1])
            result = integrate(
                seg_a,
                seg_b,
                config,
                heuristics=(),
                extra_hypotheses=off[None],
                views=(view_a, view_b),
            )
        else:
            result = integrate(seg_a, seg_b, config, views=(view_a, view_b))
        times.append(time.perf_counter() - t0)
        ok = "unrelated" not in kind and is_right(result.matrix, T_truth)
        rows.append((result.evidence or nothing).as_array())
        # The beams at the reference placement: where they contradict it far more than the
        # match, the reference itself is wrong (reported, never used to relabel).
        truth = match_evidence(
            seg_a,
            seg_b,
            np.array([theta, x, y]),
            (view_a, view_b),
            config,
            score=0.0,
            rival_score=0.0,
            support=0.0,
            fraction=0.0,
        )
        at_truth.append(truth.as_array())
        dx, dy, dth = se2.pose_from_matrix(se2.invert(T_truth) @ result.matrix)
        kinds.append(KINDS.index(kind))
        right.append(ok)
        errors.append((np.hypot(dx, dy), abs(dth)))
        anchors.append((a[0], b[0]))
        found.append(se2.pose_from_matrix(result.matrix))
    np.savez_compressed(
        out_dir / f"{name}.npz",
        evidence=np.array(rows),
        evidence_at_truth=np.array(at_truth),
        kind=np.array(kinds),
        right=np.array(right),
        seconds=np.array(times),
        error=np.array(errors),
        anchors=np.array(anchors, dtype=np.int64),
        found=np.array(found),
    )
    return (
        f"{name}: {len(rows)} pairs, right {np.mean(right):.3f}, "
        f"{time.perf_counter() - started:.0f} s"
    )


def load(out_dir: Path, logs: list[str]) -> dict[str, dict[str, np.ndarray]]:
    data = {}
    for name in logs:
        path = out_dir / f"{name}.npz"
        if not path.is_file():
            print(f"{name}: no {path}; run 'collect' first", file=sys.stderr)
            continue
        with np.load(path) as f:
            entry = {k: f[k] for k in f.files}
        entry["features"] = np.array(
            [MatchEvidence.from_array(raw).features() for raw in entry["evidence"]]
        )
        data[name] = entry
    return data


def fit_logistic(x: np.ndarray, y: np.ndarray, l2: float) -> LogisticModel:
    """Maximum-likelihood logistic regression with an L2 penalty on standardised features."""
    mean, scale = x.mean(axis=0), x.std(axis=0) + 1e-9
    z = (x - mean) / scale
    design = np.column_stack((np.ones(len(z)), z))

    def loss(w: np.ndarray) -> tuple[float, np.ndarray]:
        logits = design @ w
        p = 1.0 / (1.0 + np.exp(-logits))
        nll = np.sum(np.logaddexp(0.0, logits) - y * logits)
        penalty = 0.5 * l2 * len(y) * np.sum(w[1:] ** 2)
        grad = design.T @ (p - y) + l2 * len(y) * np.concatenate(([0.0], w[1:]))
        return float(nll + penalty), grad

    w = minimize(loss, np.zeros(design.shape[1]), jac=True, method="L-BFGS-B").x
    weights = w[1:] / scale
    return LogisticModel(FEATURES, float(w[0] - np.dot(weights, mean)), weights)


def held_out_log_loss(data: dict[str, dict[str, np.ndarray]], l2: float) -> float:
    """Mean over the logs of ``data`` of the log loss on each, of the fit on the others with
    penalty ``l2`` (each log counts once, whatever its number of pairs: a building the model
    has not seen is the case to predict)."""
    losses = []
    for name, test in data.items():
        train = [d for n, d in data.items() if n != name]
        x = np.vstack([d["features"] for d in train])
        y = np.concatenate([d["right"] for d in train]).astype(float)
        p = np.clip(fit_logistic(x, y, l2).probabilities(test["features"]), 1e-12, 1.0 - 1e-12)
        yt = test["right"].astype(float)
        losses.append(float(np.mean(-(yt * np.log(p) + (1.0 - yt) * np.log(1.0 - p)))))
    return float(np.mean(losses))


def choose_l2(data: dict[str, dict[str, np.ndarray]]) -> float:
    """The penalty of :data:`L2_GRID` with the least :func:`held_out_log_loss` on ``data``."""
    return min(L2_GRID, key=lambda l2: held_out_log_loss(data, l2))


def precision_recall(p: np.ndarray, y: np.ndarray, threshold: float) -> tuple[float, float]:
    accepted = p >= threshold
    precision = float(y[accepted].mean()) if accepted.any() else float("nan")
    recall = float(accepted[y].mean()) if y.any() else float("nan")
    return precision, recall


def judged_precision(
    name: str, test: dict[str, np.ndarray], p: np.ndarray, among: np.ndarray
) -> tuple[float, int] | None:
    """Precision of "confidence >= integrate_confidence" on the pairs ``among`` (a mask), with
    the pairs wrong only by the reference counted right (``reference_check.ReferenceJudge``:
    right once the reference of their anchor scans is replaced by the pose the scans either
    side agree on; the labels of the fit stay the reference's), and how many those are. Pairs
    of unrelated places stay wrong whatever the reference. None for data collected before
    pairs were stored with their scans."""
    if "anchors" not in test:
        return None
    accepted = among & (p >= INTEGRATE_CONFIDENCE)
    if not accepted.any():
        return float("nan"), 0
    unrelated = np.isin(test["kind"], [KINDS.index(k) for k in KINDS if "unrelated" in k])
    suspects = np.flatnonzero(accepted & ~test["right"].astype(bool) & ~unrelated)
    by_reference = 0
    if len(suspects):
        judge = _judges.get(name)
        if judge is None:
            scans = list(read_carmen(carmen_log(name)))
            judge = _judges[name] = judge_of_log(
                name, [carmen_scan_data(s) for s in scans], [s.reference_pose for s in scans]
            )
        for row in suspects:
            a, b = (int(v) for v in test["anchors"][row])
            x, y, theta = (float(v) for v in test["found"][row])
            verdict = judge.verdict(name, float(a), name, float(b), (x, y, theta))
            by_reference += verdict == "reference"
    right = int(np.count_nonzero(accepted & test["right"].astype(bool)))
    return (right + by_reference) / int(np.count_nonzero(accepted)), by_reference


_judges: dict[str, ReferenceJudge] = {}  # per log, its searches remembered


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("step", choices=("collect", "fit"))
    parser.add_argument("--logs", nargs="+", default=list(FIT_LOGS))
    parser.add_argument("--out", type=Path, default=OUTPUT / "confidence")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--write", action="store_true", help="write the model fitted on all logs")
    parser.add_argument(
        "--thresholds",
        type=float,
        nargs="+",
        default=[0.5, 0.8, 0.9, 0.95, 0.98],
        help="thresholds reported",
    )
    parser.add_argument(
        "--l2",
        default=str(L2),
        help=f"penalty of the fit (default {L2}), or 'cv': chosen by held-out log loss",
    )
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.step == "collect":
        with ProcessPoolExecutor(max_workers=args.jobs) as pool:
            for line in pool.map(collect_log, args.logs, [args.out] * len(args.logs)):
                print(line, flush=True)
        return
    data = load(args.out, args.logs)
    report: dict[str, object] = {}
    held_out_p: dict[str, np.ndarray] = {}
    for name in data:
        others = {n: d for n, d in data.items() if n != name}
        # A penalty chosen by cross-validation is chosen without the log it is checked on.
        l2 = choose_l2(others) if args.l2 == "cv" else float(args.l2)
        x = np.vstack([d["features"] for d in others.values()])
        y = np.concatenate([d["right"] for d in others.values()]).astype(float)
        model = fit_logistic(x, y, l2)
        test = data[name]
        p = model.probabilities(test["features"])
        held_out_p[name] = p
        yt = test["right"].astype(bool)
        consecutive = test["kind"] == KINDS.index("consecutive")
        loss = float(np.mean(np.logaddexp(0.0, -np.where(yt, 1, -1) * np.log(p / (1 - p)))))
        entry: dict[str, object] = {
            "pairs": len(yt),
            "l2": l2,
            "right": float(yt.mean()),
            "consecutive_right": float(yt[consecutive].mean()),
            "log_loss": loss,
            "brier": float(np.mean((p - yt) ** 2)),
        }
        for among, mask in (("consecutive", consecutive), ("all", np.ones_like(consecutive))):
            judged = judged_precision(name, test, p, mask)
            if judged is not None:
                entry[f"{among}_precision_judged"], entry[f"{among}_by_reference"] = judged
        for threshold in args.thresholds:
            pc, rc = precision_recall(p[consecutive], yt[consecutive], threshold)
            pa, ra = precision_recall(p, yt, threshold)
            entry[f"t{threshold}"] = {
                "consecutive_precision": pc,
                "consecutive_recall": rc,
                "all_precision": pa,
                "all_recall": ra,
            }
        report[name] = entry
        print(f"{name} (held out): {json.dumps(entry)}", flush=True)
    (args.out / "cross_validation.json").write_text(json.dumps(report, indent=1) + "\n")
    draw(data, held_out_p, args.out)
    if args.write:
        x = np.vstack([d["features"] for d in data.values()])
        y = np.concatenate([d["right"] for d in data.values()]).astype(float)
        l2 = choose_l2(data) if args.l2 == "cv" else float(args.l2)
        write_model(fit_logistic(x, y, l2), list(data), len(y), l2)
        print(f"wrote {MODEL_FILE.relative_to(REPO)}")


def draw(
    data: dict[str, dict[str, np.ndarray]], held_out: dict[str, np.ndarray], out: Path
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    bins = np.linspace(0.0, 1.0, 11)
    fig, ax = plt.subplots(figsize=(6, 6))
    ax.plot([0, 1], [0, 1], "k:", lw=1, label="perfect calibration")
    for name, p in held_out.items():
        y = data[name]["right"].astype(float)
        which = np.clip(np.digitize(p, bins) - 1, 0, len(bins) - 2)
        centres, observed, sizes = [], [], []
        for b in range(len(bins) - 1):
            inside = which == b
            if inside.sum() >= 5:
                centres.append(p[inside].mean())
                observed.append(y[inside].mean())
                sizes.append(inside.sum())
        ax.plot(centres, observed, "o-", ms=3, label=f"{name} (held out)")
    ax.set_xlabel("predicted P(right)")
    ax.set_ylabel("observed fraction right")
    ax.set_title("Match confidence: reliability, each log left out of the fit")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.savefig(out / "reliability.png", dpi=120, bbox_inches="tight")
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(6, 5))
    for name, p in held_out.items():
        y = data[name]["right"].astype(bool)
        order = np.argsort(-p)
        hits = np.cumsum(y[order])
        precision = hits / np.arange(1, len(y) + 1)
        recall = hits / max(y.sum(), 1)
        ax.plot(recall, precision, label=name)
    ax.set_xlabel("recall (right matches accepted)")
    ax.set_ylabel("precision (accepted matches right)")
    ax.set_ylim(0.8, 1.001)
    ax.set_title("Match confidence: precision / recall, all pair kinds, held out")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.savefig(out / "precision_recall.png", dpi=120, bbox_inches="tight")
    plt.close(fig)


def write_model(model: LogisticModel, logs: list[str], pairs: int, l2: float) -> None:
    """``MODEL_FILE``: the model, its numbers to 6 significant digits, with its provenance."""
    rounded = LogisticModel(
        FEATURES,
        float(f"{model.intercept:.6g}"),
        np.array([float(f"{w:.6g}") for w in model.weights]),
    )
    fitted = (
        f"bench/fit_confidence.py on {datetime.date.today().isoformat()}: {pairs} scan pairs "
        f"of {', '.join(logs)} (kinds: {', '.join(KINDS)}), L2 penalty {l2:g}; calibration "
        "checked leaving each log out in turn (README, 'Match confidence')"
    )
    command = (
        ".venv/bin/python -m bench.fit_confidence collect && "
        ".venv/bin/python -m bench.fit_confidence fit --write"
    )
    MODEL_FILE.write_text(scan_model_json(rounded, fitted, command))


if __name__ == "__main__":
    main()
