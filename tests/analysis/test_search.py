"""microfacet.analysis.search: the coarse-to-fine search against a full search."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.analysis.search import coarse_to_fine


@pytest.mark.parametrize("stride", [2, 4, 5])
def test_unimodal_rows_give_the_full_searchs_least_node(stride):
    """Convex curves with minima anywhere, at the ends included: the least node equals a
    full search's, and its neighbours in the returned window are the grid's neighbours."""
    rng = np.random.default_rng(stride)
    n, rows = 57, 400
    x = np.arange(n, dtype=float)
    centre = rng.uniform(-5, n + 5, rows)[:, None]
    width = rng.uniform(0.5, 30, rows)[:, None]
    calls = []

    def f(nodes):
        calls.append(nodes.shape[1])
        return np.abs(x[nodes] - centre) ** 1.5 / width

    nodes, values, kw = coarse_to_fine(f, n, rows, stride=stride)
    r = np.arange(rows)
    full = np.argmin(f(np.broadcast_to(np.arange(n), (rows, n))), axis=1)
    np.testing.assert_array_equal(nodes[r, kw], full)
    inside = (full > 0) & (full < n - 1)
    np.testing.assert_array_equal(nodes[r, kw - 1][inside], full[inside] - 1)
    np.testing.assert_array_equal(nodes[r, kw + 1][inside], full[inside] + 1)
    assert sum(calls[:2]) < n                      # fewer evaluations than the full search
