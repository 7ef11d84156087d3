"""``make demo`` run again and again (issue 46): does any frame of ``joining.gif`` (or of
``joining.png``) show a robot placed wrong?

    .venv/bin/python -m bench.demo_runs [--runs 20] [--out bench_output/demo_runs]

Each run is the demo itself (``cli.demo.run_demo``: three simulated robots mapped and merged
live by the real nodes, over DDS), in its own folder. Every global map the demo drew --
the frames of ``joining.gif`` (one a second) and the snapshots of ``joining.png`` -- is
judged against the simulator's walls: the frame is put in ``world`` by the best of its possible
alignments (``map`` is one robot's own frame: each robot's true start pose, refined by ICP on
the frame's walls; :func:`judge_frame`), and a robot is
*placed wrong* in a frame when less than half of its walls (points every 0.1 m) lie within
0.30 m of a true wall there. Prints one line per run (robots merged at the end, frames,
frames with a robot placed wrong, the worst share) and the totals.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from bench.harness import OUTPUT
from multi_robot_mapper.cli.demo import (
    DemoScenario,
    every_second,
    joining_views,
    run_demo,
    simulate_scenario,
)
from multi_robot_mapper.core import se2
from multi_robot_mapper.core.geometry import sample_segments
from multi_robot_mapper.core.worlds import WORLDS

ON_A_WALL = 0.30  # m
RIGHT_SHARE = 0.5  # of a robot's wall points on a true wall: placed right


def fit_to_walls(
    points: np.ndarray, walls: cKDTree, wall_points: np.ndarray, T: np.ndarray
) -> np.ndarray:
    """T_world_map refined so that ``points`` (in map) lie on the walls: point-to-point ICP,
    pairs within 1 m, from ``T``."""
    for _ in range(30):
        placed = se2.transform_points(T, points)
        distance, index = walls.query(placed, distance_upper_bound=1.0)
        near = np.isfinite(distance)
        if near.sum() < 10:
            break
        T = se2.fit_points(points[near], wall_points[index[near]])
    return T


def judge_frame(
    segments: dict[str, np.ndarray],
    walls: cKDTree,
    wall_points: np.ndarray,
    starts: list[np.ndarray],
) -> dict[str, float]:
    """Each robot's share of wall points on a true wall, under the best of the frame's possible
    alignments to ``world``. The merger's ``map`` is always one robot's own frame (its first
    scan's pose; which robot can change as groups join), so each robot's true start pose is a
    candidate ``T_world_map``, refined by ICP on every robot's walls; the candidate whose worst
    robot lies best on the walls is the frame's. A frame whose robots are placed right relative
    to each other has a candidate under which every one lies on the walls."""
    shown = {r: s for r, s in segments.items() if len(s)}
    if not shown:
        return {}
    points = {r: sample_segments(s, 0.1)[0] for r, s in shown.items()}
    every = np.vstack(list(points.values()))
    best: dict[str, float] = {}
    for T_start in starts:
        T = fit_to_walls(every, walls, wall_points, T_start)
        shares = {
            robot: float(np.mean(walls.query(se2.transform_points(T, p))[0] <= ON_A_WALL))
            for robot, p in points.items()
        }
        if not best or min(shares.values()) > min(best.values()):
            best = shares
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--out", default=str(OUTPUT / "demo_runs"))
    args = parser.parse_args()
    wall_points = sample_segments(WORLDS[DemoScenario().world](), 0.05)[0]
    walls = cKDTree(wall_points)
    # Each robot's frame in world: the true pose of its first scan (the demo's scans are the
    # same every run: one seed).
    robot_starts = [
        se2.matrix_from_pose(*recording.ground_truth[0].pose)
        for recording in simulate_scenario(DemoScenario()).values()
    ]
    total_frames = wrong_frames = merged_all = 0
    for run in range(args.runs):
        result = run_demo(Path(args.out) / f"run{run:02d}")
        views = result.live.observer.global_maps
        frames = {id(v): v for v in [*every_second(views), *joining_views(views)]}
        starts = [np.asarray(result.metrics.T_ref_map), *robot_starts]  # map -> world
        worst, wrong = 1.0, 0
        for view in frames.values():
            shares = judge_frame(view.segments, walls, wall_points, starts)
            low = [s for s in shares.values() if s < RIGHT_SHARE]
            wrong += bool(low)
            worst = min([worst, *shares.values()])
        total_frames += len(frames)
        wrong_frames += wrong
        merged_all += len(result.merged) == len(result.robots)
        print(
            f"run {run}: {len(result.merged)}/{len(result.robots)} merged, {len(frames)} frames, "
            f"{wrong} with a robot placed wrong, worst share on a wall {worst:.2f}, "
            f"{result.wall_s:.0f} s",
            flush=True,
        )
    print(
        f"{args.runs} runs: every robot merged in {merged_all}; {wrong_frames} of {total_frames} "
        "frames show a robot placed wrong"
    )


if __name__ == "__main__":
    main()
