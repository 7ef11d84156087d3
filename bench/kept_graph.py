"""The joint graph kept between merge updates against the graph solved afresh (issue 50).

    .venv/bin/python -m bench.kept_graph [--log intel] [--robots 8] [--every 10]
        [--thresholds 0.01 0.001 0.0001]

Runs ``bench.merge_speed``'s live regime (the log cut into ``--robots`` runs driving at once,
an update every ``--every`` seconds of their runs) and keeps every graph its updates solve
(:class:`~multi_robot_mapper.core.merging.kept_graph.GraphSpec`). Then solves that sequence
again, update after update: afresh from the rigid start (Levenberg-Marquardt, the code before
the graph was kept), and kept (ISAM2) at each relinearisation threshold. Prints, per way, the
CPU seconds per update (median, p95, max), and against each graph's optimum (Levenberg-
Marquardt to a relative tolerance of 1e-12): the cost above it (relative) and how far the
farthest keyframe lies from it.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
from unittest import mock  # noqa: E402

import gtsam  # noqa: E402
import numpy as np  # noqa: E402

from bench.merge_speed import live_joint  # noqa: E402
from multi_robot_mapper.core.merging import joint_graph, kept_graph  # noqa: E402
from multi_robot_mapper.core.merging.config import MergeConfig  # noqa: E402
from multi_robot_mapper.core.merging.kept_graph import GraphSpec, KeptGraph, NodeName  # noqa: E402
from multi_robot_mapper.core.pose_graph import Edge, PoseGraph  # noqa: E402

Poses = dict[NodeName, tuple[float, float, float]]


def captured(log: str, robots: int, every: float) -> list[GraphSpec]:
    """Every graph the live regime's updates solve, in order."""
    specs: list[GraphSpec] = []
    solve = joint_graph._brought_up_to_date

    def capture(kept: KeptGraph | None, spec: GraphSpec) -> KeptGraph:
        specs.append(spec)
        return solve(kept, spec)

    with mock.patch.object(joint_graph, "_brought_up_to_date", capture):
        live_joint(log, robots, 40, MergeConfig(), every)
    return specs


def solved_in_turn(specs: list[GraphSpec], kept: bool) -> tuple[list[float], list[Poses]]:
    """Each graph solved after the last, kept or afresh: CPU seconds and poses of each."""
    graph: KeptGraph | None = None
    seconds, poses = [], []
    for spec in specs:
        began = time.process_time()
        if kept and graph is not None and graph.carries(spec):
            graph.update(spec)
        else:
            graph = KeptGraph(spec)
        seconds.append(time.process_time() - began)
        estimate = graph.graph.poses()
        poses.append({name: estimate[graph.keys[name]] for name in spec.nodes})
    return seconds, poses


def optimum(spec: GraphSpec) -> Poses:
    """The graph's optimum: Levenberg-Marquardt from the rigid start to a relative tolerance
    of 1e-12."""
    graph = KeptGraph(spec)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    params.setMaxIterations(100)
    whole, start = graph.graph._whole_graph(), graph.graph._values()
    values = gtsam.LevenbergMarquardtOptimizer(whole, start, params).optimize()
    return {
        name: (values.atPose2(key).x(), values.atPose2(key).y(), values.atPose2(key).theta())
        for name, key in graph.keys.items()
    }


def cost(spec: GraphSpec, poses: Poses) -> float:
    """The graph's cost at ``poses``, its edges alone (free of the anchor: of the frame)."""
    graph = PoseGraph(spec.robust_scale, "dcs")
    index = {name: i for i, name in enumerate(spec.nodes)}
    for name, i in index.items():
        graph.add_node(i, poses[name])
    for e in spec.edges:
        edge = Edge(index[e.first], index[e.second], e.T_first_second, e.information, e.robust)
        graph.add_edge(edge)
    return graph.objective()


def report(
    way: str, specs: list[GraphSpec], solved: tuple[list[float], list[Poses]], best: list[Poses]
) -> None:
    seconds, poses = solved
    above, off = [], []
    for spec, got, want in zip(specs, poses, best, strict=True):
        ideal = cost(spec, want)
        above.append((cost(spec, got) - ideal) / max(ideal, 1e-12))
        off.append(
            max(float(np.hypot(got[n][0] - want[n][0], got[n][1] - want[n][1])) for n in spec.nodes)
        )
    t, a, o = np.array(seconds), np.array(above), np.array(off)
    print(
        f"| {way} | {len(t)} | {np.median(t):.3f} / {np.percentile(t, 95):.3f} / {t.max():.3f} | "
        f"{np.median(a):.1e} / {np.percentile(a, 95):.1e} / {a.max():.1e} | "
        f"{np.median(o) * 1e3:.2f} / {np.percentile(o, 95) * 1e3:.2f} / {o.max() * 1e3:.2f} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--log", default="intel")
    parser.add_argument("--robots", type=int, default=8)
    parser.add_argument("--every", type=float, default=10.0)
    parser.add_argument("--thresholds", type=float, nargs="+", default=[0.01, 0.001, 0.0001])
    args = parser.parse_args()
    specs = captured(args.log, args.robots, args.every)
    best = [optimum(spec) for spec in specs]
    print(
        "| way | updates | CPU s median / p95 / max | cost above the optimum, median / p95 / max "
        "| farthest keyframe from it (mm), median / p95 / max |"
    )
    print("| --- | --- | --- | --- | --- |")
    report(
        "afresh (Levenberg-Marquardt from the rigid start)",
        specs,
        solved_in_turn(specs, False),
        best,
    )
    for threshold in args.thresholds:
        with mock.patch.object(kept_graph, "_RELINEARIZE", threshold):
            report(
                f"kept (ISAM2, relinearise at {threshold:g})",
                specs,
                solved_in_turn(specs, True),
                best,
            )


if __name__ == "__main__":
    main()
