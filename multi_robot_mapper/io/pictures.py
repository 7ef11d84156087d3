"""Pictures of segment maps: PNG/SVG with a 1 m grid, a scale bar and a colour per source."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from multi_robot_mapper.io.outputs import atomic_file

FloatArray = np.typing.NDArray[np.float64]

PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2")


def draw_segments(
    ax: Axes, segments: FloatArray, color: str, width: float = 1.5, label: str | None = None
) -> None:
    """Draw an ``(N, 4)`` segment set as lines."""
    lines = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2)
    ax.add_collection(LineCollection(lines, colors=color, linewidths=width, label=label))


def finish_metric_axes(ax: Axes, title: str, extent: FloatArray | None = None) -> None:
    """Equal axes in metres with a 1 m grid and a scale bar in the lower left corner."""
    ax.set_aspect("equal")
    if extent is not None and np.all(np.isfinite(extent)):
        pad = 0.5
        ax.set_xlim(extent[0] - pad, extent[2] + pad)
        ax.set_ylim(extent[1] - pad, extent[3] + pad)
    else:
        ax.autoscale_view()
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    ax.set_xticks(np.arange(np.ceil(x0), np.floor(x1) + 1.0, 1.0), minor=True)
    ax.set_yticks(np.arange(np.ceil(y0), np.floor(y1) + 1.0, 1.0), minor=True)
    ax.grid(which="minor", color="0.9", linewidth=0.5)
    ax.grid(which="major", color="0.8", linewidth=0.6)
    span = x1 - x0
    # The longest 1-2-5 length (at least 1 m) within a sixth of the width.
    nice = np.array([1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0])
    bar = float(nice[max(0, int(np.searchsorted(nice, span / 6.0, side="right")) - 1)])
    bx, by = x0 + 0.04 * span, y0 + 0.05 * (y1 - y0)
    ax.plot([bx, bx + bar], [by, by], color="k", linewidth=3)
    ax.text(bx + bar / 2, by + 0.02 * (y1 - y0), f"{bar:g} m", ha="center", va="bottom", fontsize=8)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=10)


def segments_extent(segment_sets: Sequence[FloatArray]) -> FloatArray:
    """``[xmin, ymin, xmax, ymax]`` of all segment end points."""
    ends = np.vstack(
        [np.asarray(s).reshape(-1, 2) for s in segment_sets if len(s)] or [np.zeros((1, 2))]
    )
    return np.concatenate((ends.min(axis=0), ends.max(axis=0)))


def save_figure(fig: Figure, path: str | Path, *more: str | Path) -> Path:
    """Write a figure to each path (format from the suffix: .png, .svg) and close it."""
    paths = [Path(p) for p in (path, *more)]
    try:
        for target in paths:  # each under a temporary name until complete
            with atomic_file(target, "wb") as stream:
                fig.savefig(
                    stream, format=target.suffix.lstrip(".") or "png", dpi=150, bbox_inches="tight"
                )
    finally:
        plt.close(fig)
    return paths[0]


def draw_map(
    map_segments: FloatArray,
    segment_robot: np.typing.NDArray[np.int64],
    robots: Sequence[str],
    paths: dict[str, FloatArray],
    title: str,
    unmerged: dict[str, tuple[FloatArray, FloatArray]] | None = None,
) -> Figure:
    """A global segment map: a colour per robot, each robot's path, 1 m grid, scale bar.

    ``unmerged``: robot -> (segments, path) in the robot's own frame, for robots placed in no
    common frame: each gets a panel of its own beside the global map (never drawn over it at
    the origin, which would look like a merge); their entries in ``paths`` are not drawn."""
    unmerged = unmerged or {}
    merged = [r for r in robots if r not in unmerged]
    panels = ([None] if merged or not unmerged else []) + list(unmerged)
    extent = segments_extent(
        [map_segments]
        + [np.hstack((paths[r][:, :2], paths[r][:, :2])) for r in merged if len(paths.get(r, ()))]
    )
    span = max(extent[2] - extent[0], extent[3] - extent[1], 1.0)
    size = float(np.clip(span / 4.0, 6.0, 16.0))
    side = [size] + [6.0] * (len(panels) - 1) if panels[0] is None else [6.0] * len(panels)
    fig, axes = plt.subplots(
        1, len(panels), figsize=(sum(side), max(side)), width_ratios=side, squeeze=False
    )
    colors = robot_colors(robots)
    for ax, panel in zip(axes[0], panels, strict=True):
        if panel is None:
            for index, robot in enumerate(robots):
                if robot in unmerged:
                    continue
                mine = map_segments[segment_robot == index]
                _draw_robot(ax, robot, mine, paths.get(robot), colors[robot])
            if merged:
                ax.legend(loc="upper right", fontsize=8, title="dashed: path, dot: start")
            finish_metric_axes(ax, title, extent)
            continue
        segments, path = unmerged[panel]
        _draw_robot(ax, panel, segments, path, colors[panel])
        own = segments_extent([segments, np.hstack((path[:, :2], path[:, :2]))])
        heading = f"{panel}: unmerged, in its own frame" + ("" if merged else f"\n{title}")
        finish_metric_axes(ax, heading, own)
    return fig


def _draw_robot(
    ax: Axes, robot: str, segments: FloatArray, path: FloatArray | None, color: str
) -> None:
    if len(segments):
        draw_segments(ax, segments, color, width=0.8, label=f"{robot} ({len(segments)} segments)")
    if path is not None and len(path):
        ax.plot(path[:, 0], path[:, 1], color=color, linewidth=0.8, linestyle="--", alpha=0.8)
        ax.plot(path[0, 0], path[0, 1], "o", color=color, markersize=5)


def robot_colors(robots: Sequence[str]) -> dict[str, str]:
    """One colour per robot, by its place in ``robots``."""
    return {robot: PALETTE[index % len(PALETTE)] for index, robot in enumerate(robots)}


def draw_robot_maps(
    ax: Axes,
    maps: dict[str, FloatArray],
    paths: dict[str, FloatArray],
    colors: dict[str, str],
    title: str,
    walls: FloatArray | None = None,
    extent: FloatArray | None = None,
) -> None:
    """Robots' segment maps (and their paths, dashed, start dotted) on one metric axes, over
    ``walls`` in light grey when given."""
    if walls is not None and len(walls):
        draw_segments(ax, walls, "0.85", width=3.0, label="true walls")
    for robot, segments in maps.items():
        if len(segments):
            label = f"{robot} ({len(segments)} segments)"
            draw_segments(ax, segments, colors[robot], width=0.9, label=label)
        path = paths.get(robot)
        if path is not None and len(path):
            ax.plot(path[:, 0], path[:, 1], color=colors[robot], linewidth=0.8, linestyle="--")
            ax.plot(path[0, 0], path[0, 1], "o", color=colors[robot], markersize=4)
    if maps:
        ax.legend(loc="upper right", fontsize=7)
    if extent is None:
        extent = segments_extent([*maps.values(), *(np.hstack((p, p)) for p in paths.values())])
    finish_metric_axes(ax, title, extent)


def draw_global_map(
    merged: dict[str, FloatArray],
    merged_paths: dict[str, FloatArray],
    unmerged: dict[str, FloatArray],
    unmerged_paths: dict[str, FloatArray],
    colors: dict[str, str],
    title: str,
    walls: FloatArray | None = None,
) -> Figure:
    """The merged robots in one frame (``map``); each unmerged robot in a panel of its own,
    in its own map frame, labelled so."""
    panels = 1 + len(unmerged)
    fig, axes = plt.subplots(1, panels, figsize=(9 + 5 * (panels - 1), 7), squeeze=False)
    draw_robot_maps(axes[0, 0], merged, merged_paths, colors, title, walls)
    for ax, (robot, segments) in zip(axes[0, 1:], unmerged.items(), strict=True):
        draw_robot_maps(
            ax,
            {robot: segments},
            {robot: unmerged_paths.get(robot, np.zeros((0, 2)))},
            colors,
            f"{robot}: UNMERGED (its own map frame, not placed in map)",
        )
    return fig


def draw_snapshots(
    snapshots: Sequence[tuple[str, dict[str, FloatArray]]],
    colors: dict[str, str],
    extent: FloatArray,
) -> Figure:
    """A strip of global maps, left to right, each titled (e.g. when robots joined)."""
    fig, axes = plt.subplots(1, len(snapshots), figsize=(5.5 * len(snapshots), 4.5), squeeze=False)
    for ax, (title, maps) in zip(axes[0], snapshots, strict=True):
        draw_robot_maps(ax, maps, {}, colors, title, extent=extent)
    return fig


def animate_snapshots(
    frames: Sequence[tuple[str, dict[str, FloatArray]]],
    colors: dict[str, str],
    extent: FloatArray,
    path: str | Path,
    fps: float = 4.0,
) -> Path:
    """The global maps as an animated GIF, one frame each (written under a temporary name)."""
    from matplotlib.animation import PillowWriter

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_name(f".{path.stem}.part{path.suffix}")
    fig, ax = plt.subplots(figsize=(8, 5.5))
    writer = PillowWriter(fps=fps)
    with writer.saving(fig, str(temporary), dpi=80):
        for title, maps in frames:
            ax.clear()
            draw_robot_maps(ax, maps, {}, colors, title, extent=extent)
            writer.grab_frame()
    plt.close(fig)
    temporary.replace(path)
    return path


def draw_grid(
    cells: np.typing.NDArray[np.int8], origin: tuple[float, float], resolution: float, title: str
) -> Figure:
    """An occupancy grid: unknown grey, free white, occupied black."""
    shades = np.full(cells.shape, 0.75)
    shades[cells == 0] = 1.0
    shades[cells >= 50] = 0.0
    height, width = cells.shape
    extent = np.array(
        [origin[0], origin[1], origin[0] + width * resolution, origin[1] + height * resolution]
    )
    size = float(np.clip(max(extent[2] - extent[0], extent[3] - extent[1]) / 3.0, 6.0, 14.0))
    fig, ax = plt.subplots(figsize=(size, size * 0.75))
    ax.imshow(
        shades,
        cmap="gray",
        vmin=0.0,
        vmax=1.0,
        origin="lower",
        extent=(extent[0], extent[2], extent[1], extent[3]),
        interpolation="nearest",
    )
    finish_metric_axes(ax, title, extent)
    return fig
