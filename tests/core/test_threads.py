"""The thread setting of microfacet's pools (microfacet.core.threads) and where it is read."""

from __future__ import annotations

import importlib
import os

import numpy as np
import pytest

from microfacet.core import threads
from microfacet.core.errors import InputError
from microfacet.core.threads import (
    default_num_threads,
    limited_threads,
    num_threads,
    set_num_threads,
    threads_from_text,
)


@pytest.fixture(autouse=True)
def _restore():
    yield
    set_num_threads(None)


def test_default_is_min_of_8_and_the_cpus():
    assert default_num_threads() == max(1, min(8, os.cpu_count() or 1))
    assert num_threads() == default_num_threads()


def test_set_and_reset():
    set_num_threads(3)
    assert num_threads() == 3
    set_num_threads(np.int64(2))
    assert num_threads() == 2 and type(num_threads()) is int
    set_num_threads(None)
    assert num_threads() == default_num_threads()


@pytest.mark.parametrize("bad", [0, -1, 1.5, "2", True])
def test_bad_values_name_the_parameter(bad):
    set_num_threads(5)
    with pytest.raises(InputError) as exc:
        set_num_threads(bad)
    assert exc.value.param == "num_threads"
    assert num_threads() == 5                      # unchanged


def test_context_manager_restores_even_on_error():
    set_num_threads(4)
    with limited_threads(1) as n:
        assert n == num_threads() == 1
    assert num_threads() == 4
    with pytest.raises(RuntimeError), limited_threads(2):
        assert num_threads() == 2
        raise RuntimeError
    assert num_threads() == 4
    set_num_threads(None)
    with limited_threads(None):
        assert num_threads() == default_num_threads()


@pytest.mark.parametrize("text,value", [(None, None), ("", None), ("  ", None), ("4", 4),
                                        (" 2 ", 2)])
def test_threads_from_text(text, value):
    assert threads_from_text(text) == value


@pytest.mark.parametrize("text", ["0", "-2", "four", "1.5"])
def test_threads_from_bad_text_names_the_variable(text):
    with pytest.raises(InputError, match=r"^\$MICROFACET_NUM_THREADS: must be a positive"):
        threads_from_text(text)


def test_the_library_does_not_read_the_environment(monkeypatch):
    """Only the command line reads $MICROFACET_NUM_THREADS: setting it changes nothing for
    the library, and the thin-film pool follows the setting."""
    from microfacet.optics import thinfilm

    monkeypatch.setenv(threads.ENV_VAR, "1")
    assert num_threads() == default_num_threads()
    seen = []
    monkeypatch.setattr(threads, "ThreadPoolExecutor", _recording_pool(seen))   # thread_map's
    shape = (64, 4096)                               # enough blocks to use the pool
    with limited_threads(2):
        thinfilm.reflectance(550.0, np.zeros(shape), np.full(shape, 100.0), 2.2, 2.5 + 3.3j)
    assert seen == [2]


def _recording_pool(seen):
    from concurrent.futures import ThreadPoolExecutor

    class Recording(ThreadPoolExecutor):
        def __init__(self, max_workers=None, **kw):
            seen.append(max_workers)
            super().__init__(max_workers=max_workers, **kw)

    return Recording


def test_command_line_reads_the_variable(monkeypatch, capsys, tmp_path):
    """cli/main.py sets the threads from $MICROFACET_NUM_THREADS before a command runs; a
    bad value is a one-line error naming the variable."""
    cli_main = importlib.import_module("microfacet.cli.main")
    got = []
    monkeypatch.setattr(cli_main, "set_num_threads", got.append)
    argv = ["height", str(tmp_path / "no-stack"), "--out", str(tmp_path / "o")]
    monkeypatch.setenv(threads.ENV_VAR, "3")
    assert cli_main.main(argv) == 2                 # the stack is missing: after the setting
    assert got == [3]
    monkeypatch.delenv(threads.ENV_VAR)
    assert cli_main.main(argv) == 2
    assert got == [3, None]
    monkeypatch.setenv(threads.ENV_VAR, "zero")
    capsys.readouterr()
    assert cli_main.main(argv) == 2
    assert "$MICROFACET_NUM_THREADS: must be a positive integer" in capsys.readouterr().err


