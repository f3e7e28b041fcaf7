"""The summaries against the maps they summarize (microfacet.analysis.consistency): a
mixture that reads two close components where the map holds three populations is caught, a
ROI whose single fit lies on another order than its pixels is flagged, and a mixture that
does summarize its map passes."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.analysis.consistency import mixture_map_check, roi_pixel_check
from microfacet.core.distributions import ThicknessMixture


def _map(seed=0):
    """A per-pixel map of three populations, 11 / 73 / 16 % of the area (issue 23's scene)."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([rng.normal(112, 1.0, 1100), rng.normal(131, 1.5, 7300),
                        rng.normal(150, 1.0, 1600)])
    return rng.permutation(t).reshape(100, 100)


def test_a_mixture_that_summarizes_its_map_passes():
    c = mixture_map_check(_map(), ThicknessMixture([(0.11, 112, 1.0), (0.73, 131, 1.5),
                                                     (0.16, 150, 1.0)]))
    assert c.consistent and c.unexplained_fraction < 0.01
    np.testing.assert_allclose(c.map_fractions, [0.11, 0.73, 0.16], atol=0.01)
    np.testing.assert_allclose(c.map_means_nm, [112, 131, 150], atol=0.2)


def test_two_close_components_for_three_populations_are_caught():
    c = mixture_map_check(_map(), ThicknessMixture([(0.5, 130.9, 1.0), (0.5, 132.1, 1.0)]))
    assert not c.consistent
    assert c.unexplained_fraction > 0.2          # the 112 and 150 nm pixels
    d = c.to_json()
    assert d["consistent"] is False and len(d["map_fractions"]) == 2


def test_a_wrong_weight_is_caught_and_nothing_mapped_is_none():
    c = mixture_map_check(_map(), ThicknessMixture([(0.4, 112, 1.0), (0.4, 131, 1.5),
                                                    (0.2, 150, 1.0)]))
    assert not c.consistent and c.max_fraction_difference > 0.25
    assert mixture_map_check(np.full((4, 4), np.nan), ThicknessMixture([(1, 100, 1)])) is None
    assert mixture_map_check(_map(), None) is None


def _Roi(fits):
    """Two ROIs side by side over a 10 × 20 map, with their single fits."""
    from microfacet.analysis.roi import RoiFit
    z = np.zeros(2)
    return RoiFit(np.array([0, 0]), np.array([0, 10]), 10, 10, np.asarray(fits, dtype=float),
                  z, z, z, np.zeros(2, int))


def test_a_roi_on_another_order_than_its_pixels_is_flagged():
    rng = np.random.default_rng(1)
    t = np.concatenate([rng.normal(129.5, 8.0, (10, 10)), rng.normal(131, 1.0, (10, 10))],
                       axis=1)
    med, bad = roi_pixel_check(_Roi([378.0, 133.0]), t)
    assert bad.tolist() == [True, False]        # 133 vs 131: within 5 nm
    np.testing.assert_allclose(med, [129.5, 131.0], atol=2.0)
    med, bad = roi_pixel_check(_Roi([140.0, np.nan]), t)  # within 3 robust SD of a mixed ROI
    assert bad.tolist() == [False, False]


def test_a_component_read_one_order_away_from_another_is_an_order_alias():
    """Facets of a 250 nm population: 200 read right, 60 read one order down at ~140 nm
    (their colour fits both within the margin: ambiguous, the runner-up at ~250 nm), and a
    clear 120 nm population whose runner-up order lies on nothing. Only the 140 nm
    component is an alias, of the 250 nm one; an ambiguous share below 20 % is not checked."""
    from microfacet.analysis.consistency import component_orders

    rng = np.random.default_rng(2)
    d = np.concatenate([rng.normal(250, 1, 200), rng.normal(140, 1, 60),
                        rng.normal(120, 1, 150)])
    other = np.concatenate([d[:200] - 110, d[200:260] + 110 + rng.normal(0, 2, 60),
                            d[260:] + 110])
    amb = np.zeros(d.size, bool)
    amb[200:240] = True                                  # two thirds of the 140 nm facets
    amb[260:270] = True                                  # 7 % of the 120 nm ones
    m = ThicknessMixture([(0.36, 120.0, 1.0), (0.15, 140.0, 1.0), (0.49, 250.0, 1.0)])
    out = component_orders(m, d, other, np.ones(d.size), amb)
    assert [o["alias_of_nm"] for o in out] == [None, 250.0, None]
    assert out[1]["order_ambiguous_fraction"] == np.float64(40 / 60)
    assert abs(out[1]["other_order_nm"] - 250.0) < 2.0
    assert out[0]["order_ambiguous_fraction"] == np.float64(10 / 150)
    assert out[2]["order_ambiguous_fraction"] == 0.0 and out[2]["other_order_nm"] is None
    # the 140 nm facets' runner-up nowhere near a component: not an alias
    far = other.copy()
    far[200:260] += 60.0
    assert component_orders(m, d, far, np.ones(d.size), amb)[1]["alias_of_nm"] is None


