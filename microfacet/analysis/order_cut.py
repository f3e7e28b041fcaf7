"""Facets' interference orders decided together: a minimum cut over the facet graph.

A film's colours an order apart are near-aliases (2-3 ΔE00 at the same tilt, docs/accuracy.md,
"Facets read an order off"), so one facet's least-ΔE order is a toss-up under JPEG, tilt or
white-balance errors, while the summed misfit of a whole region of one film is not. The
region is not known; the image says where it may end: neighbouring facets of one film have
close colours, a boundary between films a colour step. Each facet has two states, the order
it was read in and its runner-up (``FacetThickness.thickness_other_order_nm``), and the
labelling minimises

    E = Σ_i a_i · e_i(s_i)²  +  Σ_(i,j) λ · exp(-ΔE_ij² / 2c²) · √min(a_i, a_j) · [s_i ≠ s_j]

with ``a_i`` a facet's pixels, ``e_i`` its ΔE00 in the state (capped at :data:`CAP_DE`; the
runner-up's plus ``joint.order_cut_keep_de``: a facet leaves the order it was read in only
where its neighbours' colours ask for it), ``ΔE_ij`` the step between two neighbours' mean
colours, ``c`` = ``joint.order_cut_contrast_de`` and ``λ`` = ``joint.order_cut_strength``.
The states "the lower of the two orders" and "the upper" are a binary labelling whose
pairwise term is submodular where the two neighbours' pairs of candidates lie in the same two
orders (the other pairs carry no term), so one minimum s-t cut gives the exact minimum
(Boykov & Kolmogorov 2004; Kolmogorov & Zabih 2004), solved with
:func:`scipy.sparse.csgraph.maximum_flow` on integer capacities.

References
----------
Y. Boykov and V. Kolmogorov, "An experimental comparison of min-cut/max-flow algorithms for
energy minimization in vision", IEEE TPAMI 26(9), 1124-1137 (2004).
V. Kolmogorov and R. Zabih, "What energy functions can be minimized via graph cuts?", IEEE
TPAMI 26(2), 147-159 (2004).
"""

from __future__ import annotations

import numpy as np

from ..colour.difference import delta_e_2000
from ..core.lazy import load
from .facet_thickness import FacetThickness
from .options import JointOptions

sparse = load("scipy.sparse")
csgraph = load("scipy.sparse.csgraph")

__all__ = ["CAP_DE", "order_cut"]

#: ΔE00 at which a facet's misfit is capped in the cut's data term: a dust speck or a pit
#: fits no order and should not decide its neighbours'.
CAP_DE = 10.0
#: Capacities are the energy's terms × this, rounded to integers (the max-flow solver's).
_SCALE = 100.0


def _capacities(x) -> np.ndarray:
    return np.minimum(np.round(np.asarray(x) * _SCALE), 2 ** 30).astype(np.int32)


def _source_side(graph, source) -> np.ndarray:
    """The nodes a maximum flow from ``source`` leaves reachable in the residual graph."""
    flow = csgraph.maximum_flow(graph, source, graph.shape[0] - 1).flow
    residual = (graph - flow).tocsr()
    residual.data = np.maximum(residual.data, 0)
    residual.eliminate_zeros()
    seen = np.zeros(graph.shape[0], bool)
    seen[csgraph.breadth_first_order(residual, source, directed=True,
                                     return_predecessors=False)] = True
    return seen


