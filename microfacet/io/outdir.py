"""Output folders: never an input, one writer at a time, whole or not at all.

Every command that writes a folder (``analyze``, ``height``, ``batch``, ``simulate``, ``synth``)
goes through :class:`OutputFolder`. Its rules, checked before any work starts:

1. **Never an input.** ``out`` may not be an input, hold an input (be its ancestor), be the
   current folder or one of its ancestors, or hold a focus stack (a ``stack.json``).
2. **Only its own kind is replaced.** An existing ``out`` is replaced only with
   ``overwrite=True`` and only when it is recognisably the same kind of microfacet output
   (:func:`output_kind`: a results folder by its ``summary.json`` format, a batch output by its
   ``batch_summary.csv``, ...). An empty folder may be used. Anything else is never replaced.
3. **One writer.** A lock file ``.NAME.lock`` beside ``out`` (an advisory ``flock``, which the
   operating system releases when the process ends, even by ``kill -9``). A second run on the
   same ``out`` is refused naming the first; the ``.NAME.partial-*`` and ``.NAME.old-*``
   folders of a run that died are removed by the next run that takes the lock.
4. **Room to write.** Creating the lock file probes that the parent folder is writable; the
   free space is compared with the expected size of the output.
5. **Whole or not at all.** :meth:`OutputFolder.writing` yields a temporary sibling folder and
   renames it to ``out`` when the block completes; on any exception (Ctrl-C included) it is
   removed and ``out`` is left as it was.

Errors are :class:`~microfacet.core.errors.InputError` with ``param="out"``.

Examples
--------
>>> import tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> with atomic_output_dir(d / "res", kind="results") as tmp:
...     _ = (tmp / "summary.json").write_text('{"format": "microfacet-results/1"}')
>>> output_kind(d / "res")
'results'
>>> try:
...     check_output(d, kind="results", inputs=[d / "res"])
... except InputError as exc:
...     print(exc.reason.split(":", 1)[1].strip()[:15])
holds the input
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from pathlib import Path

from ..core.errors import InputError, one_line
from .lock import acquire, current_umask, lock_path, release

__all__ = ["OutputFolder", "atomic_output_dir", "check_output", "sweep_stale"]

#: The kinds of output folder microfacet writes, and how messages call them.
KINDS = {
    "results": "an analysis results folder",
    "height": "a height-from-focus folder",
    "simulate": "a simulation folder",
    "batch": "a batch output folder",
    "render": "a render folder",
    "synthetic stack": "a synthetic stack",
}
_JSON_MARKERS = (("summary.json", "microfacet-results/", "results"),
                 ("height.json", "microfacet-height/", "height"),
                 ("simulate.json", "microfacet-simulate/", "simulate"),
                 ("render.json", "microfacet-render/", "render"))
_BATCH_HEADER = "stack,results,status"
_WALK_LIMIT = 200_000     # entries looked at for a stack inside an existing output
_SPACE_MARGIN = 1.2       # free space needed: expected size x margin + 16 MB
_MB = 1 << 20


def _small_json(path: Path):
    try:
        if path.stat().st_size > 16 * _MB:
            return None
        with open(path, encoding="utf-8-sig") as fh:
            return json.load(fh)
    except (OSError, ValueError, RecursionError):
        return None


def output_kind(folder) -> str | None:
    """Which microfacet output ``folder`` is (a key of :data:`KINDS`), or None.

    Recognised by content, not by name: ``summary.json`` of format ``microfacet-results/*``,
    ``height.json`` (``microfacet-height/*``), ``simulate.json`` (``microfacet-simulate/*``),
    ``render.json`` (``microfacet-render/*``),
    ``batch_summary.csv`` (its header), or a ``stack.json`` with ``truth/params.json`` of
    format ``microfacet-synth-truth/*``.
    """
    folder = Path(folder)
    for name, prefix, kind in _JSON_MARKERS:
        data = _small_json(folder / name)
        if isinstance(data, dict) and str(data.get("format", "")).startswith(prefix):
            return kind
    try:
        with open(folder / "batch_summary.csv", encoding="utf-8-sig") as fh:
            if fh.readline(256).startswith(_BATCH_HEADER):
                return "batch"
    except OSError:
        pass
    truth = _small_json(folder / "truth" / "params.json")
    if (folder / "stack.json").is_file() and isinstance(truth, dict) and str(
            truth.get("format", "")).startswith("microfacet-synth-truth/"):
        return "synthetic stack"
    return None


def _is_leftover(name: str) -> bool:
    """A name microfacet gives its temporary files: ``.NAME.partial-*``, ``.NAME.old-*``,
    ``.NAME.lock``."""
    return name.startswith(".") and (".partial-" in name or ".old-" in name
                                     or (name.endswith(".lock") and len(name) > 6))


def _is_within(inner: str, outer: str) -> bool:
    return inner == outer or inner.startswith(outer.rstrip(os.sep) + os.sep)


def _stack_inside(folder: Path) -> Path | None:
    seen = 0
    for root, dirs, files in os.walk(folder):
        if "stack.json" in files:
            return Path(root) / "stack.json"
        seen += len(dirs) + len(files)
        if seen > _WALK_LIMIT:
            return folder / "..."
    return None


def _check_path_text(out) -> str:
    text = os.fspath(out)
    if not text:
        raise InputError("empty path", param="out")
    if "\x00" in text:
        raise InputError(f"{one_line(text)}: contains a NUL byte", param="out")
    if any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise InputError(f"{one_line(text)}: contains a control character (a newline?); "
                         f"refusing to create such a folder", param="out")
    return text


def check_output(out, *, kind: str, inputs=(), overwrite: bool = False) -> Path:
    """Check the rules 1-2 of this module for ``out`` without writing anything.

    Parameters
    ----------
    out : path-like
        The folder to write.
    kind : str
        A key of :data:`KINDS`: what will be written.
    inputs : iterable of path-like
        Files and folders the command reads (stack folders, a results folder, a CSV).
    overwrite : bool
        Whether an existing output of the same kind may be replaced.

    Returns
    -------
    pathlib.Path
        ``out`` as an absolute path.

    Raises
    ------
    InputError
        With ``param="out"``, naming the rule that ``out`` breaks.
    """
    if kind not in KINDS:
        raise ValueError(f"kind: expected one of {', '.join(KINDS)}, got {kind!r}")
    text = _check_path_text(out)
    path = Path(os.path.abspath(text))
    real = os.path.realpath(path)
    shown = one_line(text)
    cwd = os.path.realpath(os.getcwd())
    if _is_within(cwd, real):
        what = "is the current folder" if cwd == real else "holds the current folder"
        raise InputError(f"{shown}: {what}; results never replace the folder you are in — "
                         f"choose a new folder", param="out")
    for item in inputs:
        if "\x00" in os.fspath(item):
            raise InputError(f"{one_line(os.fspath(item))}: the path contains a NUL byte")
        item_real = os.path.realpath(os.fspath(item))
        if _is_within(item_real, real):
            what = "is the input" if item_real == real else "holds the input"
            raise InputError(f"{shown}: {what} {one_line(item_real)}; outputs never replace "
                             f"inputs — choose a new folder", param="out")
    if path.is_symlink():
        raise InputError(f"{shown}: is a symbolic link; give a plain folder", param="out")
    if not os.path.lexists(path):
        return path
    if not path.is_dir():
        raise InputError(f"{shown}: exists and is not a folder", param="out")
    try:
        empty = all(_is_leftover(e.name) for e in os.scandir(path))
    except OSError as exc:
        raise InputError(f"{shown}: cannot read ({exc.strerror})", param="out") from None
    if empty:  # nothing, or only what killed microfacet runs left (removed when claimed)
        return path
    found = output_kind(path)
    if (path / "stack.json").is_file() and found != kind:
        raise InputError(f"{shown}: is a focus stack folder (it has stack.json); it is never "
                         f"replaced — choose a new folder", param="out")
    if found is None:
        raise InputError(f"{shown}: exists and is not {KINDS[kind]} written by microfacet; it "
                         f"is never replaced — choose a new folder or move it away yourself",
                         param="out")
    if found != kind:
        raise InputError(f"{shown}: is {KINDS[found]}, not {KINDS[kind]}; it is not replaced — "
                         f"choose another folder", param="out")
    if not overwrite:
        raise InputError(f"{shown}: already exists ({KINDS[kind]}); `overwrite` "
                         f"replaces it", param="out")
    inner = _stack_inside(path) if kind != "synthetic stack" else None
    if inner is not None:
        raise InputError(f"{shown}: holds a focus stack ({one_line(inner)}) or too much to be "
                         f"{KINDS[kind]}; it is never replaced", param="out")
    return path


def _leftovers(parent: Path, name: str):
    prefixes = (f".{name}.partial-", f".{name}.old-")
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return []
    return [Path(e.path) for e in entries if e.name.startswith(prefixes)]


def _clean_leftovers(parent: Path, name: str, kind: str | None) -> list[Path]:
    """Remove what killed runs left beside ``parent/name`` (we hold its lock). If ``name``
    itself is missing but a ``.old-*`` folder holds a complete output (a run killed between
    its two renames), it is put back first."""
    out = parent / name
    removed = []
    for p in sorted(_leftovers(parent, name)):
        old = p / name
        if (not os.path.lexists(out) and p.name.startswith(f".{name}.old-") and old.is_dir()
                and output_kind(old) is not None and (kind is None or output_kind(old) == kind)):
            os.replace(old, out)
        shutil.rmtree(p, ignore_errors=True)
        removed.append(p)
    return removed


def sweep_stale(folder) -> list[Path]:
    """Remove the leftovers of killed runs (``.NAME.partial-*``, ``.NAME.old-*`` and unheld
    ``.NAME.lock``) inside ``folder``, skipping every NAME that a live run holds.

    Returns the removed paths.
    """
    folder = Path(folder)
    names = set()
    try:
        for e in os.scandir(folder):
            for tag in (".partial-", ".old-"):
                if e.name.startswith(".") and tag in e.name:
                    names.add(e.name[1:e.name.index(tag)])
            if e.name.startswith(".") and e.name.endswith(".lock") and len(e.name) > 6:
                names.add(e.name[1:-5])
    except OSError:
        return []
    removed = []
    for name in sorted(names):
        lock = lock_path(folder, name)
        try:
            taken = acquire(lock, shown=str(folder / name))
        except InputError:
            continue  # a live run holds it
        if not taken:  # this process is writing it right now (the lock is re-entrant)
            release(lock)
            continue
        try:
            removed += _clean_leftovers(folder, name, None)
        finally:
            release(lock)
    return removed


# --------------------------------------------------------------------------- the folder
class OutputFolder:
    """Claim an output folder for the duration of a ``with`` block (rules 1-4 above).

    Parameters
    ----------
    out : path-like
    kind : str
        A key of :data:`KINDS`.
    inputs : iterable of path-like
        What the command reads; ``out`` may not be or hold any of them.
    overwrite : bool
        Replace an existing output of the same kind (only once the new one is complete).
    expected_bytes : int
        Expected size of the output; refused up front when the disk has less free space.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with OutputFolder(d / "h", kind="height") as claim:
    ...     # (long work here: a second run on d / "h" is refused meanwhile)
    ...     with claim.writing() as tmp:
    ...         _ = (tmp / "height.json").write_text('{"format": "microfacet-height/1"}')
    >>> sorted(p.name for p in d.iterdir())
    ['h']
    """

    def __init__(self, out, *, kind: str, inputs=(), overwrite: bool = False,
                 expected_bytes: int = 0):
        self.kind = kind
        self.inputs = tuple(inputs)
        self.overwrite = overwrite
        self.expected_bytes = int(expected_bytes)
        self.path = check_output(out, kind=kind, inputs=self.inputs, overwrite=overwrite)
        self._shown = one_line(os.fspath(out))
        self._lock = None
        self.removed: list[Path] = []

    @property
    def parent(self) -> Path:
        return self.path.parent

    def __enter__(self):
        parent = self.parent
        if os.path.lexists(parent) and not parent.is_dir():
            raise InputError(f"{self._shown}: {one_line(parent)} is not a folder", param="out")
        try:
            parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"{self._shown}: cannot create {one_line(parent)} "
                             f"({exc.strerror})", param="out") from None
        lock = lock_path(parent, self.path.name)
        fresh = acquire(lock, shown=self._shown)
        self._lock = lock
        try:
            if fresh:
                self.removed = _clean_leftovers(parent, self.path.name, self.kind)
            # the folder may have changed while we waited for nothing: check again
            check_output(self.path, kind=self.kind, inputs=self.inputs,
                         overwrite=self.overwrite)
            self._check_space()
        except BaseException:
            release(lock)
            self._lock = None
            raise
        return self

    def _check_space(self):
        if self.expected_bytes <= 0:
            return
        try:
            free = shutil.disk_usage(self.parent).free
        except OSError:
            return
        need = int(self.expected_bytes * _SPACE_MARGIN) + 16 * _MB
        if free < need:
            raise InputError(f"{self._shown}: needs about {need / _MB:,.0f} MB, but only "
                             f"{free / _MB:,.0f} MB are free on that disk", param="out")

    def __exit__(self, *exc):
        if self._lock is not None:
            release(self._lock)
            self._lock = None
        return False

    @contextlib.contextmanager
    def writing(self):
        """Yield a temporary sibling folder; rename it to ``out`` when the block completes.

        On any exception (KeyboardInterrupt included) the temporary folder is removed and
        ``out`` is left as it was.
        """
        if self._lock is None:
            raise RuntimeError("OutputFolder.writing() outside its with-block")
        out, parent = self.path, self.parent
        try:
            tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=parent))
        except OSError as exc:
            raise InputError(f"{self._shown}: cannot write in {one_line(parent)} "
                             f"({exc.strerror})", param="out") from None
        try:
            os.chmod(tmp, 0o777 & ~current_umask())  # mkdtemp makes 0700; follow the umask
            yield tmp
            check_output(out, kind=self.kind, inputs=self.inputs, overwrite=self.overwrite)
            if os.path.lexists(out) and next(os.scandir(out), None) is not None:
                old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old-", dir=parent))
                os.replace(out, old / out.name)
                os.replace(tmp, out)
                shutil.rmtree(old, ignore_errors=True)
            else:
                os.replace(tmp, out)  # onto nothing, or onto an empty folder
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise


@contextlib.contextmanager
def atomic_output_dir(out, *, kind: str, overwrite: bool = False, inputs=(),
                      expected_bytes: int = 0):
    """Claim ``out`` and write it atomically in one step (see :class:`OutputFolder`).

    Yields
    ------
    pathlib.Path
        The temporary folder to write into; renamed to ``out`` when the block completes.
    """
    with OutputFolder(out, kind=kind, overwrite=overwrite, inputs=inputs,
                      expected_bytes=expected_bytes) as claim, claim.writing() as tmp:
        yield tmp
