"""One writer per output (microfacet.io.lock): an advisory ``flock`` on ``.NAME.lock`` beside
the output, re-entrant within a process, refused to another process while it lives, free
again when that process dies (even by SIGKILL)."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import textwrap
import threading
import time

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


# ------------------------------------------------ a lock read before its holder wrote it
_SLOW_HOLDER = textwrap.dedent("""
    import fcntl, json, os, socket, sys
    fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT, 0o644)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # locked, the file not written yet
    print("locked", flush=True)
    sys.stdin.readline()
    data = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "started": "now",
                       "command": "slow"}).encode()
    os.pwrite(fd, data, 0)
    os.ftruncate(fd, len(data))
    print("written", flush=True)
    sys.stdin.readline()
""")


@pytest.fixture
def slow_holder():
    """``slow_holder(lock_path)``: a process that takes the lock and writes its record only
    when told (a line on its stdin), as a run between its ``flock`` and its write."""
    procs = []

    def start(path):
        p = subprocess.Popen([sys.executable, "-c", _SLOW_HOLDER, str(path)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        procs.append(p)
        assert p.stdout.readline().strip() == "locked"
        return p
    yield start
    for p in procs:
        p.kill()
        p.wait(timeout=30)


def _tell(p, delay_s):
    def go():
        p.stdin.write("\n")
        p.stdin.flush()
    timer = threading.Timer(delay_s, go)
    timer.start()
    return timer


@pytest.mark.slow
@pytest.mark.parametrize("old_content", ["", '{"pid": 1', "dead"])
def test_a_lock_read_before_its_holder_wrote_it_names_the_holder(tmp_path, slow_holder,
                                                                 old_content):
    """Two runs racing for one output: the loser reads the lock file while the winner has
    locked it but not written it yet (empty, half-written, or a dead run's record): it waits
    for the record instead of reporting ``pid None on None, since None``."""
    path = lk.lock_path(tmp_path, "out")
    if old_content == "dead":
        gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True, check=True)
        old_content = json.dumps({"pid": int(gone.stdout), "host": socket.gethostname(),
                                  "started": "earlier", "command": "dead"})
    path.write_text(old_content)
    p = slow_holder(path)
    timer = _tell(p, 0.3)
    with pytest.raises(InputError) as err:
        lk.acquire(path, shown="the output")
    timer.join()
    assert f"pid {p.pid} on {socket.gethostname()}, since now" in str(err.value)
    assert "None" not in str(err.value) and "earlier" not in str(err.value)


def test_a_holder_that_never_writes_is_a_run_starting_not_none(tmp_path, slow_holder,
                                                               monkeypatch):
    monkeypatch.setattr(lk, "HOLDER_WAIT_S", 0.1)
    path = lk.lock_path(tmp_path, "out")
    slow_holder(path)
    t0 = time.monotonic()
    with pytest.raises(InputError, match=r"another microfacet run \(another process, "
                                         r"starting\)") as err:
        lk.acquire(path, shown="the output")
    assert "None" not in str(err.value) and time.monotonic() - t0 < 5


_RACER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from microfacet.core.errors import InputError
    from microfacet.io.lock import acquire, release
    path = Path(sys.argv[1])
    print("ready", flush=True)
    sys.stdin.readline()                  # all start together
    end = time.monotonic() + float(sys.argv[2])
    while time.monotonic() < end:
        try:
            if acquire(path, shown="out"):
                release(path)
        except InputError as exc:
            print(exc, flush=True)
""")


@pytest.mark.slow
def test_racing_runs_always_name_the_holder(tmp_path):
    """Processes taking and releasing one lock as fast as they can for half a second (the old
    code printed ``pid None`` for most refusals): every refusal names a pid."""
    path = lk.lock_path(tmp_path, "out")
    procs = [subprocess.Popen([sys.executable, "-c", _RACER, str(path), "0.5"],
                              stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
             for _ in range(4)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    lines = [line for p in procs for line in p.communicate(timeout=120)[0].splitlines()]
    assert all(p.returncode == 0 for p in procs)
    assert lines, "no refusal: the processes did not race"
    assert not [line for line in lines if "None" in line], lines[:3]
    # the holder's pid, or (the lock taken and released faster than it can be read) that a
    # run is starting
    assert all(re.search(r"\(pid \d+ on |another process, starting|keeps changing; another "
                         r"run is starting", line) for line in lines), lines
