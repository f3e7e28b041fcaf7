"""The one grid minimiser of the analysis: least value on a uniform grid, row by row,
coarse-to-fine, refined by a parabola.

The analysis' searches (a pixel's tilt over the tilt grid, a facet's thickness in its
interference-order window and below the grid step, a ROI's thickness) evaluate an expensive
colour difference at every grid node of every row. Where the objective is unimodal over the
grid, or its basins are wider than a few nodes, :func:`coarse_to_fine` finds the least node at
a fraction of the evaluations: every ``stride``-th node first, then every node within
±``reach`` of the best of those (and one more on each side, for the parabola).
:func:`refine` puts a parabola through the least node and its two neighbours: the vertex,
its value and the curvature there (no extrapolation past the grid's ends).

Examples
--------
>>> x = np.linspace(0.0, 10.0, 41)
>>> f = lambda nodes: (x[nodes] - np.array([[3.1], [7.7]])) ** 2   # two rows
>>> scan = coarse_to_fine(f, x.size, 2, stride=4)
>>> x[scan.node].tolist()
[3.0, 7.75]
>>> m = refine(scan, x.size)
>>> np.round(x[m.node] + m.offset * (x[1] - x[0]), 6).tolist()
[3.1, 7.7]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Minimum", "Scan", "coarse_to_fine", "refine"]


@dataclass
class Scan:
    """The nodes a search evaluated last, per row.

    Attributes
    ----------
    nodes : ndarray of int, shape (n_rows, w)
        Node indices (clamped to the grid, so repeated at its ends).
    values : ndarray, shape (n_rows, w)
        The objective there.
    best : ndarray of int, shape (n_rows,)
        Column of the least value.
    """

    nodes: np.ndarray
    values: np.ndarray
    best: np.ndarray

    @property
    def node(self) -> np.ndarray:
        """The least node of each row."""
        return self.nodes[np.arange(self.nodes.shape[0]), self.best]

    @property
    def value(self) -> np.ndarray:
        """The least value of each row."""
        return self.values[np.arange(self.values.shape[0]), self.best]

    def at(self, node) -> np.ndarray:
        """The value at ``node`` (one per row; it must be among the row's nodes)."""
        node = np.asarray(node)
        if self.nodes.shape[1] > node.max(initial=0) and np.array_equal(
                self.nodes[0], np.arange(self.nodes.shape[1])) and self.nodes.strides[0] == 0:
            col = node                                  # a full scan: columns are nodes
        else:
            col = np.argmax(self.nodes == node[:, None], axis=1)
        return self.values[np.arange(self.values.shape[0]), col]


def _masked(values, nodes, allowed):
    if allowed is None:
        return values
    ok = np.take_along_axis(allowed, nodes, axis=1)
    return np.where(ok, values, np.inf)


def full_scan(evaluate, n_nodes: int, n_rows: int, *, allowed=None) -> Scan:
    """Every node of every row; the least over all of them (:func:`coarse_to_fine` with
    ``stride=1``)."""
    nodes = np.broadcast_to(np.arange(n_nodes), (n_rows, n_nodes))
    values = _masked(evaluate(nodes), nodes, allowed)
    return Scan(nodes, values, np.argmin(values, axis=1))


def coarse_to_fine(evaluate, n_nodes: int, n_rows: int, *, stride: int, reach: int | None = None,
                   allowed=None):
    """The least value of ``evaluate`` over grid nodes ``0 .. n_nodes-1``, for every row.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(nodes) -> values``: ``nodes`` an int array (n_rows, w) of node indices per
        row, ``values`` the objective there, same shape.
    n_nodes, n_rows : int
    stride : int
        The coarse pass takes every ``stride``-th node (and the last); 1: every node once
        (:func:`full_scan`).
    reach : int, optional
        The fine pass takes every node within ±``reach`` (default ``stride``) of the coarse
        best, plus one more on each side (the parabola's neighbours).
    allowed : ndarray of bool, shape (n_rows, n_nodes), or a list of them, optional
        Nodes a row may take (a constrained search). A list gives one :class:`Scan` per mask,
        sharing the evaluations of the coarse pass.

    Returns
    -------
    Scan, or a list of Scan (one per mask of ``allowed``)
        The fine pass; ``best`` is the least column among its inner ones (±``reach``), so that
        both of its neighbours were evaluated unless it is at an end of the grid.
    """
    masks = allowed if isinstance(allowed, (list, tuple)) else [allowed]
    if stride <= 1:
        scans = [full_scan(evaluate, n_nodes, n_rows, allowed=m) for m in masks]
        return scans if isinstance(allowed, (list, tuple)) else scans[0]
    reach = stride if reach is None else int(reach)
    coarse = np.unique(np.r_[np.arange(0, n_nodes, stride), n_nodes - 1])
    c_nodes = np.broadcast_to(coarse, (n_rows, coarse.size))
    c_values = evaluate(c_nodes)
    inner = np.full(2 * reach + 3, np.inf)
    inner[1:-1] = 0.0
    scans = []
    for m in masks:
        best = coarse[np.argmin(_masked(c_values, c_nodes, m), axis=1)]
        nodes = np.clip(best[:, None] + np.arange(-reach - 1, reach + 2)[None, :], 0,
                        n_nodes - 1)
        values = _masked(evaluate(nodes), nodes, m)
        scans.append(Scan(nodes, values, np.argmin(values + inner[None, :], axis=1)))
    return scans if isinstance(allowed, (list, tuple)) else scans[0]


def parabola(y0, y1, y2):
    """Vertex of the parabola through equally spaced values ``y0, y1, y2`` (arrays).

    Returns
    -------
    offset : ndarray
        Vertex position in grid steps from the middle node, clipped to [−1, 1]; 0 where the
        three values are not convex (``y0 − 2 y1 + y2 ≤ 0``).
    vertex : ndarray
        The parabola's value at ``offset``.
    curvature : ndarray
        ``y0 − 2 y1 + y2`` (second difference per step²), NaN where not convex.

    >>> off, v, c = parabola(np.array([4.0]), np.array([1.0]), np.array([2.0]))
    >>> off.tolist(), v.tolist(), c.tolist()
    ([0.25], [0.875], [4.0])
    """
    y0, y1, y2 = (np.asarray(y) for y in (y0, y1, y2))   # in their own precision
    den = y0 - 2.0 * y1 + y2
    with np.errstate(divide="ignore", invalid="ignore"):
        off = np.where(den > 0, np.clip(0.5 * (y0 - y2) / den, -1.0, 1.0), 0.0)
    return off, y1 - 0.25 * (y0 - y2) * off, np.where(den > 0, den, np.nan)


@dataclass
class Minimum:
    """The refined least value of each row of a :class:`Scan`.

    Attributes
    ----------
    node : ndarray of int
        The least grid node.
    offset : ndarray
        The parabola's vertex in grid steps from ``node`` (0 where ``node`` is at an end of the
        grid or the values about it are not convex).
    value : ndarray
        The value at ``node``.
    vertex : ndarray
        The parabola's value at the vertex (``value`` where ``offset`` is 0).
    curvature : ndarray
        Second difference of the values about ``clip(node, 1, n − 2)`` (NaN where not
        convex): at an end of the grid, that of the node next to it.
    """

    node: np.ndarray
    offset: np.ndarray
    value: np.ndarray
    vertex: np.ndarray
    curvature: np.ndarray


def refine(scan: Scan, n_nodes: int) -> Minimum:
    """The parabola through the least node of each row of ``scan`` and its neighbours."""
    k = scan.node
    km = np.clip(k, 1, max(n_nodes - 2, 1))
    y0, y1, y2 = scan.at(km - 1), scan.at(km), scan.at(km + 1)
    off, vert, curv = parabola(y0, y1, y2)
    inside = k == km
    value = scan.value.astype(np.float64)
    return Minimum(k, np.where(inside, off, 0.0), value, np.where(inside, vert, value), curv)


def local_minima(curve) -> np.ndarray:
    """Indices of the local minima of a 1-D curve (NaN ignored; the ends count), least first.

    >>> local_minima(np.array([3.0, 1.0, 2.0, 0.5, 0.7, np.nan])).tolist()
    [3, 1]
    """
    c = np.where(np.isfinite(curve), curve, np.inf)
    padded = np.concatenate([[np.inf], c, [np.inf]])
    is_min = (padded[1:-1] <= padded[:-2]) & (padded[1:-1] < padded[2:])
    idx = np.flatnonzero(is_min & np.isfinite(c))
    return idx[np.argsort(c[idx])]
