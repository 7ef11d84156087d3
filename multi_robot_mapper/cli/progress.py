"""Progress on stderr: a bar redrawn in place on a terminal, a plain line now and then
elsewhere (a log file, CI, a pipe), so that a long replay always shows where it is."""

from __future__ import annotations

import sys
import time
from typing import TextIO

from multi_robot_mapper.cli.interrupts import raise_if_interrupted

BAR_PERIOD_S = 0.1  # a terminal's bar is redrawn at most this often
LINE_PERIOD_S = 30.0  # elsewhere, a line at most this often (and at each new stage)


class ProgressBar:
    """``bar(stage, done, total)``: on a terminal one line redrawn in place, elsewhere a line
    ``<title>: <stage> <done>/<total> (<percent>%)`` at each new stage and every
    ``LINE_PERIOD_S``; ``close()`` ends the bar's line."""

    def __init__(
        self, title: str, stream: TextIO | None = None, width: int = 30, period: float | None = None
    ) -> None:
        self.title = title
        self.stream = stream or sys.stderr
        self.width = width
        self.terminal = self.stream.isatty()
        self.period = (
            period if period is not None else (BAR_PERIOD_S if self.terminal else LINE_PERIOD_S)
        )
        self._last = -float("inf")
        self._stage = ""
        self._drawn = False

    def __call__(self, stage: str, done: int, total: int) -> None:
        raise_if_interrupted()  # a Ctrl-C a library swallowed (cli/interrupts.py) stops here
        now = time.monotonic()
        kind = stage.split(" ")[0]  # "mapping robot2" is the stage "mapping"
        new_stage = kind != self._stage
        if not new_stage and done < total and now - self._last < self.period:
            return
        if not new_stage and done >= total and not self.terminal:
            return  # the next stage's line says this one ended
        self._last, self._stage = now, kind
        if self.terminal:
            filled = int(self.width * done / max(total, 1))
            bar = "#" * filled + "." * (self.width - filled)
            self.stream.write(f"\r{self.title} [{bar}] {done}/{total} {stage:<16}")
            self._drawn = True
        else:
            percent = 100.0 * done / max(total, 1)
            self.stream.write(f"{self.title}: {stage} {done}/{total} ({percent:.0f}%)\n")
        self.stream.flush()

    def close(self) -> None:
        if self.terminal and self._drawn:
            self.stream.write("\n")
            self.stream.flush()
