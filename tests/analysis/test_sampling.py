"""Independent samples in a map (microfacet.analysis.sampling): the merging of patches
into regions and their area-weighted count."""

import math

import numpy as np
import pytest

from microfacet.analysis.sampling import thickness_regions


def _grid_labels(rows, cols, size=5):
    """Labels of a rows × cols grid of size × size-px patches (row-major ids)."""
    return np.kron(np.arange(rows * cols).reshape(rows, cols),
                   np.ones((size, size), dtype=np.int64))


def test_thickness_regions_finds_the_true_regions():
    # 2 × 6 patches: the left three columns at 100 nm, the right three at 110 nm
    rows, cols, sigma = 2, 6, 0.5
    labels = _grid_labels(rows, cols)
    truth = np.repeat((np.arange(cols) >= 3)[None, :], rows, axis=0).ravel()   # left | right
    rng = np.random.default_rng(10)
    value = np.where(truth, 110.0, 100.0) + rng.normal(0.0, sigma, truth.size)
    value[7] = np.nan                                  # a patch without a value
    r = thickness_regions(labels, value, np.full(truth.size, sigma))
    assert r.count == 2
    assert r.patch_region[7] == -1
    ok = np.isfinite(value)
    left, right = r.patch_region[ok & ~truth], r.patch_region[ok & truth]
    assert np.unique(left).size == 1 and np.unique(right).size == 1 and left[0] != right[0]
    for region, members in ((left[0], ok & ~truth), (right[0], ok & truth)):
        n = int(members.sum())
        # equal errors: the region's value is the plain mean of its patches
        assert r.value[region] == pytest.approx(value[members].mean(), abs=1e-9)
        assert abs(r.value[region] - (110.0 if truth[members][0] else 100.0)) < \
            4 * sigma / math.sqrt(n)
        assert r.sigma[region] == pytest.approx(math.sqrt((sigma ** 2 + r.scatter ** 2) / n),
                                                rel=1e-6)
        assert r.area[region] == 25 * n                # pixels of its patches


def test_thickness_regions_estimates_the_scatter_beyond_the_errors():
    rows, cols, sigma, tau = 20, 20, 0.2, 1.0
    labels = _grid_labels(rows, cols, size=3)
    rng = np.random.default_rng(11)
    value = 130.0 + rng.normal(0.0, math.hypot(sigma, tau), rows * cols)   # one region
    r = thickness_regions(labels, value, np.full(rows * cols, sigma))
    # MAD of 760 neighbour differences: SE of τ about 5 %
    assert r.scatter == pytest.approx(tau, rel=0.2)
    # the regions partition the patches; their area-weighted values average to the data's
    assert np.all(r.patch_region >= 0) and r.area.sum() == labels.size
    assert np.average(r.value, weights=r.area) == pytest.approx(value.mean(), abs=1e-6)


_OVERSPLIT_BUG = ("sampling.thickness_regions: greedy merging of neighbours (mutual best pairs "
                  "first, chi2 test at alpha = 1e-4 per merge, no account of the selection) "
                  "sorts one homogeneous region into sub-regions of low and high patches "
                  "whose means then differ 'significantly': 400 patches of one value split "
                  "into 5 regions, effective_count 2.65 (at alpha = 0.01 per merge: 15 and "
                  "5.8; documented: the count errs high)")


@pytest.mark.xfail(strict=True, reason=_OVERSPLIT_BUG)
@pytest.mark.parametrize("tau", [0.0, 1.0])
def test_thickness_regions_one_homogeneous_region_stays_one(tau):
    # 20 × 20 patches, all of one true thickness: errors σ as declared (+ scatter τ)
    rows, cols, sigma = 20, 20, 0.5
    labels = _grid_labels(rows, cols, size=3)
    rng = np.random.default_rng(12)
    value = 100.0 + rng.normal(0.0, math.hypot(sigma, tau), rows * cols)
    r = thickness_regions(labels, value, np.full(rows * cols, sigma))
    assert r.effective_count <= 2.0 and r.count == 1, (r.count, r.effective_count)


def test_thickness_regions_effective_count_is_the_kish_count_of_their_areas():
    labels = _grid_labels(4, 6)
    value = np.repeat([100.0, 120.0, 140.0], 8) + np.random.default_rng(13).normal(0, 0.1, 24)
    r = thickness_regions(labels, value, np.full(24, 0.1))
    assert r.count == 3                                      # rows 0-1 | rows 1-2 | rows 2-3
    np.testing.assert_array_equal(np.sort(r.area), [200.0, 200.0, 200.0])
    assert r.effective_count == pytest.approx(r.area.sum() ** 2 / np.sum(r.area ** 2))
    assert r.effective_count == pytest.approx(3.0)


def test_thickness_regions_keeps_distinct_values_apart():
    # every patch its own thickness, far apart beyond the errors: nothing merges
    labels = _grid_labels(3, 4)
    value = 100.0 + 10.0 * np.arange(12)
    r = thickness_regions(labels, value, np.full(12, 0.1))
    assert r.count == 12
    np.testing.assert_allclose(np.sort(r.value), value)
