"""The progress of a long command off a terminal: a line per stage and period."""

from __future__ import annotations

import io


def test_progress_off_a_terminal_is_a_line_per_stage_and_period() -> None:
    from multi_robot_mapper.cli.progress import ProgressBar

    stream = io.StringIO()
    bar = ProgressBar("mrm replay (pivot)", stream=stream, period=1e9)
    for done in range(1, 101):
        bar("mapping robot1" if done <= 50 else "mapping robot2", done, 100)
    bar("merging", 0, 1)
    bar("merging", 1, 1)
    bar.close()
    assert stream.getvalue().splitlines() == [
        "mrm replay (pivot): mapping robot1 1/100 (1%)",
        "mrm replay (pivot): merging 0/1 (0%)",
    ]
