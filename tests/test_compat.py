"""The compatibility names outside scripts rely on (docs/api.md): the same functions, a
warning that names where they live now, and the document they cite exists."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import pytest

import microfacet
from microfacet.colour.difference import delta_e_2000
from microfacet.optics.thinfilm import reflectance

DOCS = Path(__file__).resolve().parents[1] / "docs"


@pytest.mark.parametrize("name, attr, target", [("microfacet.thinfilm", "reflectance", reflectance),
                                                ("microfacet.color", "delta_e_2000",
                                                 delta_e_2000)])
def test_compat_modules_are_the_functions_and_warn(name, attr, target):
    sys.modules.pop(name, None)
    with pytest.warns(DeprecationWarning, match="docs/api.md"):
        module = importlib.import_module(name)
    assert getattr(module, attr) is target
    assert (DOCS / "api.md").is_file()


def test_the_top_level_names_load_and_are_documented():
    """Every name of ``microfacet.__all__`` loads (lazily) and docs/api.md lists it."""
    api = (DOCS / "api.md").read_text(encoding="utf-8")
    for name in microfacet.__all__:
        assert getattr(microfacet, name) is not None
        if name != "__version__":
            assert f"`{name}" in api, name
    assert 15 <= len(microfacet.__all__) <= 25