def order_cut(thickness: FacetThickness, mean_lab, pairs, *, period_nm,
              options: JointOptions) -> np.ndarray:
    """The facets whose runner-up order the minimum cut chooses (module notes).

    Parameters
    ----------
    thickness : FacetThickness
        Each facet's thickness (nm) and ΔE00 in the order it was read in, the same in its
        runner-up order (NaN: none; the facet keeps its order), and the pixels of its mean
        colour (0: no sample).
    mean_lab : ndarray, shape (S, 3)
        Each facet's mean CIELAB.
    pairs : ndarray of int, shape (P, 2)
        Neighbouring facets (:func:`~.segmentation.neighbour_pairs`).
    period_nm : float
        The colours' period in thickness: two facets' candidates lie in the same orders
        where they differ by less than half of it.
    options : JointOptions
        ``order_cut_strength`` (λ: the cost, ΔE00² · px^½, of a boundary between two
        neighbours of one colour read in different orders; 0 keeps every facet's order),
        ``order_cut_contrast_de`` (c: the colour step, ΔE00, at which that cost has fallen to
        e^-½ of it) and ``order_cut_keep_de`` (added to the runner-up's ΔE00 in the data
        term).

    Returns
    -------
    ndarray of bool, shape (S,)
        The facets to read in their runner-up order.

    Examples
    --------
    Five facets in a row of one colour: four read at 100 nm fit it at 1 ΔE00, the middle
    one read an order up fits 215 nm at 0.8 and 100 nm at 1.2; its neighbours take it back.
    A sixth, of a colour 30 ΔE00 away, keeps its own order.

    >>> from microfacet.analysis.options import JointOptions
    >>> th = FacetThickness(
    ...     thickness_nm=np.array([100.0, 100.0, 215.0, 100.0, 100.0, 215.0]),
    ...     sigma_nm=np.full(6, 0.5), delta_e=np.array([1.0, 1.0, 0.8, 1.0, 1.0, 0.5]),
    ...     at_window_edge=np.zeros(6, bool), n_pixels=np.full(6, 50),
    ...     delta_e_other_order=np.array([3.0, 3.0, 1.2, 3.0, 3.0, 1.0]),
    ...     thickness_other_order_nm=np.array([215.0, 215.0, 100.0, 215.0, 215.0, 100.0]))
    >>> lab = np.array([[60.0, 10, 10]] * 5 + [[60.0, 40, 10]])
    >>> pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5]])
    >>> order_cut(th, lab, pairs, period_nm=115.0, options=JointOptions()).tolist()
    [False, False, True, False, False, False]
    """
    d = np.asarray(thickness.thickness_nm, dtype=np.float64)
    d2 = np.asarray(thickness.thickness_other_order_nm, dtype=np.float64)
    a = np.asarray(thickness.n_pixels, dtype=np.float64)
    e1 = np.minimum(np.asarray(thickness.delta_e, dtype=np.float64), CAP_DE)
    e2 = (np.minimum(np.asarray(thickness.delta_e_other_order, dtype=np.float64), CAP_DE)
          + options.order_cut_keep_de)
    ok = np.isfinite(d) & np.isfinite(d2) & np.isfinite(e1) & np.isfinite(e2) & (a > 0)
    if options.order_cut_strength <= 0 or ok.sum() < 2:
        return np.zeros(d.size, bool)
    low = d <= d2                                   # read in the lower of its two orders
    lo, hi = np.where(low, d, d2), np.where(low, d2, d)
    cost_lo = np.where(ok, a * np.where(low, e1, e2) ** 2, 0.0)
    cost_hi = np.where(ok, a * np.where(low, e2, e1) ** 2, 0.0)
    i, j = _same_orders(pairs, ok, lo, hi, period_nm)
    step = delta_e_2000(np.asarray(mean_lab)[i], np.asarray(mean_lab)[j])
    link = (options.order_cut_strength * np.sqrt(np.minimum(a[i], a[j]))
            * np.exp(-step ** 2 / (2.0 * options.order_cut_contrast_de ** 2)))
    upper = _min_cut(cost_lo, cost_hi, i, j, link)
    return ok & (upper != ~low)


def _same_orders(pairs, ok, lo, hi, period_nm):
    """The neighbouring pairs of samples whose two candidates lie in the same two orders."""
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    i, j = p[:, 0], p[:, 1]
    same = ok[i] & ok[j]
    same[same] = ((np.abs(lo[i[same]] - lo[j[same]]) < period_nm / 2)
                  & (np.abs(hi[i[same]] - hi[j[same]]) < period_nm / 2))
    return i[same], j[same]


def _min_cut(cost_lo, cost_hi, i, j, link) -> np.ndarray:
    """The binary labelling (True: the upper order) of least Σ cost + Σ link [differ]: the
    source side of a minimum s-t cut, an edge source → k costing k's upper state and k →
    sink its lower one, each less their common part."""
    S = cost_lo.size
    base = np.minimum(cost_lo, cost_hi)
    src, snk = S, S + 1
    rows = np.concatenate([np.full(S, src), np.arange(S), i, j])
    cols = np.concatenate([np.arange(S), np.full(S, snk), j, i])
    cap = _capacities(np.concatenate([cost_hi - base, cost_lo - base, link, link]))
    keep = cap > 0
    graph = sparse.csr_matrix((cap[keep], (rows[keep], cols[keep])), shape=(S + 2, S + 2))
    graph.sum_duplicates()
    return ~_source_side(graph, src)[:S]
