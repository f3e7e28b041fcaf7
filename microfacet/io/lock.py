"""One writer per output: an advisory lock file beside the output folder.

``acquire(parent / ".NAME.lock")`` opens (creating) the lock file and takes an exclusive,
non-blocking ``flock`` on it; the operating system releases it when the process ends in any
way (``kill -9`` included), so a lock file left behind by a dead run is simply free again.
The file holds the holder's pid, host, start time and command, which a refused second run
names. Within one process the lock is re-entrant (a command that claims its output early and
a library call that writes it later share the hold). Creating the file is also the probe that
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
from pathlib import Path

from ..core.errors import InputError, one_line

try:  # POSIX
    import fcntl as _fcntl
except ImportError:  # pragma: no cover - Windows
    _fcntl = None

__all__ = ["acquire", "current_umask", "lock_path", "release"]


def current_umask() -> int:
    """The process's file-creation mask (read without changing it)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


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


def _holder(path: Path) -> str:
    try:
        info = json.loads(path.read_text(encoding="utf-8") or "{}")
        return (f"pid {info.get('pid')} on {info.get('host')}, since {info.get('started')}")
    except (OSError, ValueError):
        return "another process"


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
                raise InputError(f"{shown}: is being written by another microfacet run "
                                 f"({_holder(lock)}); wait for it to finish", param=param)
            if os.fstat(fd).st_ino != os.stat(lock).st_ino:
                os.close(fd)  # the file we locked was removed and replaced meanwhile
                continue
            info = {"pid": os.getpid(), "host": socket.gethostname(),
                    "started": datetime.datetime.now().isoformat(timespec="seconds"),
                    "command": one_line(" ".join(sys.argv))[:300]}
            os.ftruncate(fd, 0)
            os.write(fd, json.dumps(info).encode())
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


