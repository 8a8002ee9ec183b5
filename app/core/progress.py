"""A progress bar on stderr for long commands (``voxwarp animate``, ``export-volume``)."""

from __future__ import annotations

import sys
import time
from typing import Any

#: seconds between progress lines when stderr is not a terminal
PROGRESS_LINE_S = 5.0


class ProgressBar:
    """Units (frames, slices) done of ``total`` on stderr: a tqdm bar on a terminal,
    else a line every :data:`PROGRESS_LINE_S` seconds (and at the end); nothing when
    disabled. Call :meth:`update` per unit and :meth:`close` at the end; set
    ``lines = False`` before closing after an error (no closing line above it)."""

    def __init__(self, total: int, enabled: bool, unit: str = "frame") -> None:
        self.total, self.done, self.unit = total, 0, unit
        self.bar: Any = None
        self.lines = False
        self._last = time.monotonic()
        if not enabled:
            return
        tty = getattr(sys.stderr, "isatty", lambda: False)()
        try:  # the movie extra's; without it, lines as on a non-terminal
            from tqdm import tqdm
        except ImportError:
            tty = False
        if tty:
            self.bar = tqdm(
                total=total, unit=unit, desc=f"{unit}s", file=sys.stderr, dynamic_ncols=True
            )
        else:
            self.lines = True

    def update(self, n: int = 1) -> None:
        self.done += n
        if self.bar is not None:
            self.bar.update(n)
        elif self.lines and time.monotonic() - self._last >= PROGRESS_LINE_S:
            self._line()

    def _line(self) -> None:
        self._last = time.monotonic()
        pct = 100.0 * self.done / max(self.total, 1)
        print(f"{self.unit}s: {self.done}/{self.total} ({pct:.0f}%)", file=sys.stderr, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.lines:
            self._line()
            self.lines = False
