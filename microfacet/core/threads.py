"""How many threads microfacet's own thread pools use (the thin-film blocks of
:mod:`microfacet.optics.thinfilm`): one process-wide setting, default ``min(8, CPU count)``.

The library never reads the environment: the command line turns ``$MICROFACET_NUM_THREADS``
into a setting (:func:`threads_from_text`), a batch worker sets its share of the machine
(:func:`set_num_threads`), and a script limits a block of work with :func:`limited_threads`.
The setting is per process, not per thread.

Examples
--------
>>> with limited_threads(1):
...     num_threads()
1
>>> num_threads() == default_num_threads()
True
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from numbers import Integral

from .errors import InputError

__all__ = ["ENV_VAR", "limited_threads", "num_threads", "set_num_threads", "threads_from_text"]

#: The environment variable the command line reads (:func:`threads_from_text`).
ENV_VAR = "MICROFACET_NUM_THREADS"
#: More threads than this gain little on the thin-film blocks and cost memory per block.
MAX_DEFAULT_THREADS = 8

_setting: int | None = None


def default_num_threads() -> int:
    """``min(8, CPU count)``, at least 1."""
    return max(1, min(MAX_DEFAULT_THREADS, os.cpu_count() or 1))


def num_threads() -> int:
    """The threads a pool of microfacet may use: the setting, else the default."""
    return default_num_threads() if _setting is None else _setting


def set_num_threads(n: int | None) -> None:
    """Set the threads of microfacet's pools (``None``: back to the default).

    Raises
    ------
    InputError
        ``n`` is not a positive integer (names ``num_threads``).
    """
    global _setting
    if n is not None and (isinstance(n, bool) or not isinstance(n, Integral) or n < 1):
        raise InputError(f"must be a positive integer, got {n!r}", param="num_threads")
    _setting = None if n is None else int(n)


@contextmanager
def limited_threads(n: int | None) -> Iterator[int]:
    """Use ``n`` threads inside the block (the setting before it is restored after it);
    yields the number in use."""
    before = _setting
    set_num_threads(n)
    try:
        yield num_threads()
    finally:
        set_num_threads(before)


def threads_from_text(text: str | None) -> int | None:
    """The setting written in ``text`` (the value of :data:`ENV_VAR` at the command line):
    None for none or blank, else a positive integer.

    >>> threads_from_text("4"), threads_from_text(" "), threads_from_text(None)
    (4, None, None)

    Raises
    ------
    InputError
        Anything else, naming the variable.
    """
    if text is None or not text.strip():
        return None
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise InputError(f"${ENV_VAR}: must be a positive integer, got {text!r}")
    return n
