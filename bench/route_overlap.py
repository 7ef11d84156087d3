"""The overlap robots' routes really have in generated buildings, for each overlap level asked.

For each plan kind and level (none, small, large), ``--buildings`` buildings drawn from seeds
(sizes drawn from the seed, 20-200 m), ``--robots`` routes of ``--length`` m each; the shared
ground of a robot is the share of its route within 0.5 m of another robot's
(:func:`shared_ground`, the largest over the others). Prints the mean and the 10th-90th
percentiles over robots.

    .venv/bin/python -m bench.route_overlap [--buildings 30] [--robots 3] [--length 80]
"""

from __future__ import annotations

import argparse

import numpy as np

from multi_robot_mapper.core.building_runs import OVERLAP_LEVELS, plan_routes, shared_ground
from multi_robot_mapper.core.buildings import PLAN_KINDS, generate_building


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--buildings", type=int, default=30, help="per kind (default 30)")
    parser.add_argument("--robots", type=int, default=3, help="robots (default 3)")
    parser.add_argument("--length", type=float, default=80.0, help="route length, m (default 80)")
    args = parser.parse_args()
    k = args.robots
    print(
        f"shared ground per robot (mean [p10, p90]), {args.buildings} buildings per kind, "
        f"{k} robots, routes of {args.length:g} m"
    )
    print(
        f"  {'kind':16s}"
        + "".join(f"{level + ' (' + str(v) + ')':>22s}" for level, v in OVERLAP_LEVELS.items())
    )
    for kind in PLAN_KINDS:
        cells = []
        for overlap in OVERLAP_LEVELS.values():
            shares = []
            for seed in range(args.buildings):
                building = generate_building(seed, kind=kind)
                paths = plan_routes(building, k, args.length, overlap, seed=seed)
                matrix = shared_ground(paths)
                shares.extend(matrix[~np.eye(k, dtype=bool)].reshape(k, k - 1).max(axis=1))
            p10, p90 = np.percentile(shares, [10, 90])
            cells.append(f"{np.mean(shares):.2f} [{p10:.2f}, {p90:.2f}]")
        print(f"  {kind:16s}" + "".join(f"{c:>22s}" for c in cells))


if __name__ == "__main__":
    main()
