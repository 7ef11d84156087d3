"""A picture of generated buildings (``mrm simulate --world generated``): a grid of plans of
every kind, each with three robots' routes at an overlap level, and one simulated scan
beside glass.

Walls black, glass cyan, furniture brown, people's walking lines magenta, the waypoint graph
light grey; each robot's route in its colour, a triangle at its start pointing along its
first heading. Titles give the kind, size, symmetry, overlap level and the ground the robots
really share (:func:`shared_ground`: each robot's share of its route within 0.5 m of
another's, the mean over robots of the largest share).

    .venv/bin/python -m bench.building_gallery [--out docs/figures/generated_buildings.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection

from multi_robot_mapper.core.building_runs import (
    OVERLAP_LEVELS,
    BuildingScanner,
    plan_routes,
    shared_ground,
)
from multi_robot_mapper.core.buildings import Building, generate_building
from multi_robot_mapper.core.simulation import LASERS, raycast_fan

ROBOT_COLOURS = ("tab:red", "tab:blue", "tab:green")
# (seed, kind, size m, overlap level, route length m, furniture /m^2, people)
PANELS = [
    (1, "room_row", 60.0, "small", 70.0, 0.05, 0),
    (0, "mirror_wings", 120.0, "none", 90.0, 0.0, 0),
    (3, "rotation_wings", 70.0, "large", 70.0, 0.0, 0),
    (4, "bare_corridors", 120.0, "small", 90.0, 0.0, 3),
    (5, "pillar_hall", 45.0, "large", 70.0, 0.08, 6),
    (6, "mixed", 110.0, "none", 70.0, 0.03, 4),
    (1, "rotation_wings", 200.0, "small", 160.0, 0.02, 0),
    (2, "mixed", 200.0, "large", 160.0, 0.0, 8),
]


def draw_plan(ax: Axes, building: Building) -> None:
    def lines(segments: np.ndarray, **style: object) -> None:
        if len(segments):
            ax.add_collection(LineCollection(segments.reshape(-1, 2, 2), **style))

    lines(building.edge_segments, colors="0.85", linewidths=0.5)
    lines(building.walls, colors="black", linewidths=0.7)
    lines(building.clutter.static, colors="saddlebrown", linewidths=0.5)
    lines(building.glass, colors="deepskyblue", linewidths=1.8, zorder=4)
    lines(building.clutter.walkers, colors="magenta", linewidths=1.5)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xticks([])
    ax.set_yticks([])


def draw_routes(ax: Axes, paths: list[np.ndarray]) -> None:
    for path, colour in zip(paths, ROBOT_COLOURS, strict=False):
        ax.plot(path[:, 0], path[:, 1], "-", color=colour, linewidth=1.4, alpha=0.75)
        heading = np.degrees(np.arctan2(*(path[1] - path[0])[::-1]))
        ax.plot(*path[0], marker=(3, 0, heading - 90.0), color=colour, markersize=9)


def scan_panel(ax: Axes) -> None:
    """One UTM-30LX scan in a corridor of rooms with glass fronts: returns as dots, beams
    that end on glass (no return) as faint rays up to the pane (or the range limit)."""
    building = generate_building(2, kind="room_row", size=40.0, glass=True, clutter=0.1)
    laser = LASERS["utm30lx"]
    corridor = building.spaces[building.space_kinds == 1][0]
    # Below the middle of a glass room front, looking north into the rooms.
    fronts = building.glass[np.isclose(building.glass[:, 1], corridor[3])]
    middle = 0.5 * (fronts[:, 0] + fronts[:, 2])
    x = float(middle[np.argmin(np.abs(middle - 0.5 * (corridor[0] + corridor[2])))])
    pose = (x, 0.5 * (corridor[1] + corridor[3]), 0.5 * np.pi)
    ranges = BuildingScanner.of(building, laser).ranges(pose)
    bearing = pose[2] + laser.angles
    hits = np.isfinite(ranges)
    draw_plan(ax, building)
    x = pose[0] + ranges[hits] * np.cos(bearing[hits])
    y = pose[1] + ranges[hits] * np.sin(bearing[hits])
    ax.plot(x, y, ".", color="tab:orange", markersize=2.5, zorder=3)
    fan = (laser.angle_min, laser.angle_increment, laser.beams, laser.range_max)
    reach = np.minimum(raycast_fan(building.glass, pose, *fan), laser.range_max)  # the pane
    silent = ~hits
    rays = np.stack(
        (
            np.full((silent.sum(), 2), pose[:2]),
            np.column_stack(
                (
                    pose[0] + reach[silent] * np.cos(bearing[silent]),
                    pose[1] + reach[silent] * np.sin(bearing[silent]),
                )
            ),
        ),
        axis=1,
    )
    ax.add_collection(LineCollection(rays, colors="tab:orange", linewidths=0.4, alpha=0.5))
    ax.plot(*pose[:2], "k^", markersize=6)
    ax.set_xlim(pose[0] - 9, pose[0] + 9)
    ax.set_ylim(corridor[1] - 3, corridor[3] + 8)
    share = 100.0 * silent.mean()
    ax.set_title(
        f"one scan beside glass: {share:.0f} % of beams return nothing\n"
        "(orange dots: returns; faint rays: beams ending on glass)",
        fontsize=8,
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs/figures/generated_buildings.png"))
    args = parser.parse_args()
    fig, axes = plt.subplots(3, 3, figsize=(15, 13))
    for ax, (seed, kind, size, level, length, furniture, people) in zip(
        axes.ravel(), PANELS, strict=False
    ):
        building = generate_building(
            seed, kind=kind, size=size, glass=True, clutter=furniture, people=people
        )
        paths = plan_routes(building, 3, length, OVERLAP_LEVELS[level], seed=seed)
        shares = shared_ground(paths)
        shared = shares[~np.eye(3, dtype=bool)].reshape(3, 2).max(axis=1).mean()
        draw_plan(ax, building)
        draw_routes(ax, paths)
        extras = []
        if furniture:
            extras.append(f"furniture {furniture:g}/m²")
        if people:
            extras.append(f"{people} people")
        ax.set_title(
            f"{kind}, {size:.0f} m, symmetry {building.symmetry}, seed {seed}\n"
            f"overlap {level} ({OVERLAP_LEVELS[level]:g}): shared {shared:.2f}; "
            f"3 routes of {length:.0f} m" + (f"\n{', '.join(extras)}" if extras else ""),
            fontsize=8,
        )
    scan_panel(axes.ravel()[-1])
    fig.suptitle(
        "Generated buildings (all with glass): walls black, glass cyan, furniture brown, "
        "people magenta, waypoint graph grey, three robots' routes (triangle: start)",
        fontsize=10,
    )
    fig.tight_layout()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
