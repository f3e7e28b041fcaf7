"""Every study of pipelines/ runs: ``python -m pipelines run NAME --quick --out TMP`` exits 0,
prints a Markdown table and leaves docs/ and fixtures/ untouched (only ``--docs`` writes
docs/; nothing writes fixtures/). The registry lists every study.

Slow (each quick run takes seconds to ~20 s): ``pytest -m slow tests/test_studies.py``.
"""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "pipelines" / "studies"
WATCHED = ("docs", "fixtures")


def _study_names() -> list[str]:
    """The ``name=`` of each ``STUDY = Study(...)`` in pipelines/studies (read, not imported)."""
    names = []
    for path in sorted(STUDIES.glob("[!_]*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if (isinstance(node, ast.Assign) and [t.id for t in node.targets
                                                  if isinstance(t, ast.Name)] == ["STUDY"]):
                kw = {k.arg: k.value for k in node.value.keywords}
                names.append(ast.literal_eval(kw["name"]))
    return names


def _snapshot() -> dict:
    """Size and modification time of every file under docs/ and fixtures/."""
    out = {}
    for top in WATCHED:
        for dirpath, _, files in os.walk(ROOT / top):
            for f in files:
                st = os.stat(os.path.join(dirpath, f))
                out[os.path.join(dirpath, f)] = (st.st_size, st.st_mtime_ns)
    return out


def _run(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "pipelines", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def test_every_study_module_declares_one_study():
    names = _study_names()
    assert len(names) == len(list(STUDIES.glob("[!_]*.py")))
    assert len(set(names)) == len(names)


@pytest.mark.slow
@pytest.mark.subprocess
def test_list_shows_every_study():
    res = _run("list", timeout=120)
    assert res.returncode == 0, res.stderr
    for name in _study_names():
        assert f"`{name}`" in res.stdout


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("name", _study_names())
def test_quick_run(name, tmp_path):
    before = _snapshot()
    res = _run("run", name, "--quick", "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr[-3000:]
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("|")]
    assert len(lines) >= 3 and lines[1].startswith("|---"), res.stdout[-2000:]
    assert _snapshot() == before, "a quick run changed docs/ or fixtures/"


@pytest.mark.slow
@pytest.mark.subprocess
@pytest.mark.parametrize("args", [
    ["--quick", "--docs"],                       # docs record full runs only
    ["--docs", "--set", "tiles=64"],             # ... with the default options
    ["--out", str(ROOT / "fixtures" / "x")],     # never into an input folder
])
def test_run_refuses_to_write_docs_or_inputs_wrongly(args):
    before = _snapshot()
    res = _run("run", "speed-memory", *args, timeout=120)
    assert res.returncode != 0
    assert _snapshot() == before
    assert not (ROOT / "fixtures" / "x").exists()
