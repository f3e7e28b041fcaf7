"""The curated public API (docs/api.md): the subpackages' ``__init__.pyi`` stubs, the ``__all__``
lists, the top-level entry points' docstrings and the References of the method modules.

The stubs and the modules are read with ``ast`` where the check does not need the objects, so
that a module's import errors show up in its own tests, not here.
"""

from __future__ import annotations

import ast
import importlib
import inspect
import re
from pathlib import Path

import pytest

import microfacet

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "microfacet"
API_MD = ROOT / "docs" / "api.md"
#: The subpackages whose public names are declared in an ``__init__.pyi`` stub.
PACKAGES = ("analysis", "colour", "core", "focus", "forward", "io", "napari", "optics",
            "render", "report")
#: Modules that implement a published method: their docstring has a References section whose
#: first entry is the seed paper.
METHOD_MODULES = (
    "optics/thinfilm.py", "optics/constants.py", "optics/spectrumfit.py",
    "colour/difference.py", "colour/colorimetry.py", "colour/adaptation.py",
    "colour/transfer.py", "colour/srgb.py", "colour/table.py", "colour/model.py",
    "focus/measures.py", "focus/peaks.py", "focus/normals.py", "focus/uncertainty.py",
    "focus/height.py", "focus/align.py",
    "forward/brdf.py", "forward/halfvector.py", "forward/eq6.py", "forward/angular.py",
    "forward/compare.py",
    "analysis/mixtures.py", "analysis/ndf_fit.py", "analysis/segmentation.py",
    "analysis/roi.py", "analysis/tilt.py", "analysis/mask.py", "analysis/colour_image.py",
    "analysis/sampling.py", "analysis/planes.py", "analysis/facet_thickness.py",
    "analysis/joint.py", "analysis/distributions.py", "analysis/identification.py",
    "analysis/pipeline.py",
)
SECTION = r"^{}\n-{{3,}}$"


def _stub(package: str | None) -> Path:
    return (PACKAGE / package if package else PACKAGE) / "__init__.pyi"


def _stub_imports(package: str | None) -> dict[str, str | None]:
    """``{name: module it comes from (None for a submodule)}`` of a package's stub."""
    names = {}
    for node in ast.parse(_stub(package).read_text(encoding="utf-8")).body:
        if isinstance(node, ast.ImportFrom):
            assert node.level == 1, f"{_stub(package)}: only `from .x import y` is read"
            for alias in node.names:
                assert alias.asname is None, f"{_stub(package)}: {alias.name} renamed"
                names[alias.name] = node.module
    return names


def _literal_all(tree: ast.Module):
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets):
            try:
                return ast.literal_eval(node.value)
            except ValueError:
                return None
    return None


def _module_all(relpath: str) -> list[str] | None:
    return _literal_all(ast.parse((PACKAGE / relpath).read_text(encoding="utf-8")))


def _top_level_bindings(tree: ast.Module) -> set[str]:
    bound = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            bound.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in targets:
                bound.update(n.id for n in ast.walk(t) if isinstance(n, ast.Name))
    return bound


def _public_modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if path.name != "__init__.py" and "_" != path.name[0]:
            yield rel


@pytest.mark.parametrize("package", [None, *PACKAGES], ids=lambda p: p or "microfacet")
def test_every_stub_name_loads(package):
    """Every name of the stub is an attribute of the package, loaded on first use from the
    module the stub names."""
    name = "microfacet" + (f".{package}" if package else "")
    pkg = importlib.import_module(name)
    for attr, module in _stub_imports(package).items():
        value = getattr(pkg, attr)
        if module is None:
            assert inspect.ismodule(value) and value.__name__ == f"{name}.{attr}"
        else:
            source = importlib.import_module(f"{name}.{module}")
            assert value is getattr(source, attr), f"{name}.{attr}"


@pytest.mark.parametrize("package", PACKAGES)
def test_each_package_all_is_its_stub(package):
    """A package's ``__all__`` (runtime) and the stub's own ``__all__`` (what type checkers
    re-export) are exactly the names the stub imports; every module is listed."""
    pkg = importlib.import_module(f"microfacet.{package}")
    names = _stub_imports(package)
    assert pkg.__all__ == sorted(names)
    assert _literal_all(ast.parse(_stub(package).read_text(encoding="utf-8"))) == sorted(names)
    modules = {p.stem for p in (PACKAGE / package).glob("*.py") if p.name != "__init__.py"}
    assert {n for n, m in names.items() if m is None} == modules


@pytest.mark.parametrize("package", PACKAGES)
def test_stub_names_are_their_modules_documented_api(package):
    """A name a package re-exports is in its module's ``__all__``."""
    for attr, module in _stub_imports(package).items():
        if module is not None:
            listed = _module_all(f"{package}/{module.replace('.', '/')}.py")
            assert listed is not None and attr in listed, f"{package}.{module}.{attr}"


@pytest.mark.slow
@pytest.mark.parametrize("relpath", list(_public_modules()))
def test_module_all_lists_names_the_module_binds(relpath):
    """Every name of a module's ``__all__`` is bound at its top level, once, and public."""
    tree = ast.parse((PACKAGE / relpath).read_text(encoding="utf-8"))
    listed = _literal_all(tree)
    if listed is None:
        return
    assert len(listed) == len(set(listed)), relpath
    assert not [n for n in listed if n.startswith("_")], relpath
    missing = set(listed) - _top_level_bindings(tree)
    assert not missing, f"{relpath}: {sorted(missing)}"


def test_top_level_callables_have_numpydoc_docstrings():
    """Every public callable of ``import microfacet`` documents its parameters or shows an
    example, as numpydoc sections."""
    lacking = []
    for name in microfacet.__all__:
        obj = getattr(microfacet, name)
        if not callable(obj):
            continue
        doc = inspect.getdoc(obj) or ""
        if not any(re.search(SECTION.format(s), doc, re.M) for s in ("Parameters", "Examples")):
            lacking.append(name)
    assert lacking == []


def test_docs_api_names_every_public_name():
    """docs/api.md lists every top-level name and every name a subpackage re-exports."""
    api = API_MD.read_text(encoding="utf-8")
    missing = [n for n in microfacet.__all__ if n != "__version__" and f"`{n}" not in api]
    for package in PACKAGES:
        missing += [f"{package}.{n}" for n, m in _stub_imports(package).items()
                    if m is not None and f"`{n}`" not in api]
    assert missing == []
    assert 15 <= len(microfacet.__all__) <= 25


@pytest.mark.parametrize("relpath", METHOD_MODULES)
def test_method_modules_cite_their_sources_seed_first(relpath):
    doc = ast.get_docstring(ast.parse((PACKAGE / relpath).read_text(encoding="utf-8"))) or ""
    match = re.search(SECTION.format("References") + "\n", doc, re.M)
    assert match, f"{relpath}: no References section"
    first = re.split(r"\n\.\. \[2\]|\n\n", doc[match.end():])[0]
    assert "Nagata" in first, f"{relpath}: the seed paper is not the first reference"
