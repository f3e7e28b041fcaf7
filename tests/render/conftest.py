"""Fixtures of the render tests."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def variant():
    """The fastest spectral variant that works here, set for the module's tests."""
    mi = pytest.importorskip("mitsuba")
    from microfacet.render.variants import choose_variant

    v, _ = choose_variant()
    mi.set_variant(v)
    return v