def test_two_components_each_others_runner_up_order_are_aliases_at_any_share():
    """One 235 nm population read partly an order up (the 1024² sweep's seed-0 g009: 235 and
    367 nm components, 10 % and 0.3 % of their areas ambiguous): each component's ambiguous
    facets have their runner-up order on the other, so both are aliases, of each other,
    though neither share reaches 20 %. Where only one side points at the other, or the
    other side points elsewhere, the shares decide as before."""
    from microfacet.analysis.consistency import component_orders, distinct_populations

    rng = np.random.default_rng(5)
    d = np.concatenate([rng.normal(235, 2, 400), rng.normal(367, 3, 40)])
    other = np.concatenate([d[:400] + 130, d[400:] - 130])
    amb = np.zeros(d.size, bool)
    amb[:40] = True                                       # 10 % of the 235 nm facets
    amb[400:402] = True                                   # 5 % of the 367 nm ones
    m = ThicknessMixture([(0.9, 235.0, 2.0), (0.1, 367.0, 3.0)])
    out = component_orders(m, d, other, np.ones(d.size), amb)
    assert [(o["alias_of_nm"], o["alias_both_ways"]) for o in out] == [(367.0, True),
                                                                      (235.0, True)]
    assert distinct_populations(m, out) == 1
    one_way = amb.copy()
    one_way[400:402] = False                              # the 367 nm facets all clear
    out = component_orders(m, d, other, np.ones(d.size), one_way)
    assert [o["alias_of_nm"] for o in out] == [None, None]
    elsewhere = other.copy()
    elsewhere[400:] -= 40.0                               # their runner-up on nothing
    out = component_orders(m, d, elsewhere, np.ones(d.size), amb)
    assert [o["alias_of_nm"] for o in out] == [None, None]
    assert distinct_populations(m, out) == 2


def test_distinct_populations_count_each_alias_with_its_component():
    from microfacet.analysis.consistency import distinct_populations

    m = ThicknessMixture([(0.2, 12.0, 1.0), (0.3, 93.0, 1.0), (0.3, 176.0, 1.0),
                          (0.2, 227.0, 1.0)])
    none = [{"alias_of_nm": None}] * 4
    assert distinct_populations(m, none) == 4
    one = [{"alias_of_nm": 93.0}] + none[1:]
    assert distinct_populations(m, one) == 3
    both_ways = [{"alias_of_nm": 93.0}, {"alias_of_nm": 12.0}] + none[2:]
    assert distinct_populations(m, both_ways) == 3
    chain = [{"alias_of_nm": 93.0}, {"alias_of_nm": 176.0}] + none[2:]
    assert distinct_populations(m, chain) == 2


def test_a_candidate_whose_other_order_lies_on_a_component_is_its_alias():
    """A candidate's facets whose runner-up order lies on a component and fits them within
    the populations' misfit may be that component read in another order; a runner-up that
    fits clearly worse, or lies on no component, leaves the candidate a population."""
    from microfacet.analysis.consistency import candidate_alias

    m = ThicknessMixture([(0.7, 110.0, 1.5), (0.3, 55.0, 1.0)])
    rng = np.random.default_rng(0)
    other = 165.0 - 110.0 + rng.normal(0.0, 0.8, 40)          # the 165 nm facets' look-alike
    area = rng.uniform(20, 200, 40)
    alias, gap = candidate_alias(m, other, rng.uniform(1.5, 3.5, 40), area, misfit_de=4.0)
    assert alias == 55.0 and 1.5 < gap < 3.5
    alias, gap = candidate_alias(m, other, rng.uniform(5.0, 8.0, 40), area, misfit_de=4.0)
    assert alias is None and gap > 4.0                          # the colours tell them apart
    alias, _ = candidate_alias(m, other + 30.0, np.full(40, 1.0), area, misfit_de=4.0)
    assert alias is None                                        # on no component
    assert candidate_alias(m, [np.nan], [np.nan], [1.0], misfit_de=4.0) == (None, None)


