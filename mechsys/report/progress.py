"""A progress bar for long runs: rich, on stderr, shown only on a terminal and only once a run takes > 0.5 s."""
from __future__ import annotations

import sys
import time
from typing import Any, Optional


class ProgressBar:
    """Callable ``bar(t)`` with the time reached; ``close()`` removes the bar (it is transient)."""

    def __init__(self, total: float, label: str = "simulating", delay: float = 0.5, enabled: Optional[bool] = None):
        self.total = float(total)
        self.label = label
        self.delay = delay
        self.enabled = sys.stderr.isatty() if enabled is None else enabled
        self._start = time.perf_counter()
        self._progress: Any = None
        self._task: Any = None
        self.updates = 0

    def __call__(self, t: float) -> None:
        self.updates += 1
        if not self.enabled:
            return
        if self._progress is None:
            if time.perf_counter() - self._start < self.delay:
                return
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

            self._progress = Progress(TextColumn(f"{self.label} t = {{task.completed:.4g}} / {self.total:g} s"),
                                      BarColumn(), TimeRemainingColumn(), console=Console(stderr=True),
                                      transient=True)
            self._progress.start()
            self._task = self._progress.add_task(self.label, total=self.total)
        self._progress.update(self._task, completed=min(float(t), self.total))

    def close(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
