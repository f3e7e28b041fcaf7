"""Studies of microfacet: measurements that answer one question each and print a table.

Each study is a module of :mod:`pipelines.studies` declaring

* ``STUDY = Study(name=..., question=..., doc=("docs/x.md", "block") or None, run_time=...,
  quick_time=...)`` and
* ``run(*, quick: bool, out: Path, **options) -> str``: the Markdown table (or page) it
  measured. Figures, CSVs and work files go under ``out``; nothing else is written.

``python -m pipelines list`` prints the registry, ``python -m pipelines run NAME [--quick]
[--docs] [--out DIR] [--set KEY=VALUE ...]`` runs one study. Only ``--docs`` touches docs/: it
replaces the text between ``<!-- study:BLOCK -->`` and ``<!-- /study:BLOCK -->`` in the
study's doc with what ``run`` returned, and copies the study's ``doc_files`` (figures, CSVs)
from ``out`` into docs/. Names follow one scheme, ``<kind>-<subject>``: ``speed-*`` (time and
memory), ``accuracy-*`` (error against a truth or a reference) and ``gallery-*`` (pictures).

Shared helpers are modules of this package (``from pipelines import _shared``); the layer lint
of the package is :mod:`pipelines.module_map` (not a study).
"""

from __future__ import annotations

import importlib
import pkgutil
import re
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["DOCS", "ROOT", "Study", "block_markers", "find", "registry", "replace_block"]

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: Folders a study never writes to (inputs); docs/ only through ``--docs``.
PROTECTED = (ROOT / "docs", ROOT / "fixtures", ROOT / "microfacet", ROOT / "tests")


@dataclass(frozen=True)
class Study:
    """What the registry knows of a study.

    Attributes
    ----------
    name : str
        ``<kind>-<subject>``, the command-line name.
    question : str
        The question the study answers, in one line.
    doc : tuple or None
        ``(path relative to the repository, block name)`` of the doc block ``--docs``
        rewrites with the default run's output; None: the study writes no doc.
    run_time, quick_time : str
        Typical time of a full and of a ``--quick`` run on the 2-core development machine.
    options : dict
        ``{name: (default, help)}``: settings beyond ``--quick`` (``--set name=value``; the
        value is converted to the default's type). ``--docs`` needs the defaults.
    doc_files : dict
        ``{file under out: path relative to the repository}`` copied with ``--docs``.
    """

    name: str
    question: str
    doc: tuple | None
    run_time: str
    quick_time: str = ""
    options: dict = field(default_factory=dict)
    doc_files: dict = field(default_factory=dict)

    def parse_options(self, pairs) -> dict:
        """``{name: value}`` of ``KEY=VALUE`` strings, typed like the defaults."""
        out = {}
        for pair in pairs or ():
            key, sep, text = pair.partition("=")
            key = key.strip().replace("-", "_")
            if not sep or key not in self.options:
                known = ", ".join(sorted(self.options)) or "none"
                raise ValueError(f"--set {pair!r}: {self.name} takes KEY=VALUE with KEY one "
                                 f"of: {known}")
            default = self.options[key][0]
            out[key] = _convert(text.strip(), default, key)
        return out


def _convert(text, default, key):
    if isinstance(default, bool):
        if text.lower() in ("1", "true", "yes", "on"):
            return True
        if text.lower() in ("0", "false", "no", "off"):
            return False
        raise ValueError(f"--set {key}: expected true or false, got {text!r}")
    if isinstance(default, (int, float)):
        try:
            return type(default)(text)
        except ValueError:
            raise ValueError(f"--set {key}: expected a {type(default).__name__}, got "
                             f"{text!r}") from None
    return text if text.lower() not in ("", "none") else None


def registry() -> dict:
    """``{name: module}`` of every study in :mod:`pipelines.studies`, in name order."""
    pkg = importlib.import_module(f"{__name__}.studies")
    found = {}
    for info in pkgutil.iter_modules(pkg.__path__):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"{pkg.__name__}.{info.name}")
        study = getattr(mod, "STUDY", None)
        if not isinstance(study, Study):
            raise TypeError(f"pipelines/studies/{info.name}.py declares no STUDY")
        if study.name in found:
            raise ValueError(f"two studies named {study.name!r}")
        found[study.name] = mod
    return dict(sorted(found.items()))


def find(name: str):
    """The module of study ``name`` (KeyError naming the known ones)."""
    all_ = registry()
    if name not in all_:
        raise KeyError(f"no study {name!r}; known: {', '.join(all_)}")
    return all_[name]


def block_markers(block: str) -> tuple[str, str]:
    """The comments that delimit a study's block in a doc."""
    return f"<!-- study:{block} -->", f"<!-- /study:{block} -->"


def replace_block(path, block: str, text: str) -> None:
    r"""Replace the text between the block's markers in ``path`` (both must be there, once).

    The block is written with a blank line after the opening and before the closing marker
    (a table next to a comment line still renders as a table).

    >>> import tempfile
    >>> p = Path(tempfile.mkdtemp()) / "x.md"
    >>> _ = p.write_text("a\n\n<!-- study:t -->\n\nold\n\n<!-- /study:t -->\n\nb\n")
    >>> replace_block(p, "t", "| new |")
    >>> p.read_text()
    'a\n\n<!-- study:t -->\n\n| new |\n\n<!-- /study:t -->\n\nb\n'
    """
    path = Path(path)
    body = path.read_text(encoding="utf-8")
    start, end = block_markers(block)
    pattern = re.compile(re.escape(start) + r"\n.*?" + re.escape(end), flags=re.S)
    if len(pattern.findall(body)) != 1:
        raise ValueError(f"{path}: needs exactly one {start} … {end} block")
    body = pattern.sub(lambda m: f"{start}\n\n{text.strip()}\n\n{end}", body)
    path.write_text(body, encoding="utf-8")


def is_protected(path) -> bool:
    """Whether ``path`` lies in an input folder (docs/, fixtures/, the package, tests/)."""
    p = Path(path).resolve()
    return any(p == q or q in p.parents for q in PROTECTED)