def _split_population(seed=3):
    """A 52 nm population whose colours fit the order above about alike: 150 facets read
    right (runner-up 163 nm, 3-4 dE00 worse) and 100 read one order up at ~163 nm (runner-up
    ~52 nm, 0.2-0.8 dE00 worse); and a clear 192 nm population (runner-up ~80 nm, 5 dE00
    worse)."""
    rng = np.random.default_rng(seed)
    d = np.concatenate([rng.normal(52, 1, 150), rng.normal(163, 1, 100), rng.normal(192, 1, 200)])
    other = np.concatenate([d[:150] + 111, d[150:250] - 111, d[250:] - 112])
    gap = np.concatenate([rng.uniform(3, 4, 150), rng.uniform(0.2, 0.8, 100),
                          np.full(200, 5.0)])
    m = ThicknessMixture([(1 / 3, 52.0, 1.0), (2 / 9, 163.0, 1.0), (4 / 9, 192.0, 1.0)])
    return m, d, other, gap


def test_order_move_reads_a_component_in_the_order_its_facets_fit_alike():
    """The 163 nm component moves to the 52 nm one's order (its facets fit it within 1 dE00
    on average); the 52 nm one does not move up (3.5 dE00 worse) and the 192 nm one's
    runner-up lies on no component."""
    from microfacet.analysis.consistency import order_move

    m, d, other, gap = _split_population()
    mv, moved = order_move(m, d, other, gap, np.ones(d.size), margin_de=1.0,
                           min_separation_nm=55.0)
    assert (mv.from_nm, mv.to_nm, mv.facets) == (163.0, 52.0, 100)
    assert mv.area_share == 1.0 and 0.2 < mv.mean_gap_de < 0.8
    assert np.flatnonzero(moved).tolist() == list(range(150, 250))
    assert mv.to_json()["to_nm"] == 52.0


def test_order_move_needs_the_margin_the_share_and_an_order_between():
    """No move where the facets fit the other order worse than the margin on average, where
    fewer than half of the component's area has its runner-up there, or where the two
    components are closer than the separation asked (not an order apart)."""
    from microfacet.analysis.consistency import MOVE_MIN_SHARE, order_move

    m, d, other, gap = _split_population()
    assert order_move(m, d, other, gap + 0.7, np.ones(d.size), margin_de=1.0,
                      min_separation_nm=55.0)[0] is None
    half = other.copy()
    half[150:150 + int(100 * (1 - MOVE_MIN_SHARE)) + 1] += 40.0   # just over half elsewhere
    assert order_move(m, d, half, gap, np.ones(d.size), margin_de=1.0,
                      min_separation_nm=55.0)[0] is None
    assert order_move(m, d, other, gap, np.ones(d.size), margin_de=1.0,
                      min_separation_nm=120.0)[0] is None
    # the weights count: the same facets, the moved ones weighing little, still all of theirs
    w = np.ones(d.size)
    w[150:250] = 0.1
    mv, _ = order_move(m, d, other, gap, w, margin_de=1.0, min_separation_nm=55.0)
    assert mv is not None and mv.area_share == 1.0


def test_the_map_check_in_chunks_is_the_check_at_once(monkeypatch):
    """Chunking the pixels (a ragged last chunk) changes no number of the check."""
    from microfacet.core import threads

    m = _map(1)
    m[::7, ::3] = np.nan
    mix = ThicknessMixture([(0.2, 112, 1.0), (0.6, 131, 1.5), (0.2, 150, 1.0)])
    monkeypatch.setattr(threads, "BLOCK_VALUES", 3 * 10 ** 6)   # one chunk
    whole = mixture_map_check(m, mix)
    monkeypatch.setattr(threads, "BLOCK_VALUES", 3 * 333)     # 333 pixels
    assert mixture_map_check(m, mix) == whole


