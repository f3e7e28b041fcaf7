"""analysis.order_cut: the facets' orders by a minimum cut, against exhaustive search and on
facet grids whose answer is known."""

import itertools

import numpy as np
import pytest

from microfacet.analysis.facet_thickness import FacetThickness
from microfacet.analysis.options import JointOptions
from microfacet.analysis.order_cut import CAP_DE
from microfacet.analysis.order_cut import order_cut as _order_cut
from microfacet.analysis.segmentation import neighbour_pairs
from microfacet.colour.difference import delta_e_2000

KW = dict(period_nm=115.0, strength=1000.0, contrast_de=5.0, keep_de=4.0)


def order_cut(d, de, d2, de2, area, lab, pairs, *, period_nm, strength, contrast_de, keep_de):
    """:func:`order_cut` of facets given as arrays, with the three joint options."""
    th = FacetThickness(np.asarray(d, float), np.full(len(d), 0.5), np.asarray(de, float),
                        np.zeros(len(d), bool), np.asarray(area), np.asarray(de2, float),
                        np.asarray(d2, float))
    options = JointOptions().replace(order_cut_strength=strength,
                                     order_cut_contrast_de=contrast_de,
                                     order_cut_keep_de=keep_de)
    return _order_cut(th, lab, pairs, period_nm=period_nm, options=options)


def _energy(state_upper, lo, hi, e_lo, e_hi, area, lab, pairs, *, period_nm, strength,
            contrast_de):
    """The energy of the module notes for a labelling (True: the upper order), written
    out term by term."""
    e = float(np.sum(area * np.where(state_upper, e_hi, e_lo) ** 2))
    for i, j in pairs:
        if abs(lo[i] - lo[j]) < period_nm / 2 and abs(hi[i] - hi[j]) < period_nm / 2 \
                and state_upper[i] != state_upper[j]:
            step = float(delta_e_2000(lab[i], lab[j]))
            e += strength * np.exp(-step ** 2 / (2 * contrast_de ** 2)) * np.sqrt(
                min(area[i], area[j]))
    return e


@pytest.mark.parametrize("seed", range(6))
def test_the_cut_is_the_exact_minimum_of_its_energy(seed):
    """Nine facets on a random graph, candidates in two or three orders, colours within a
    few ΔE00: the cut's labelling has the least energy of all 2⁹ (exhaustive search)."""
    rng = np.random.default_rng(seed)
    S = 9
    base = rng.choice([100.0, 100.0, 100.0, -15.0], S)        # a few in lower orders
    d = base + rng.choice([0.0, 115.0], S) + rng.normal(0, 1, S)
    d2 = np.where(d > base + 50, base, base + 115.0) + rng.normal(0, 1, S)
    de, de2 = rng.uniform(0.3, 4.0, S), rng.uniform(0.3, 4.0, S)
    area = rng.integers(20, 200, S).astype(float)
    lab = np.array([60.0, 10.0, 10.0]) + rng.normal(0, 3, (S, 3))
    pairs = np.array(sorted({tuple(sorted(p)) for p in rng.integers(0, S, (16, 2))
                             if p[0] != p[1]}))
    kw = dict(KW, strength=30.0, keep_de=0.5)
    moved = order_cut(d, de, d2, de2, area, lab, pairs, **kw)
    lo, hi = np.minimum(d, d2), np.maximum(d, d2)
    e_own, e_other = np.minimum(de, CAP_DE), np.minimum(de2, CAP_DE) + kw["keep_de"]
    e_lo = np.where(d <= d2, e_own, e_other)
    e_hi = np.where(d <= d2, e_other, e_own)
    args = (lo, hi, e_lo, e_hi, area, lab, pairs)
    ekw = {k: kw[k] for k in ("period_nm", "strength", "contrast_de")}
    got = _energy((d > d2) != moved, *args, **ekw)
    best = min(_energy(np.array(s), *args, **ekw)
               for s in itertools.product([False, True], repeat=S))
    assert got == pytest.approx(best, rel=1e-6, abs=1e-3)


def _grid(region_of, lab_of):
    """8 x 8 facets of 4 x 4 px; per facet its region's colour."""
    y, x = np.mgrid[:32, :32]
    labels = (y // 4) * 8 + x // 4
    fy, fx = np.mgrid[:8, :8]
    region = region_of(fy.ravel(), fx.ravel())
    return labels, region, np.array([lab_of[r] for r in region], dtype=np.float64)


def test_a_patch_read_an_order_off_inside_one_colour_takes_the_regions_order():
    """One film (100 nm) over the grid; a 2 x 2 patch of facets whose colours, by noise, fit
    215 nm a little better (0.8 against 1.2 ΔE00) is read at 100 nm, and every other facet
    keeps its order; with strength 0 nothing moves."""
    labels, region, lab = _grid(lambda fy, fx: np.zeros(fy.size, int), {0: [55.0, 5, 20]})
    S = region.size
    patch = np.zeros((8, 8), bool)
    patch[3:5, 3:5] = True
    patch = patch.ravel()
    d = np.where(patch, 215.0, 100.0)
    d2 = np.where(patch, 100.0, 215.0)
    de = np.where(patch, 0.8, 1.0)
    de2 = np.where(patch, 1.2, 3.0)
    pairs = neighbour_pairs(labels)
    moved = order_cut(d, de, d2, de2, np.full(S, 16.0), lab, pairs, **KW)
    assert moved.tolist() == patch.tolist()
    assert not order_cut(d, de, d2, de2, np.full(S, 16.0), lab, pairs,
                         **dict(KW, strength=0.0)).any()


def test_a_region_of_another_colour_keeps_its_own_order():
    """The right half a film of another colour (30 ΔE00 away) read an order up, fitting its
    own order better by 1 ΔE00 and the left half's by less than the left half fits it: the
    colour step keeps the boundary, both halves keep their orders."""
    lab_of = {0: [55.0, 5, 20], 1: [55.0, 35, 20]}
    labels, region, lab = _grid(lambda fy, fx: (fx >= 6).astype(int), lab_of)
    assert float(delta_e_2000(np.array(lab_of[0]), np.array(lab_of[1]))) > 15
    S = region.size
    right = region == 1
    d = np.where(right, 215.0, 100.0)
    d2 = np.where(right, 100.0, 215.0)
    de, de2 = np.where(right, 1.0, 1.0), np.where(right, 2.0, 3.0)
    moved = order_cut(d, de, d2, de2, np.full(S, 16.0), lab, neighbour_pairs(labels), **KW)
    assert not moved.any()
    # of one colour, the same small region is read in its neighbours' order
    same = order_cut(d, de, d2, de2, np.full(S, 16.0), np.repeat(lab[:1], S, axis=0),
                     neighbour_pairs(labels), **KW)
    assert same.tolist() == right.tolist()


def test_facets_without_a_runner_up_or_a_sample_keep_their_order():
    """NaN runner-up, NaN ΔE or no pixels: never moved, and no link through them."""
    d = np.array([100.0, 215.0, 215.0, 100.0])
    d2 = np.array([215.0, np.nan, 100.0, 215.0])
    de = np.array([1.0, 0.5, 0.5, np.nan])
    de2 = np.array([3.0, 1.0, 1.0, 3.0])
    area = np.array([50.0, 50.0, 0.0, 50.0])
    lab = np.full((4, 3), 50.0)
    pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 3]])
    assert not order_cut(d, de, d2, de2, area, lab, pairs, **KW).any()