def test_thread_map_keeps_order_and_bounds_the_chunks_in_flight():
    """thread_map returns the items' results in order, on the setting's threads; the chunks
    of chunk_starts cover the range once and shrink with the threads, so that the items in
    flight stay at most ``in_flight``."""
    import threading

    names = set()

    def work(ab):
        names.add(threading.current_thread().name)
        a, b = ab
        return list(range(a, b))

    for n in (1, 2, 3):
        with threads.limited_threads(n):
            chunks = threads.chunk_starts(1001, 100)
            assert all(b - a <= -(-100 // n) for a, b in chunks)
            got = threads.thread_map(work, chunks)
        assert sum(got, []) == list(range(1001))
    with threads.limited_threads(1):
        names.clear()
        threads.thread_map(work, threads.chunk_starts(10, 3))
    assert names == {threading.current_thread().name}      # one thread: the caller's
    assert threads.thread_map(work, []) == []


def test_malloc_arenas_are_limited_where_glibc_allows_it():
    """limit_malloc_arenas sets glibc's M_ARENA_MAX (True) and does nothing elsewhere
    (False), never raising."""
    import platform
    import sys

    glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    assert threads.limit_malloc_arenas(2) is glibc


def test_free_heap_memory_is_given_back_where_glibc_allows_it():
    """return_free_memory gives the pages malloc keeps free back (glibc: True, the resident
    memory falls by most of what was freed below a block still in use); elsewhere it does
    nothing (False)."""
    import platform
    import sys

    glibc = sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc"
    if not glibc:
        assert threads.return_free_memory() is False
        return

    def resident_mb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20

    threads.return_free_memory()
    blocks = [np.ones(8192) for _ in range(1200)]   # 64 kB each: malloc's heap, 75 MB
    del blocks[:-1]                                 # the last one keeps the heap's top
    held = resident_mb()
    assert threads.return_free_memory() is True
    assert resident_mb() < held - 50.0


def test_thread_map_carries_the_callers_numpy_error_state():
    """numpy's error state is each thread's own: thread_map's workers keep the caller's
    (a division by zero raises under ``np.errstate(divide="raise")`` on any thread)."""
    def divide(_):
        return np.float64(1.0) / np.float64(0.0)

    with threads.limited_threads(2), np.errstate(divide="raise"):
        with pytest.raises(FloatingPointError):
            threads.thread_map(divide, range(4))
    with threads.limited_threads(2), np.errstate(divide="ignore"):
        assert all(np.isinf(threads.thread_map(divide, range(4))))


def test_background_work_runs_beside_the_caller_and_gives_its_value_or_its_error():
    """Background runs fn on a thread of its own when more than one thread is allowed (the
    caller goes on meanwhile: fn waits for the caller here, so it can only finish if the
    caller is not blocked), and by the first result() with one thread (on the caller's
    thread, where a sequential program would run it); result() gives fn's value, or raises
    what fn raised, with numpy's error state the caller's."""
    import threading

    go = threading.Event()

    def waits_for_the_caller():
        assert go.wait(timeout=30)
        return threading.current_thread().name

    with threads.limited_threads(2):
        job = threads.Background(waits_for_the_caller)
        go.set()                                    # the caller went on: fn may finish
        assert job.result() == "microfacet-background"
        assert job.result() == "microfacet-background"          # the value stays
    ran = []
    with threads.limited_threads(1):
        job = threads.Background(lambda: ran.append(threading.current_thread().name) or 7)
        assert ran == []                            # not run before it is asked for
        assert job.result() == 7 and ran == [threading.current_thread().name]
    for n in (1, 2):
        with threads.limited_threads(n), np.errstate(divide="raise"):
            job = threads.Background(lambda: np.float64(1.0) / np.float64(0.0))
            with pytest.raises(FloatingPointError):
                job.result()
