"""The report package (microfacet.report): lazy public names and the rules its modules keep."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import microfacet.report as report

PACKAGE = Path(report.__file__).parent
MODULES = sorted(PACKAGE.glob("*.py"))


@pytest.mark.slow
def test_import_does_not_import_matplotlib_nor_the_modules():
    code = ("import sys, microfacet.report as r; a = 'matplotlib' in sys.modules; "
            "b = 'microfacet.report.writer' in sys.modules; import microfacet.report.writer; "
            "print(a, b, 'matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.split() == ["False", "False", "False"]


def test_public_names():
    from microfacet.report import figures, layout, page_parameters, writer

    assert report.write_report is writer.write_report and report.PAGES == writer.PAGES
    assert report.parameter_tables is page_parameters.parameter_tables
    assert report.plot_maps is figures.plot_maps
    assert (report.MAX_MAP_PX, report.NO_VALUE) == (layout.MAX_MAP_PX, layout.NO_VALUE)
    assert {"write_report", "PAGES", "parameter_tables", "plot_maps"} <= set(report.__all__)


def test_every_page_module_has_a_name_a_title_and_draw():
    from microfacet.report import writer

    for name in writer.PAGES:
        mod = __import__(f"microfacet.report.page_{name}", fromlist=["draw"])
        assert mod.NAME == name and mod.TITLE and callable(mod.draw)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: p.name)
def test_module_rules(path):
    """Imports at module top only; no underscore name of another module; ≤ 500 lines."""
    text = path.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 500
    tree = ast.parse(text)
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            inner = [n for n in ast.walk(node) if isinstance(n, (ast.Import, ast.ImportFrom))]
            assert not inner, f"{path.name}: import inside {node.name}"
        if isinstance(node, ast.ImportFrom):
            private = [a.name for a in node.names
                       if a.name.startswith("_") and not a.name.startswith("__")]
            assert not private, f"{path.name}: imports {private} from {node.module}"
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                and node.value.id in {p.stem for p in MODULES} \
                and node.attr.startswith("_") and not node.attr.startswith("__"):
            pytest.fail(f"{path.name}: uses {node.value.id}.{node.attr}")