def _misread_scene(share=0.1, de_minor=(3.5, 5.5), seed=0, n=2000):
    """Facets of a 130 nm population (ΔE00 0.3-3.0) and a ``share`` of them read at 250 nm
    with ΔE00 drawn from ``de_minor``."""
    rng = np.random.default_rng(seed)
    m = int(share * n)
    d = np.r_[rng.normal(130, 1.0, n - m), rng.normal(250, 1.0, m)]
    de = np.r_[rng.uniform(0.3, 3.0, n - m), rng.uniform(*de_minor, m)]
    mix = ThicknessMixture([(1 - share, 130.0, 1.0), (share, 250.0, 1.0)])
    return mix, d, de


def test_a_minor_component_the_film_explains_far_worse_is_misread():
    """The 250 nm facets' median ΔE00 (4.5) is above 1.5 × the population's (1.65) + 0.5:
    misread, with both medians; the population itself never is, whatever the colours."""
    from microfacet.analysis.consistency import misread_components

    mix, d, de = _misread_scene()
    ((k, de_k, de_rest, mine),) = misread_components(mix, d, de)
    assert mix.components[k][1] == 250.0
    assert de_k == pytest.approx(4.5, abs=0.2) and de_rest == pytest.approx(1.65, abs=0.1)
    assert mine.sum() == 200
    # one component is always kept, however its colours fit
    one = ThicknessMixture([(1.0, 130.0, 1.0)])
    assert misread_components(one, d[:1800], de[:1800] + 10.0) == []


def _grain_scene(minor, seed=0, grains=4):
    """16 × 16 facets of 8 px: a 130 nm population in ``grains`` grains (4: one per quadrant,
    each ±1.5 nm about it; 1: one region) and about 10 % of the facets at 250 nm,
    ``"scattered"`` (facets apart from each other), ``"grain"`` (one block of 26) or
    ``"grains"`` (three blocks of 9); the facets' areas and their thickness regions."""
    from microfacet.analysis.sampling import thickness_regions

    rng = np.random.default_rng(seed)
    row, col = np.arange(256) // 16, np.arange(256) % 16
    labels = np.arange(256).reshape(16, 16).repeat(8, 0).repeat(8, 1)
    quadrant = row // 8 * 2 + col // 8
    d = 130.0 + (np.array([-1.5, 0.5, 1.5, -0.5])[quadrant] if grains == 4 else 0.0) \
        + rng.normal(0, 0.1, 256)
    if minor == "scattered":        # a checkerboard's cells never touch by a side
        at = rng.choice(np.flatnonzero((row + col) % 2 == 0), 26, replace=False)
    elif minor == "grain":
        at = np.flatnonzero((row >= 10) & (row < 15) & (col >= 10))[:26]
    else:
        at = np.concatenate([np.flatnonzero((row >= r) & (row < r + 3) & (col >= c)
                                            & (col < c + 3)) for r, c in ((1, 1), (6, 9),
                                                                          (11, 3))])
    d[at] = 250.0 + rng.normal(0, 0.1, at.size)
    reg = thickness_regions(labels, d, np.full(256, 0.1))
    mix = ThicknessMixture([(1 - at.size / 256, 130.0, 1.2), (at.size / 256, 250.0, 0.1)])
    return mix, d, np.full(256, 64.0), reg


def test_a_minor_component_scattered_over_single_facets_is_set_aside():
    """26 facets of 250 nm, each apart (regions of one facet): scattered; the same share as
    one block of the surface (a grain of 26 facets), or as three grains of 9 facets beside
    one region of all the rest (regions 0.04 × its size), is kept."""
    from microfacet.analysis.consistency import scattered_components

    mix, d, area, reg = _grain_scene("scattered")
    ((k, f, mine),) = scattered_components(mix, d, reg, area)
    assert mix.components[k][1] == 250.0 and mine.sum() == 26 and f == 1.0
    mix, d, area, reg = _grain_scene("grain")
    assert scattered_components(mix, d, reg, area) == []
    mix, d, area, reg = _grain_scene("grains", grains=1)
    assert reg.area.max() > 20 * 9 * 64.0           # one region of all the rest
    assert scattered_components(mix, d, reg, area) == []
    # the population itself is never set aside, nor a component above max_weight
    mix, d, area, reg = _grain_scene("scattered")
    assert scattered_components(mix, d, reg, area, max_weight=0.05) == []


