"""A minimal progress bar for the command line (stderr, only on a terminal), with an ETA from
per-stage weights where the steps take unequal time."""

from __future__ import annotations

import sys
import time

__all__ = ["ANALYZE_STAGE_WEIGHTS", "Progress", "StageProgress"]

#: Relative cost of each stage of ``microfacet analyze``, in the order the pipeline announces
#: them (``progress(stage)`` of :func:`microfacet.workflow.analyse_to_folder`). Measured as the
#: ``timings_s`` of ``summary.json`` after ``microfacet analyze fixtures/stacks/nd-fixture``
#: (joint mode, 2 cores), seconds: height_from_focus + normals; colour_and_mask;
#: colour_table; thickness_roi; segmentation + facet_fits + tilt_per_pixel; mixtures; write;
#: report. The report takes as long as the whole analysis, so equal steps would put the
#: bar at 6/8 when half the time is still ahead.
ANALYZE_STAGE_WEIGHTS = (
    ("height from focus", 2.2),
    ("colour", 1.4),
    ("colour table", 0.6),
    ("thickness per ROI", 0.4),
    ("tilt per pixel", 3.0),
    ("distributions", 1.1),
    ("write", 0.05),
    ("report", 8.5),
)


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
    weights : sequence of (str, float)
        The stages in order and their relative cost (see :data:`ANALYZE_STAGE_WEIGHTS`).
    skip : collection of str, optional
        Stages that will not run this time (``report`` with ``--no-report``); they count
        for nothing.
    quiet : bool
    stream : file, optional

    Examples
    --------
    >>> bar = StageProgress("analyze", [("a", 1.0), ("b", 3.0)], quiet=True)
    >>> bar.stage("b"); bar.fraction
    0.25
    >>> bar.stage("unknown"); bar.fraction   # an unknown stage does not move the bar
    0.25
    >>> bar.finish(); bar.fraction
    1.0
    """

    def __init__(self, label: str, weights, *, skip=(), quiet: bool = False, stream=None):
        self._stages = [(name, float(w)) for name, w in weights if name not in set(skip)]
        super().__init__(label, total=len(self._stages), quiet=quiet, stream=stream)
        self._sum = sum(w for _, w in self._stages) or 1.0

    def stage(self, name: str) -> None:
        """Stage ``name`` starts: every stage before it in the order is done."""
        names = [n for n, _ in self._stages]
        if name not in names:
            return
        k = names.index(name)
        self._draw(sum(w for _, w in self._stages[:k]) / self._sum,
                   f"{name} ({k + 1}/{len(names)})")

    def finish(self) -> None:
        """Every stage is done."""
        self._draw(1.0, "done")
