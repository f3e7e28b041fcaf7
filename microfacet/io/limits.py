"""Limits checked before memory is spent: image sizes from headers, memory from estimates.

A hostile or broken file can claim any size in its header (a 216 KB PNG stack claiming
30000 × 30000 pixels per slice; a zlib bomb). Every image size is read from its header and
checked against :class:`Limits` *before* a pixel is decoded, and a command's memory estimate
is checked against the memory this machine has free *before* the work starts. Each refusal
is an :class:`~microfacet.core.errors.InputError` naming the file or option and the limit.

Defaults
--------
``DEFAULT_MAX_MEGAPIXELS = 50``
    Per image (a slice, an export image or height map). Covers every microscope camera and
    stitched field we know of (4K digital microscopes write 8-12 MP; 50 MP is 8192 × 6144),
    and is ~4× the size the analysis is benchmarked at (docs/benchmarks.md). Raise it with
    ``max_megapixels`` (``--max-megapixels``) for bigger images; memory is checked anyway.
``DEFAULT_MAX_STACK_MEGAPIXELS = 20000``
    All slices together (e.g. 50 MP × 400 slices): bounds the time spent decoding one stack
    (about 8 minutes at the measured 0.9 s per 40 one-megapixel slices).

Examples
--------
>>> Limits().check_image((4000, 3000), "slice 0")
>>> try:
...     Limits(max_megapixels=10).check_image((30000, 30000), "slice 0")
... except InputError as exc:
...     print(exc.args[0].split(";")[0])
slice 0: 30000x30000 pixels (900 MP) is more than the limit of 10 MP per image
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError

__all__ = ["DEFAULT_MAX_MEGAPIXELS", "DEFAULT_MAX_STACK_MEGAPIXELS", "Limits", "check_file_size",
           "check_memory"]

DEFAULT_MAX_MEGAPIXELS = 50.0
DEFAULT_MAX_STACK_MEGAPIXELS = 20000.0
#: Largest stack.json / summary.json read (a stack.json of 100,000 slices is ~4 MB).
MAX_JSON_BYTES = 64 << 20
#: Largest number of rows of a spectrum CSV (spectrometers write a few thousand).
MAX_SPECTRUM_ROWS = 100_000
_MB = 1 << 20


@dataclass(frozen=True)
class Limits:
    """Size limits checked from headers before decoding.

    Attributes
    ----------
    max_megapixels : float
        Largest image (slice, export image or height map), in megapixels.
    max_stack_megapixels : float
        Largest total over all slices of a stack, in megapixels.
    """

    max_megapixels: float = DEFAULT_MAX_MEGAPIXELS
    max_stack_megapixels: float = DEFAULT_MAX_STACK_MEGAPIXELS

    def __post_init__(self):
        for name in ("max_megapixels", "max_stack_megapixels"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not (
                    math.isfinite(v) and v > 0):
                raise InputError(f"must be a number > 0, got {v!r}", param=name)

    def check_image(self, shape, where: str) -> None:
        """Refuse an image whose header claims more than :attr:`max_megapixels`."""
        h, w = int(shape[0]), int(shape[1])
        mp = h * w / 1e6
        if mp > self.max_megapixels:
            raise InputError(f"{where}: {w}x{h} pixels ({mp:,.0f} MP) is more than the limit "
                             f"of {self.max_megapixels:g} MP per image; `max_megapixels` "
                             f"raises it")

    def check_stack(self, n_slices: int, shape, where: str) -> None:
        """Refuse a stack whose slices together exceed :attr:`max_stack_megapixels`."""
        mp = n_slices * int(shape[0]) * int(shape[1]) / 1e6
        if mp > self.max_stack_megapixels:
            raise InputError(f"{where}: {n_slices} slices of {shape[1]}x{shape[0]} pixels "
                             f"({mp:,.0f} MP in all) is more than the limit of "
                             f"{self.max_stack_megapixels:g} MP per stack; "
                             f"`max_stack_megapixels` raises it")


def _available_memory_bytes() -> int | None:
    """Memory available to a new process here (Linux ``MemAvailable``), or None if unknown."""
    try:
        with open("/proc/meminfo", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def check_memory(need_bytes: float, what: str, *, param: str | None = None,
                 budget_bytes: float | None = None) -> None:
    """Refuse work estimated to need more memory than is free (or than ``budget_bytes``).

    Parameters
    ----------
    need_bytes : float
        The estimate.
    what : str
        What needs it, for the message (the file or the options that drive the estimate).
    param : str, optional
        The parameter to name in the error.
    budget_bytes : float, optional
        A fixed budget instead of the machine's available memory.
    """
    avail = _available_memory_bytes() if budget_bytes is None else budget_bytes
    if avail is None:
        return
    usable = 0.9 * avail if budget_bytes is None else avail
    if need_bytes > usable:
        where = "this machine has" if budget_bytes is None else "the limit is"
        raise InputError(f"{what} needs about {need_bytes / _MB:,.0f} MB of memory; {where} "
                         f"{usable / _MB:,.0f} MB", param=param)


def check_file_size(path, max_bytes: int, shown: str) -> int:
    """The size of ``path`` in bytes; an InputError naming ``shown`` when it is over
    ``max_bytes`` (checked before the file is read). OSError propagates (missing file).

    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "f"
    >>> _ = p.write_bytes(b"12345")
    >>> check_file_size(p, 10, "f")
    5
    """
    size = Path(path).stat().st_size
    if size > max_bytes:
        raise InputError(f"{shown}: {size / _MB:,.0f} MB is too large for this file "
                         f"(limit {max_bytes / _MB:,.0f} MB)")
    return size
