"""Deferred imports (microfacet.core.lazy): a proxied module is imported on its first
attribute use, never before; packages expose names without importing their modules.
Each check runs in a fresh interpreter (``sys.modules`` of the test process already holds
everything)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

HEAVY = ("cv2", "scipy", "sklearn", "skimage", "colour", "matplotlib", "tifffile", "joblib",
         "distributed")


def _run(code: str):
    """Run ``code`` in a fresh interpreter; it prints one JSON value, returned here."""
    out = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_load_returns_a_proxy_that_imports_on_first_use():
    r = _run("""
        import json, sys
        from microfacet.core.lazy import load
        m = load("wave")
        before = "wave" in sys.modules
        name = type(m).__name__
        text = repr(m)
        err = m.Error                   # first use: imported now
        after = "wave" in sys.modules
        cached = "Error" in vars(m)     # later uses are plain attribute lookups
        print(json.dumps([before, name, text, after, cached,
                          err is sys.modules["wave"].Error]))
    """)
    assert r == [False, "_LazyModule", "<lazy module 'wave'>", True, True, True]


def test_a_proxy_that_keeps_nothing_follows_the_module():
    """keep=False (Mitsuba: mi.BSDF is the variant's set at the time) looks every attribute up
    anew."""
    r = _run("""
        import json, sys
        from microfacet.core.lazy import load
        m = load("wave", keep=False)
        first = m.Error
        sys.modules["wave"].Error = KeyError
        print(json.dumps([first is not KeyError, m.Error is KeyError, "Error" in vars(m)]))
    """)
    assert r == [True, True, False]


def test_an_imported_module_is_returned_itself():
    r = _run("""
        import json, sys, wave
        from microfacet.core.lazy import load
        print(json.dumps(load("wave") is wave))
    """)
    assert r is True


def test_a_missing_module_fails_on_first_use_not_on_load():
    r = _run("""
        import json
        from microfacet.core.lazy import load
        m = load("no_such_module_xyz")        # no error yet
        try:
            m.thing
        except ModuleNotFoundError as exc:
            print(json.dumps(exc.name))
    """)
    assert r == "no_such_module_xyz"


def test_importing_every_subpackage_imports_no_heavy_library():
    r = _run(f"""
        import json, sys
        import microfacet
        for pkg in ("core", "optics", "colour", "io", "focus", "analysis", "forward",
                    "report", "workflow"):
            __import__("microfacet." + pkg)
        print(json.dumps([m for m in {HEAVY!r} if m in sys.modules]))
    """)
    assert r == []


@pytest.mark.parametrize("package, name, module", [
    ("microfacet.optics", "reflectance", "microfacet.optics.thinfilm"),
    ("microfacet.focus", "height_from_focus", "microfacet.focus.height"),
    ("microfacet.io", "Results", "microfacet.io.results"),
    ("microfacet.core", "NDFMixture", "microfacet.core.distributions"),
])
@pytest.mark.slow
def test_package_names_load_their_module_on_first_use(package, name, module):
    r = _run(f"""
        import importlib, json, sys
        pkg = importlib.import_module({package!r})
        listed = {name!r} in dir(pkg) and {name!r} in pkg.__all__
        before = {module!r} in sys.modules
        obj = getattr(pkg, {name!r})
        same = obj is getattr(sys.modules[{module!r}], {name!r})
        try:
            getattr(pkg, "no_such_name")
            missing = "no error"
        except AttributeError:
            missing = "AttributeError"
        print(json.dumps([listed, before, same, missing]))
    """)
    assert r == [True, False, True, "AttributeError"]
