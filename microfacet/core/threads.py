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

import math
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from numbers import Integral

from .errors import InputError

__all__ = ["BLOCK_VALUES", "ENV_VAR", "Background", "chunk_starts", "chunks",
           "limit_malloc_arenas", "limited_threads", "num_threads", "return_free_memory",
           "row_chunks", "set_num_threads", "thread_map", "threads_from_text"]

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


#: Values a block-wise loop holds in one float64 temporary (2 MB): :func:`row_chunks` of a
#: map's rows.
BLOCK_VALUES = 1 << 18


def row_chunks(shape) -> list:
    """The :func:`chunks` of the rows of an array of ``shape`` (``shape[0]`` rows of
    ``prod(shape[1:])`` values each) for a loop that works a block of whole rows at a time:
    about :data:`BLOCK_VALUES` values a block, at least one row.

    >>> row_chunks((5, 100000)), row_chunks((3, 1 << 20, 3))
    ([(0, 2), (2, 4), (4, 5)], [(0, 1), (1, 2), (2, 3)])
    """
    row = max(1, math.prod(int(v) for v in shape[1:]))
    return chunks(int(shape[0]), BLOCK_VALUES // row)


def chunks(n: int, in_flight: int) -> list:
    """The ``(start, stop)`` of consecutive chunks of ``range(n)`` of ``in_flight`` items
    (at least 1), for a loop that bounds its temporaries by working a chunk at a time.

    >>> chunks(5, 2), chunks(3, 0)
    ([(0, 2), (2, 4), (4, 5)], [(0, 1), (1, 2), (2, 3)])
    """
    step = max(1, int(in_flight))
    return [(a, min(n, a + step)) for a in range(0, n, step)]


def chunk_starts(n: int, in_flight: int) -> list:
    """The :func:`chunks` of ``range(n)`` for :func:`thread_map`: each of
    ``ceil(in_flight / num_threads())`` items, so that the chunks the threads hold at once
    total at most ``in_flight`` items (memory bounded as with one thread).

    >>> with limited_threads(2):
    ...     chunk_starts(5, 4)
    [(0, 2), (2, 4), (4, 5)]
    """
    return chunks(n, -(-int(in_flight) // num_threads()))


def thread_map(fn: Callable, items: Sequence) -> list:
    """``[fn(item) for item in items]``, the items on :func:`num_threads` threads (in order).

    For numpy work on independent chunks: numpy releases the GIL inside each ufunc, so the
    chunks run concurrently. Each thread holds one chunk's temporaries, so the memory in
    flight is that many chunks'. One thread, or one item, runs in the calling thread. numpy's
    error state is the thread's own: the caller's (``np.errstate``) is carried into the
    workers.

    >>> with limited_threads(1):
    ...     thread_map(lambda ab: sum(range(*ab)), chunk_starts(10, 4))
    [6, 22, 17]
    """
    items = list(items)
    threads = min(num_threads(), len(items))
    if threads <= 1:
        return [fn(item) for item in items]
    import numpy as np

    err = np.geterr()

    def call(item):
        with np.errstate(**err):
            return fn(item)

    with ThreadPoolExecutor(max_workers=threads) as pool:
        return list(pool.map(call, items))


class Background:
    """``fn()`` computed on a thread of its own while the caller goes on, when
    :func:`num_threads` allows more than one thread; with one, computed by the first
    :meth:`result` (where a sequential program would compute it). For work that depends on
    nothing the caller changes meanwhile: the value is the same either way. numpy's error
    state is the caller's, as in :func:`thread_map`.

    >>> Background(lambda: sum(range(10))).result()
    45
    >>> with limited_threads(1):
    ...     Background(lambda: 1 // 0).result()
    Traceback (most recent call last):
    ...
    ZeroDivisionError: integer division or modulo by zero
    """

    def __init__(self, fn: Callable[[], object]):
        import threading

        import numpy as np

        self._fn, self._err = fn, np.geterr()
        self._value = self._exc = None
        self._thread = None
        if num_threads() > 1:
            self._thread = threading.Thread(target=self._run, name="microfacet-background",
                                            daemon=True)
            self._thread.start()

    def _run(self) -> None:
        import numpy as np

        try:
            with np.errstate(**self._err):
                self._value = self._fn()
        except BaseException as exc:  # noqa: BLE001 - raised again by result()
            self._exc = exc
        finally:
            self._fn = None

    def result(self):
        """``fn()``'s value, once it has run (waiting for it), or what it raised."""
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        elif self._fn is not None:
            self._run()
        if self._exc is not None:
            raise self._exc
        return self._value


#: ``mallopt`` parameter number of ``M_ARENA_MAX`` (glibc's malloc.h).
_M_ARENA_MAX = -8


def limit_malloc_arenas(n: int = 1) -> bool:
    """Let glibc's malloc keep at most ``n`` arenas in this process (``mallopt(M_ARENA_MAX)``).

    glibc gives each new thread an arena of its own, and memory freed in an arena stays in
    the process: with :func:`thread_map`'s threads the analysis of a 1-megapixel stack peaks
    ~50 MB higher for that alone (590-600 MB against 552 MB with one arena,
    docs/benchmarks.md). One arena since the self-check runs on a thread of its own beside
    the other stages (2026-12-02): with two, what that thread freed stayed in its arena and
    the 1 MP peak read 397-416 MB, with one 384-387 MB (378-383 MB before), in the same time.
    A process-wide setting, made by ``microfacet analyze``, ``microfacet
    batch`` and the batch workers before the analysis' threads start (not for every command:
    a renderer's own threads may want their arenas); elsewhere (another C library, another
    system) nothing is done.

    Returns
    -------
    bool
        Whether the setting was made.
    """
    return _glibc_call("mallopt", _M_ARENA_MAX, int(n))


def return_free_memory() -> bool:
    """Give the pages glibc's malloc holds free back to the system (``malloc_trim(0)``).

    Arrays of a few megabytes come from malloc's heap once larger ones have been freed (its
    mmap threshold rises with them), and the heap keeps what they free: between the analysis'
    stages about 100 MB at 1 megapixel, on top of which the next stage's temporaries then
    come (docs/benchmarks.md). The analysis calls this after each of its stages and before
    its report; a call takes a few milliseconds. Elsewhere (another C library, another system)
    nothing is done.

    Returns
    -------
    bool
        Whether memory was given back.
    """
    return _glibc_call("malloc_trim", 0)


def _glibc_call(name, *args) -> bool:
    """glibc's function ``name`` called with the integers ``args``, as a bool; False where
    there is no glibc (another system, another C library) or no such function."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        import ctypes

        return bool(getattr(ctypes.CDLL("libc.so.6"), name)(*args))
    except (OSError, AttributeError):
        return False
