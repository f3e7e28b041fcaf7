"""Stage timings from one place: each stage of a pipeline is timed by the same clock."""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["StageTimer"]


class StageTimer:
    """Times consecutive stages; ``timings`` maps stage names to seconds (rounded to 0.1 ms).

    Parameters
    ----------
    progress : callable, optional
        ``progress(stage)`` is called when a stage starts (:meth:`start`).

    Examples
    --------
    >>> t = StageTimer()
    >>> t.start("read")
    >>> t.lap("read")            # the time since the last lap (or the start)
    >>> t.lap("fit")
    >>> sorted(t.timings), t.total() >= 0
    (['fit', 'read'], True)
    """

    def __init__(self, progress: Callable[[str], None] | None = None):
        self._progress = progress
        self._t0 = self._last = time.perf_counter()
        self.timings: dict[str, float] = {}

    def start(self, stage: str) -> None:
        """Announce ``stage`` (the progress callback); the clock keeps running."""
        if self._progress is not None:
            self._progress(stage)

    def lap(self, name: str) -> None:
        """Record the time since the previous lap as stage ``name``."""
        now = time.perf_counter()
        self.timings[name] = round(now - self._last, 4)
        self._last = now

    def total(self) -> float:
        """Seconds since the timer was made; also recorded as ``timings["total"]``."""
        t = round(time.perf_counter() - self._t0, 4)
        self.timings["total"] = t
        return t
