"""Coarse-to-fine search for the least value on a uniform grid, row by row.

The analysis' searches (a pixel's tilt over the tilt grid, a facet's thickness over a fine
window) evaluate an expensive colour difference at every grid node of every row. Where the
objective is unimodal over the grid, or its basins are wider than a few nodes,
:func:`coarse_to_fine` finds the same least node at a fraction of the evaluations: every
``stride``-th node first, then every node within ±``stride`` of the best of those.

Examples
--------
>>> x = np.linspace(0.0, 10.0, 41)
>>> f = lambda nodes: (x[nodes] - np.array([[3.1], [7.7]])) ** 2   # two rows
>>> nodes, values, kw = coarse_to_fine(f, x.size, 2, stride=4)
>>> x[nodes[np.arange(2), kw]].tolist()
[3.0, 7.75]
"""

from __future__ import annotations

import numpy as np

__all__ = ["coarse_to_fine"]


def coarse_to_fine(evaluate, n_nodes: int, n_rows: int, *, stride: int):
    """The least value of ``evaluate`` over grid nodes ``0 .. n_nodes-1``, for every row.

    Parameters
    ----------
    evaluate : callable
        ``evaluate(nodes) -> values``: ``nodes`` an int array (n_rows, w) of node indices per
        row, ``values`` the objective there, same shape.
    n_nodes, n_rows : int
    stride : int
        The coarse pass takes every ``stride``-th node (and the last); the fine pass every
        node within ±``stride`` of the coarse best, plus one more on each side.

    Returns
    -------
    nodes : ndarray of int, shape (n_rows, 2·stride + 3)
        The fine pass's nodes (clamped to the grid, so repeated at its ends).
    values : ndarray, shape (n_rows, 2·stride + 3)
        ``evaluate(nodes)``.
    kw : ndarray of int, shape (n_rows,)
        Column of the least value among the inner columns: ``nodes[r, kw - 1]`` and
        ``nodes[r, kw + 1]`` are its neighbours (for a parabola through three nodes).
    """
    coarse = np.unique(np.r_[np.arange(0, n_nodes, stride), n_nodes - 1])
    best = coarse[np.argmin(evaluate(np.broadcast_to(coarse, (n_rows, coarse.size))), axis=1)]
    nodes = np.clip(best[:, None] + np.arange(-stride - 1, stride + 2)[None, :], 0, n_nodes - 1)
    values = evaluate(nodes)
    inner = np.full(nodes.shape[1], np.inf)
    inner[1:-1] = 0.0
    kw = np.argmin(values + inner[None, :], axis=1)
    return nodes, values, kw
