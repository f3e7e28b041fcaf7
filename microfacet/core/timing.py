"""Stage timings from one place: each stage of a pipeline is timed by the same clock."""

from __future__ import annotations

import time
from collections.abc import Callable
from contextlib import contextmanager

__all__ = ["StageTimer"]


class StageTimer:
    """Times stages; ``timings`` maps each stage's ``key`` to seconds (rounded to 0.1 ms).

    Parameters
    ----------
    progress : callable, optional
        ``progress(stage)`` is called when a stage starts.
    between : callable, optional
        ``between()`` is called when a stage ends, outside its time (the analysis gives the
        memory its stage freed back to the system there).

    Examples
    --------
    >>> from types import SimpleNamespace as Stage
    >>> t = StageTimer()
    >>> with t.stage(Stage(key="read")):
    ...     pass
    >>> sorted(t.timings), t.total() >= 0
    (['read'], True)
    """

    def __init__(self, progress: Callable[[object], None] | None = None, *,
                 between: Callable[[], object] | None = None):
        self._progress, self._between = progress, between
        self._t0 = time.perf_counter()
        self.timings: dict[str, float] = {}

    @contextmanager
    def stage(self, stage):
        """Announce ``stage`` (the progress callback) and record its time as ``stage.key``."""
        if self._progress is not None:
            self._progress(stage)
        t0 = time.perf_counter()
        yield
        self.timings[stage.key] = round(time.perf_counter() - t0, 4)
        if self._between is not None:
            self._between()

    def total(self) -> float:
        """Seconds since the timer was made; also recorded as ``timings["total"]``."""
        t = round(time.perf_counter() - self._t0, 4)
        self.timings["total"] = t
        return t
