"""One writer per output (microfacet.io.lock): an advisory ``flock`` on ``.NAME.lock`` beside
the output, re-entrant within a process, refused to another process while it lives, free
again when that process dies (even by SIGKILL)."""

from __future__ import annotations

import json
import os
import signal
import socket

import pytest

from microfacet.core.errors import InputError
from microfacet.io import lock as lk
from microfacet.io.outdir import OutputFolder


def test_lock_path_is_a_hidden_sibling(tmp_path):
    assert lk.lock_path(tmp_path, "res") == tmp_path / ".res.lock"


def test_reentrant_within_a_process_and_removed_with_the_last_hold(tmp_path):
    path = lk.lock_path(tmp_path, "out")
    assert lk.acquire(path) is True        # newly taken
    assert lk.acquire(path) is False       # re-entered: shares the hold
    lk.release(path)
    assert path.exists()                   # still held once
    info = json.loads(path.read_text())
    assert info["pid"] == os.getpid() and info["host"] == socket.gethostname()
    assert {"started", "command"} <= set(info)
    lk.release(path)
    assert not path.exists()
    lk.release(path)                        # releasing what is not held: nothing happens
    assert lk.acquire(path) is True        # and it can be taken again
    lk.release(path)


def test_another_process_is_refused_while_the_holder_lives(tmp_path, lock_holder):
    path = lk.lock_path(tmp_path, "out")
    p = lock_holder(path)
    with pytest.raises(InputError, match=rf"the output: is being written by another microfacet "
                                         rf"run \(pid {p.pid} on .*\); wait") as err:
        lk.acquire(path, shown="the output")
    assert err.value.param == "out"
    # the holder ends normally: free
    p.stdin.write("\n")
    p.stdin.flush()
    assert p.wait(timeout=30) == 0
    assert lk.acquire(path) is True
    lk.release(path)


def test_a_killed_holder_leaves_a_free_lock_file(tmp_path, lock_holder):
    path = lk.lock_path(tmp_path, "out")
    p = lock_holder(path)
    os.kill(p.pid, signal.SIGKILL)
    p.wait(timeout=30)
    assert path.exists()                   # the file stays; the flock went with the process
    assert lk.acquire(path) is True
    assert json.loads(path.read_text())["pid"] == os.getpid()
    lk.release(path)


def test_output_folder_of_another_process_is_refused(tmp_path, lock_holder):
    """The same through :class:`OutputFolder`: a second run on the same ``out`` is refused
    before it writes anything, and the first run's files are untouched."""
    lock_holder(lk.lock_path(tmp_path, "res"))
    before = sorted(p.name for p in tmp_path.iterdir())
    with pytest.raises(InputError, match="is being written by another microfacet run"):
        with OutputFolder(tmp_path / "res", kind="results"):
            pass
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_a_folder_that_cannot_hold_the_lock_is_refused(tmp_path):
    with pytest.raises(InputError, match=r"cannot write in .*missing") as err:
        lk.acquire(tmp_path / "missing" / ".out.lock", param="out")
    assert err.value.param == "out"


def test_current_umask_reads_without_changing():
    old = os.umask(0o027)
    try:
        assert lk.current_umask() == 0o027
        assert lk.current_umask() == 0o027
    finally:
        os.umask(old)
