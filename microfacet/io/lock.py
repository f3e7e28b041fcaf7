"""One writer per output: an advisory lock file beside the output folder.

``acquire(parent / ".NAME.lock")`` opens (creating) the lock file and takes an exclusive,
non-blocking ``flock`` on it; the operating system releases it when the process ends in any
way (``kill -9`` included), so a lock file left behind by a dead run is simply free again.
The file holds the holder's pid, host, start time and command, which a refused second run
names. The holder writes them right after taking the lock, in one write that replaces the
previous content without emptying the file first; a second run that reads the file in between
(empty, half-written, or a dead run's content) reads it again for up to :data:`HOLDER_WAIT_S`
seconds, and then says only that another run is starting, never ``pid None``. Within one
process the lock is re-entrant (a command that claims its output early and a library call
that writes it later share the hold). Creating the file is also the probe that
the parent folder is writable.

Examples
--------
>>> import tempfile, pathlib
>>> lk = lock_path(pathlib.Path(tempfile.mkdtemp()), "out")
>>> acquire(lk), acquire(lk)       # newly taken, then re-entered
(True, False)
>>> release(lk); release(lk); lk.exists()
False
"""

from __future__ import annotations

import contextlib
import datetime
import errno
import json
import os
import socket
import sys
import time
from pathlib import Path

from ..core.errors import InputError, one_line

try:  # POSIX
    import fcntl as _fcntl
except ImportError:  # pragma: no cover - Windows
    _fcntl = None

__all__ = ["HOLDER_WAIT_S", "acquire", "current_umask", "lock_path", "release"]


def current_umask() -> int:
    """The process's file-creation mask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: How long a refused run waits for the holder to finish writing its pid into the lock file.
HOLDER_WAIT_S = 1.0
_HOLDER_POLL_S = 0.02

#: Lock files this process holds: path -> [file descriptor, count] (re-entrant per process).
_HELD: dict[str, list] = {}


def lock_path(parent: Path, name: str) -> Path:
    """The lock file of the output ``parent / name``."""
    return parent / f".{name}.lock"


def _try_lock(fd) -> bool:
    try:
        if _fcntl is not None:
            _fcntl.flock(fd, _fcntl.LOCK_EX | _fcntl.LOCK_NB)
        else:  # pragma: no cover
            import msvcrt

            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        return True
    except OSError as exc:
        if exc.errno in (errno.EAGAIN, errno.EACCES, errno.EWOULDBLOCK, errno.EDEADLK):
            return False
        raise


def _holder_info(fd) -> dict | None:
    """The holder's record in the lock file open as ``fd``, or None while it is empty,
    half-written, or a dead run's (same host, no such process)."""
    try:
        info = json.loads(os.pread(fd, 4096, 0).decode("utf-8") if hasattr(os, "pread")
                          else _seek_read(fd))
    except (OSError, ValueError):
        return None
    if not (isinstance(info, dict) and isinstance(info.get("pid"), int)
            and all(isinstance(info.get(k), str) for k in ("host", "started"))):
        return None
    if info["host"] == socket.gethostname() and not _alive(info["pid"]):
        return None  # the previous holder's content, not yet replaced by the new holder's
    return info


def _seek_read(fd) -> str:  # pragma: no cover - Windows
    os.lseek(fd, 0, os.SEEK_SET)
    return os.read(fd, 4096).decode("utf-8")


def _same_file(fd, path: Path) -> bool:
    try:
        return os.fstat(fd).st_ino == os.stat(path).st_ino
    except OSError:
        return False


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError, OverflowError):
        return True
    return True


def _holder(path: Path, fd, wait_s: float | None = None) -> str | None:
    """Who holds the lock file ``path`` (open as ``fd``): its pid, host and start time, once
    it has written them (re-read for up to ``wait_s``, default :data:`HOLDER_WAIT_S`); None
    when the holder has released and removed it meanwhile (the lock is free: try again)."""
    deadline = time.monotonic() + (HOLDER_WAIT_S if wait_s is None else wait_s)
    while True:
        if not _same_file(fd, path):
            return None
        info = _holder_info(fd)
        if info is not None:
            return f"pid {info['pid']} on {info['host']}, since {info['started']}"
        if time.monotonic() >= deadline:
            return "another process, starting"
        time.sleep(_HOLDER_POLL_S)


def _write_info(fd) -> None:
    """Write this process's record into the lock file ``fd`` (which we hold): one write over
    the old content, then the old content's tail cut off. The file is never empty meanwhile;
    a reader sees the old content, a half-replaced one (not JSON) or the new one."""
    info = {"pid": os.getpid(), "host": socket.gethostname(),
            "started": datetime.datetime.now().isoformat(timespec="seconds"),
            "command": one_line(" ".join(sys.argv))[:300]}
    data = json.dumps(info).encode()
    written = os.pwrite(fd, data, 0) if hasattr(os, "pwrite") else _seek_write(fd, data)
    if written != len(data):
        raise OSError(errno.EIO, "short write of the lock file")
    os.ftruncate(fd, len(data))


def _seek_write(fd, data: bytes) -> int:  # pragma: no cover - Windows
    os.lseek(fd, 0, os.SEEK_SET)
    return os.write(fd, data)


def acquire(lock: Path, *, param: str = "out", shown: str = "") -> bool:
    """Take the lock at ``lock``; True when newly taken (False: already ours, re-entrant).

    Raises
    ------
    InputError
        With ``param``: another live process holds it (the message names it), or the folder
        is not writable.
    """
    key = str(lock)
    if key in _HELD:
        _HELD[key][1] += 1
        return False
    for _ in range(5):
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~current_umask())
        except OSError as exc:
            raise InputError(f"{shown or lock.parent}: cannot write in {one_line(lock.parent)} "
                             f"({exc.strerror})", param=param) from None
        try:
            if not _try_lock(fd):
                who = _holder(lock, fd)
                if who is None:  # released and removed meanwhile: free, try again
                    os.close(fd)
                    continue
                raise InputError(f"{shown}: is being written by another microfacet run "
                                 f"({who}); wait for it to finish", param=param)
            if os.fstat(fd).st_ino != os.stat(lock).st_ino:
                os.close(fd)  # the file we locked was removed and replaced meanwhile
                continue
            _write_info(fd)
        except FileNotFoundError:
            os.close(fd)
            continue
        except InputError:
            os.close(fd)
            raise
        except OSError as exc:
            os.close(fd)
            raise InputError(f"{shown or lock.parent}: cannot write in {one_line(lock.parent)} "
                             f"({exc.strerror})", param=param) from None
        _HELD[key] = [fd, 1]
        return True
    raise InputError(f"{shown}: its lock file {lock} keeps changing; another run is starting",
                     param=param)


def release(lock: Path) -> None:
    """Release a lock taken by :func:`acquire` (the file is removed with the last hold)."""
    key = str(lock)
    held = _HELD.get(key)
    if held is None:
        return
    held[1] -= 1
    if held[1] > 0:
        return
    del _HELD[key]
    with contextlib.suppress(OSError):
        os.unlink(lock)
    os.close(held[0])


