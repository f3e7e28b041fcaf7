"""microfacet.analysis.search: the coarse-to-fine search against a full search, the parabola
refinement against analytic vertices, constrained searches and local minima."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.analysis.search import (
    coarse_to_fine,
    full_scan,
    local_minima,
    parabola,
    refine,
)


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

    scan = coarse_to_fine(f, n, rows, stride=stride)
    r = np.arange(rows)
    full = np.argmin(f(np.broadcast_to(np.arange(n), (rows, n))), axis=1)
    np.testing.assert_array_equal(scan.node, full)
    kw = scan.best
    inside = (full > 0) & (full < n - 1)
    np.testing.assert_array_equal(scan.nodes[r, kw - 1][inside], full[inside] - 1)
    np.testing.assert_array_equal(scan.nodes[r, kw + 1][inside], full[inside] + 1)
    np.testing.assert_array_equal(scan.value, f(full[:, None])[:, 0])
    assert sum(calls[:2]) < n                      # fewer evaluations than the full search


def test_stride_one_is_the_full_scan():
    x = np.linspace(-1, 1, 21)
    c = np.array([[-0.33], [0.5], [2.0]])

    def f(nodes):
        return (x[nodes] - c) ** 2

    a, b = coarse_to_fine(f, x.size, 3, stride=1), full_scan(f, x.size, 3)
    np.testing.assert_array_equal(a.node, b.node)
    np.testing.assert_array_equal(a.node, np.argmin(np.abs(x[None, :] - c), axis=1))
    assert b.nodes.shape == (3, x.size)
    np.testing.assert_array_equal(b.at(np.array([0, 5, 20])), f(np.array([[0], [5], [20]]))[:, 0])


def test_refine_finds_the_vertex_of_a_parabola_between_nodes():
    """On a quadratic the parabola through three nodes is the function itself: the vertex,
    its value and the curvature are exact (off the grid's nodes)."""
    step = 0.25
    x = np.arange(0.0, 10.0 + step / 2, step)
    rng = np.random.default_rng(0)
    c = rng.uniform(0.6, 9.4, 50)[:, None]
    a = rng.uniform(0.5, 3.0, 50)[:, None]
    v0 = rng.uniform(-1, 1, 50)[:, None]

    def f(nodes):
        return a * (x[nodes] - c) ** 2 + v0

    m = refine(coarse_to_fine(f, x.size, 50, stride=4), x.size)
    np.testing.assert_allclose(x[m.node] + m.offset * step, c[:, 0], atol=1e-9)
    np.testing.assert_allclose(m.vertex, v0[:, 0], atol=1e-9)
    np.testing.assert_allclose(m.curvature, 2 * a[:, 0] * step ** 2, rtol=1e-9)
    assert np.all(np.abs(m.offset) <= 0.5 + 1e-12)      # the least node is the nearest
    assert np.all(m.vertex <= m.value + 1e-12)


def test_refine_does_not_extrapolate_past_the_ends():
    x = np.arange(11.0)

    def f(nodes):
        return (x[nodes] - np.array([[-3.0], [14.0]])) ** 2

    m = refine(coarse_to_fine(f, x.size, 2, stride=3), x.size)
    assert m.node.tolist() == [0, 10]
    assert m.offset.tolist() == [0.0, 0.0]
    np.testing.assert_array_equal(m.vertex, m.value)
    np.testing.assert_array_equal(m.value, [9.0, 16.0])


def test_parabola_offset_clipped_and_none_where_not_convex():
    off, vert, curv = parabola(np.array([1.0, 4.0]), np.array([2.0, 1.0]),
                               np.array([1.0, 2.0]))
    assert off[0] == 0.0 and vert[0] == 2.0 and np.isnan(curv[0])   # concave
    assert off[1] == pytest.approx(0.25) and curv[1] == 4.0
    # a vertex beyond the neighbours (1.5 steps) is clipped to one step
    off, _, _ = parabola(np.array([4.0]), np.array([2.0]), np.array([1.0]))
    assert off[0] == 1.0


@pytest.mark.parametrize("stride", [1, 3])
def test_allowed_masks_constrain_the_search_and_share_the_coarse_pass(stride):
    """Each mask gives the least allowed node (as a full search over the allowed nodes); a
    list of masks gives one scan per mask."""
    rng = np.random.default_rng(stride)
    n, rows = 40, 200
    x = np.arange(n, dtype=float)
    centre = rng.uniform(0, n, rows)[:, None]

    def f(nodes):
        return (x[nodes] - centre) ** 2

    lo = rng.integers(0, n - 12, rows)
    window = (np.arange(n)[None, :] >= lo[:, None]) & (np.arange(n)[None, :] < lo[:, None] + 12)
    everything = np.ones((rows, n), bool)
    scans = coarse_to_fine(f, n, rows, stride=stride, allowed=[window, everything])
    assert isinstance(scans, list) and len(scans) == 2
    values = f(np.broadcast_to(np.arange(n), (rows, n)))
    want = np.argmin(np.where(window, values, np.inf), axis=1)
    np.testing.assert_array_equal(scans[0].node, want)
    np.testing.assert_array_equal(scans[1].node, np.argmin(values, axis=1))
    assert window[np.arange(rows), scans[0].node].all()
    single = coarse_to_fine(f, n, rows, stride=stride, allowed=window)
    np.testing.assert_array_equal(single.node, want)


def test_local_minima_least_first():
    curve = np.array([5.0, 3.0, 4.0, 1.0, 2.0, 2.0, 0.5, np.nan, 0.1])
    idx = local_minima(curve)
    assert idx.tolist() == [8, 6, 3, 1]
    assert local_minima(np.array([np.nan, np.nan])).size == 0
    assert local_minima(np.arange(5.0)).tolist() == [0]