def test_a_component_that_covers_a_grain_is_a_population_whatever_its_colours():
    """The 250 nm facets fit the film far worse than the population's (ΔE00 4.5 against
    about 1.65): scattered over single facets they are misread; as one grain of 26 facets
    (its interior, the facets whose every neighbour is its own, 11 of 26) they are a
    population, kept; without the facets' neighbours the colour rule alone sets it aside."""
    from microfacet.analysis.consistency import (
        GRAIN_INTERIOR_SHARE,
        interior_share,
        misread_components,
    )
    from microfacet.analysis.segmentation import neighbour_pairs

    labels = np.arange(256).reshape(16, 16)
    pairs = neighbour_pairs(labels)
    rng = np.random.default_rng(1)
    for minor, kept in (("scattered", False), ("grain", True)):
        mix, d, area, _ = _grain_scene(minor)
        de = np.where(d > 200, rng.uniform(3.5, 5.5, d.size), rng.uniform(0.3, 3.0, d.size))
        share = interior_share(d > 200, pairs, area)
        assert (share >= GRAIN_INTERIOR_SHARE) == kept
        out = misread_components(mix, d, de, pairs=pairs, area=area)
        assert (out == []) == kept
        ((k, *_),) = misread_components(mix, d, de)          # the colour rule alone
        assert mix.components[k][1] == 250.0
    assert interior_share(d > 200, pairs, area) == pytest.approx(11 / 26)   # the image edge
    # bounds the grain on its right: no neighbour there


@pytest.mark.parametrize("share, de_minor", [(0.1, (0.3, 3.0)), (0.3, (3.5, 5.5))])
def test_a_population_explained_as_well_or_a_major_one_is_not_misread(share, de_minor):
    """Colours as well explained as the population's, or a component above
    MISREAD_MAX_WEIGHT: kept."""
    from microfacet.analysis.consistency import misread_components

    mix, d, de = _misread_scene(share=share, de_minor=de_minor)
    assert misread_components(mix, d, de) == []


def test_a_minor_component_without_a_region_of_its_own_is_set_aside():
    """26 facets read at 212 nm with errors of 8 nm beside a 200 nm population: their thickness
    regions are the population's (their values agree within their errors), so no region's
    mean lies on the 212 nm component: the tail of a population, set aside although its
    facets lie in a region of hundreds of facets; with errors of 0.1 nm they are regions of
    their own, one facet each: set aside as scattered."""
    from microfacet.analysis.consistency import region_components, scattered_components
    from microfacet.analysis.sampling import thickness_regions

    rng = np.random.default_rng(1)
    labels = np.arange(256).reshape(16, 16).repeat(8, 0).repeat(8, 1)
    row, col = np.arange(256) // 16, np.arange(256) % 16
    at = rng.choice(np.flatnonzero((row + col) % 2 == 0), 26, replace=False)
    d = 200.0 + rng.normal(0, 0.1, 256)
    d[at] = 212.0 + rng.normal(0, 0.5, at.size)
    mix = ThicknessMixture([(0.9, 200.0, 0.2), (0.1, 212.0, 0.5)])
    sigma = np.full(256, 0.1)
    sigma[at] = 8.0
    reg = thickness_regions(labels, d, sigma)
    assert np.unique(reg.patch_region[at]).size < 5          # inside the population's regions
    assert not np.any(region_components(mix, reg) == 1)
    ((k, f, mine),) = scattered_components(mix, d, reg, np.full(256, 64.0))
    assert k == 1 and f == 0.0 and mine.sum() == 26
    sigma[at] = 0.1
    reg = thickness_regions(labels, d, sigma)
    ((k, f, _),) = scattered_components(mix, d, reg, np.full(256, 64.0))
    assert k == 1 and f == 1.0
