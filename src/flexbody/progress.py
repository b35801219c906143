"""A progress line for long runs, on standard error."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class ProgressBar:
    """``bar(t, t_end, n_events)``: redraws at most every 0.2 s on a terminal; elsewhere
    (a log, CI) prints a line at every tenth of the run."""

    def __init__(self, stream: TextIO | None = None, width: int = 30) -> None:
        # standard error as it is now, not as it was at import (a test's capture, since closed)
        self.stream, self.width = sys.stderr if stream is None else stream, width
        self.tty = self.stream.isatty()
        self.start = time.perf_counter()
        self.last_draw = 0.0
        self.last_tenth = -1

    def __call__(self, t: float, t_end: float, n_events: int) -> None:
        fraction = min(max(t / t_end, 0.0), 1.0)
        now = time.perf_counter()
        if self.tty:
            if now - self.last_draw < 0.2 and fraction < 1.0:
                return
            self.last_draw = now
            filled = int(self.width * fraction)
            self.stream.write(
                f"\r[{'#' * filled}{' ' * (self.width - filled)}] {100 * fraction:5.1f}%  t = {t:.4f} s  "
                f"events {n_events}  {now - self.start:.1f} s"
            )
        else:
            tenth = int(10 * fraction)
            if tenth <= self.last_tenth:
                return
            self.last_tenth = tenth
            self.stream.write(f"{100 * fraction:5.1f}%  t = {t:.4f} s  events {n_events}  {now - self.start:.1f} s\n")
        self.stream.flush()

    def close(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
