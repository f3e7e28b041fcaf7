"""Fixtures shared by the tests of several packages.

Tests mirror the package (``tests/<package>/test_<module>.py``); fixtures used by one package
only live in ``tests/<package>/conftest.py``. Test modules never import each other: what
they share is here, as fixtures.
"""

from __future__ import annotations

import functools
import inspect

import numpy as np
import pytest


@pytest.fixture(scope="session")
def thickness_samples():
    """``thickness_samples(rng, comps, n)``: samples of a Gaussian mixture given as
    ``[(weight, mean_nm, sd_nm), ...]``."""
    def draw(rng, comps, n):
        w = np.array([c[0] for c in comps], dtype=float)
        k = rng.choice(len(comps), size=n, p=w / w.sum())
        mu = np.array([c[1] for c in comps])[k]
        sd = np.array([c[2] for c in comps])[k]
        return rng.normal(mu, sd)
    return draw


@pytest.fixture(scope="session")
def tilt_samples():
    """``tilt_samples(rng, comps, n)``: tilts (deg) of Gaussian-slope lobes
    ``[(weight, sd_deg), ...]``: slopes N(0, s²) per axis, tilt = atan(hypot)."""
    def draw(rng, comps, n):
        w = np.array([c[0] for c in comps], dtype=float)
        k = rng.choice(len(comps), size=n, p=w / w.sum())
        s = np.tan(np.radians(np.array([c[1] for c in comps])[k]))
        return np.degrees(np.arctan(np.hypot(rng.normal(0, 1, n) * s,
                                             rng.normal(0, 1, n) * s)))
    return draw


@pytest.fixture(scope="session")
def render_stack():
    """``render_stack(height, z, *, seed=0, blur_per_um=0.7, noise=0.0, rgb=False,
    flat_mask=None)``: float32 images in [0, 1] of a random texture at each stage height
    ``z`` with Gaussian defocus σ = 0.3 + k|z − h(x)| px (space-variant blur by linear
    interpolation between precomputed blur levels). Independent of microfacet's synth."""
    import cv2

    def render(height, z, *, seed=0, blur_per_um=0.7, noise=0.0, rgb=False, flat_mask=None):
        rng = np.random.default_rng(seed)
        hgt = np.asarray(height, np.float32)
        tex = cv2.GaussianBlur(rng.random(hgt.shape + ((3,) if rgb else ())).astype(np.float32),
                               (0, 0), 0.8)
        tex = (tex - tex.mean()) / tex.std() * 0.12 + 0.5
        if flat_mask is not None:
            tex[flat_mask] = 0.5
        levels = np.arange(0.0, 0.3 + blur_per_um * (np.ptp(z) + np.ptp(hgt)) + 0.5, 0.25)
        out = []
        for zk in z:
            sig = 0.3 + blur_per_um * np.abs(zk - hgt)
            pos = (sig - levels[0]) / 0.25
            lo = np.floor(pos).astype(int)
            t = (pos - lo).astype(np.float32)
            img = np.zeros_like(tex)
            for li in np.unique(lo):
                b0 = cv2.GaussianBlur(tex, (0, 0), max(levels[li], 1e-3)) if levels[li] > 0 \
                    else tex
                b1 = cv2.GaussianBlur(tex, (0, 0), levels[li + 1])
                m = lo == li
                tt = t[m][:, None] if rgb else t[m]
                img[m] = (1 - tt) * b0[m] + tt * b1[m]
            if noise:
                img = img + rng.normal(0, noise, img.shape).astype(np.float32)
            out.append(np.clip(img, 0, 1).astype(np.float32))
        return out
    return render


@pytest.fixture(scope="session")
def batch_drawer(tmp_path_factory):
    """A folder of two small synthetic stacks (``a``: nd, ``b``: sd, 96×96 px, 8 slices)
    and one broken one (``broken``: a ``stack.json`` without ``format``). Tests that change
    ``broken`` put it back."""
    from microfacet.cli import main

    root = tmp_path_factory.mktemp("drawer")
    for name, preset, seed in (("a", "nd", 1), ("b", "sd", 2)):
        assert main(["synth", str(root / name), "--preset", preset, "--seed", str(seed),
                     "--size", "96x96", "--slices", "8", "-q"]) == 0
    (root / "broken").mkdir()
    (root / "broken" / "stack.json").write_text("{}")
    return root


#: Fixtures that run a whole analysis or write a report (once per session or module): every
#: test that uses one is ``slow``, so that ``-m "not slow"`` never pays for them.
SLOW_FIXTURES = frozenset({"nd_analysis", "results", "report", "results_copy", "nd", "sd",
                           "clean"})
#: What a test calls to start a child process (the ``subprocess`` marker).
_SPAWNS = ("subprocess.", "sys.executable", "_run_bounded(", "lock_holder", "slow_holder")


@functools.cache
def _defines_runner(module) -> bool:
    """The test module imports subprocess and defines a ``_run`` helper (read once)."""
    return "subprocess" in vars(module) and "def _run(" in inspect.getsource(module)


def _spawns(item) -> bool:
    fn = getattr(item, "function", None)
    module = inspect.getmodule(fn) if fn is not None else None
    if module is None or "subprocess" not in vars(module):
        return False
    try:
        source = inspect.getsource(fn)
    except (OSError, TypeError):
        return False
    return (("_run(" in source and _defines_runner(module))
            or any(s in source for s in _SPAWNS)
            or bool({"lock_holder", "slow_holder"} & set(item.fixturenames)))


def pytest_collection_modifyitems(config, items):
    """Mark tests that use a :data:`SLOW_FIXTURES` fixture ``slow`` and tests that start a
    child process ``subprocess`` (registered in pyproject.toml)."""
    for item in items:
        if SLOW_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
        if _spawns(item):
            item.add_marker(pytest.mark.subprocess)
