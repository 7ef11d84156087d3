"""Pictures (io/pictures.py): one colour per robot by its place, the extent of segment sets,
and a figure written to every path asked, whole."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from multi_robot_mapper.io.pictures import PALETTE, robot_colors, save_figure, segments_extent


def test_robots_get_the_palettes_colours_in_order_and_round_again() -> None:
    robots = [f"robot{k}" for k in range(1, len(PALETTE) + 3)]
    colors = robot_colors(robots)
    assert [colors[r] for r in robots[: len(PALETTE)]] == list(PALETTE)
    assert colors[robots[len(PALETTE)]] == PALETTE[0] and colors[robots[-1]] == PALETTE[1]
    assert robot_colors(["b", "a"]) == {"b": PALETTE[0], "a": PALETTE[1]}  # by place, not name


def test_the_extent_covers_every_end_of_every_set_and_nothing_is_the_origin() -> None:
    sets = [np.array([[0.0, 1.0, 2.0, -3.0]]), np.zeros((0, 4)), np.array([[-1.5, 4.0, 5.0, 0.0]])]
    np.testing.assert_array_equal(segments_extent(sets), [-1.5, -3.0, 5.0, 4.0])
    np.testing.assert_array_equal(segments_extent([np.zeros((0, 4))]), [0.0, 0.0, 0.0, 0.0])


def test_a_figure_is_written_to_each_path_and_closed(tmp_path: Path) -> None:
    fig, ax = plt.subplots(figsize=(1, 1))
    ax.plot([0, 1], [0, 1])
    written = save_figure(fig, tmp_path / "map.png", tmp_path / "map.svg")
    assert written == tmp_path / "map.png"
    assert (tmp_path / "map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "map.svg").read_bytes()[:500]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.png", "map.svg"]  # no temporary
    assert not plt.fignum_exists(fig.number)
