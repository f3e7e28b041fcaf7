"""A minimal progress bar for the command line (stderr, only on a terminal)."""

from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    """Context manager drawing ``label [#####.....] k/n  ETA`` on stderr.

    Silent when ``quiet`` is true or stderr is not a terminal (piped, CI, tests).

    Examples
    --------
    >>> with Progress("slices", total=3, quiet=True) as bar:
    ...     for k in range(3):
    ...         bar.update(k + 1)
    """

    def __init__(self, label: str, *, total: int, unit: str = "", quiet: bool = False,
                 stream=None):
        self.label = label
        self.unit = f" {unit}" if unit else ""
        self.total = max(int(total), 1)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = not quiet and hasattr(self.stream, "isatty") and self.stream.isatty()
        self._t0 = time.perf_counter()

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def update(self, done: int, total: int | None = None) -> None:
        if total:
            self.total = max(int(total), 1)
        if not self.enabled:
            return
        frac = min(max(done / self.total, 0.0), 1.0)
        width = 30
        filled = int(round(frac * width))
        elapsed = time.perf_counter() - self._t0
        eta = elapsed / frac - elapsed if frac > 0 else 0.0
        self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] "
                          f"{done}/{self.total}{self.unit}  {elapsed:5.1f}s  eta {eta:5.1f}s")
        self.stream.flush()

    def __exit__(self, *exc):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
        return False
