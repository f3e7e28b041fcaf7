"""A minimal progress bar for the command line (stderr, only on a terminal), with an ETA from
per-stage weights where the steps take unequal time."""

from __future__ import annotations

import sys
import time

__all__ = ["Progress", "StageProgress"]


class Progress:
    """Context manager drawing ``label [#####.....] k/n  elapsed  eta`` on stderr.

    Silent when ``quiet`` is true or the stream is not a terminal (piped, CI, tests).

    Examples
    --------
    >>> with Progress("slices", total=3, quiet=True) as bar:
    ...     for k in range(3):
    ...         bar.update(k + 1)
    >>> bar.fraction
    1.0
    """

    def __init__(self, label: str, *, total: int, unit: str = "", quiet: bool = False,
                 stream=None):
        self.label = label
        self.unit = f" {unit}" if unit else ""
        self.total = max(int(total), 1)
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = not quiet and hasattr(self.stream, "isatty") and self.stream.isatty()
        self.fraction = 0.0
        self._t0 = time.perf_counter()

    def __enter__(self):
        self._t0 = time.perf_counter()
        return self

    def update(self, done: int, total: int | None = None) -> None:
        """``done`` of ``total`` (default: the total given before) steps are finished."""
        if total:
            self.total = max(int(total), 1)
        self._draw(done / self.total, f"{done}/{self.total}{self.unit}")

    def _draw(self, fraction: float, text: str) -> None:
        self.fraction = min(max(float(fraction), 0.0), 1.0)
        if not self.enabled:
            return
        width = 30
        filled = int(round(self.fraction * width))
        elapsed = time.perf_counter() - self._t0
        # nothing measured yet: no estimate rather than a made-up 0 s
        eta = (f"{elapsed / self.fraction - elapsed:5.1f}s" if self.fraction > 0
               else "    ?")
        self.stream.write(f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] "
                          f"{text}  {elapsed:5.1f}s  eta {eta}\x1b[K")
        self.stream.flush()

    def __exit__(self, *exc):
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()
        return False


class StageProgress(Progress):
    """A :class:`Progress` over named stages of unequal cost.

    The fraction done when a stage starts is the summed weight of the stages before it over
    the summed weight of all, so the ETA (elapsed / fraction − elapsed) follows the measured
    cost of the stages rather than their count.

    Parameters
    ----------
    label : str
    stages : sequence
        The stages in order, each with a ``label`` and a relative cost ``weight``
        (:class:`microfacet.analysis.stages.Stage`).
    skip : collection, optional
        Stages that will not run this time (the report with ``--no-report``, the joint
        mode's stages in the seed mode); they count for nothing.
    quiet : bool
    stream : file, optional

    Examples
    --------
    >>> from types import SimpleNamespace as S
    >>> a, b = S(label="a", weight=1.0), S(label="b", weight=3.0)
    >>> bar = StageProgress("analyze", [a, b], quiet=True)
    >>> bar.stage(b); bar.fraction
    0.25
    >>> bar.stage(S(label="other", weight=1.0)); bar.fraction   # not a stage: no move
    0.25
    >>> bar.finish(); bar.fraction
    1.0
    """

    def __init__(self, label: str, stages, *, skip=(), quiet: bool = False, stream=None):
        self._stages = [s for s in stages if s not in list(skip)]
        super().__init__(label, total=len(self._stages), quiet=quiet, stream=stream)
        self._sum = sum(s.weight for s in self._stages) or 1.0

    def stage(self, stage) -> None:
        """``stage`` starts: every stage before it in the order is done."""
        if stage not in self._stages:
            return
        k = self._stages.index(stage)
        self._draw(sum(s.weight for s in self._stages[:k]) / self._sum,
                   f"{stage.label} ({k + 1}/{len(self._stages)})")

    def finish(self) -> None:
        """Every stage is done."""
        self._draw(1.0, "done")
