"""Tests of microfacet.analysis.mixtures: mixture recovery, BIC with correlated samples, tables."""

import json
import math

import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.analysis.mixtures import MixtureFit, fit_thickness_mixture
from microfacet.analysis.ndf_fit import fit_ndf_mixture
from microfacet.core.densities import (histogram_density, ndf_D_from_tilt_histogram, pdf_table,
                                       wasserstein1, wasserstein1_pdf)


def _thickness_samples(rng, comps, n):
    w = np.array([c[0] for c in comps], dtype=float)
    k = rng.choice(len(comps), size=n, p=w / w.sum())
    mu = np.array([c[1] for c in comps])[k]
    sd = np.array([c[2] for c in comps])[k]
    return rng.normal(mu, sd)


def _tilt_samples(rng, comps, n):
    """Tilts (deg) of Gaussian-slope lobes: slopes N(0, s²) per axis, tilt = atan(hypot)."""
    w = np.array([c[0] for c in comps], dtype=float)
    k = rng.choice(len(comps), size=n, p=w / w.sum())
    s = np.tan(np.radians(np.array([c[1] for c in comps])[k]))
    return np.degrees(np.arctan(np.hypot(rng.normal(0, 1, n) * s, rng.normal(0, 1, n) * s)))


# ------------------------------------------------------------------------- thickness


def test_thickness_three_components_recovered():
    rng = np.random.default_rng(1)
    d = _thickness_samples(rng, [(0.3, 112, 3), (0.4, 130, 3), (0.3, 149, 3)], 15000)
    fit = fit_thickness_mixture(d)
    assert isinstance(fit, MixtureFit)
    assert fit.n_components == 3
    assert min(fit.bic_by_k, key=fit.bic_by_k.get) == 3
    assert fit.bic == fit.bic_by_k[3]
    np.testing.assert_allclose(fit.mixture.means_nm, [112, 130, 149], atol=1.0)
    np.testing.assert_allclose(fit.mixture.sds_nm, [3, 3, 3], atol=0.3)
    np.testing.assert_allclose(fit.mixture.weights, [0.3, 0.4, 0.3], atol=0.03)
    assert fit.n_samples == fit.n_effective == 15000
    assert fit.degenerate is False


def test_thickness_single_gaussian_selects_one():
    rng = np.random.default_rng(2)
    fit = fit_thickness_mixture(rng.normal(125.0, 4.0, 5000), max_components=4)
    assert fit.n_components == 1
    assert abs(fit.mixture.means_nm[0] - 125.0) < 0.3
    assert abs(fit.mixture.sds_nm[0] - 4.0) < 0.2


def test_thickness_reproducible_and_subsampled():
    rng = np.random.default_rng(3)
    d = _thickness_samples(rng, [(0.5, 120, 3), (0.5, 140, 3)], 30000)
    a = fit_thickness_mixture(d, max_components=3, max_samples=5000)
    b = fit_thickness_mixture(d, max_components=3, max_samples=5000)
    assert a.mixture == b.mixture and a.bic_by_k == b.bic_by_k
    assert a.n_samples == 30000 and a.n_fit == 5000 and a.n_effective == 5000
    assert a.n_components == 2


def _grouped(rng, n_groups=8, per_group=3000, within=0.2):
    """n_groups regions, each one thickness from a 2-component mixture, plus a tiny
    within-region scatter: per-pixel values that are strongly correlated in groups."""
    centres = np.concatenate([rng.normal(120, 3, n_groups // 2),
                              rng.normal(140, 3, n_groups - n_groups // 2)])
    x = centres[:, None] + rng.normal(0, within, (n_groups, per_group))
    g = np.repeat(np.arange(n_groups), per_group).reshape(n_groups, per_group)
    return x, g


def test_thickness_correlated_samples_group_prevents_overfit():
    x, g = _grouped(np.random.default_rng(4))
    naive = fit_thickness_mixture(x)              # pixels taken as independent
    grouped = fit_thickness_mixture(x, group=g)   # 8 independent regions
    assert naive.n_components >= 4                # overfits: a component per region
    assert grouped.n_components <= 3
    assert grouped.n_effective == 8
    assert grouped.n_samples == 24000


def test_thickness_group_bic_not_only_the_parameter_cap():
    # 30 groups: the p <= n_eff cap allows K up to 10, so the BIC itself must choose
    x, g = _grouped(np.random.default_rng(5), n_groups=30, per_group=500)
    grouped = fit_thickness_mixture(x, group=g, max_components=5)
    assert sorted(grouped.bic_by_k) == [1, 2, 3, 4, 5]
    assert grouped.n_components == 2
    np.testing.assert_allclose(grouped.mixture.means_nm, [120, 140], atol=3.0)


def test_thickness_single_value_is_degenerate():
    fit = fit_thickness_mixture(np.full(100, 131.5))
    assert fit.n_components == 1
    assert fit.mixture.means_nm[0] == 131.5
    assert fit.mixture.sds_nm[0] == pytest.approx(0.1)
    assert isinstance(fit.degenerate, str) and "single value" in fit.degenerate
    assert math.isfinite(fit.bic)
    one = fit_thickness_mixture([140.0, np.nan])
    assert one.n_samples == 1 and one.mixture.means_nm[0] == 140.0


def test_thickness_few_samples_and_nan():
    d = np.array([100.0, 101.0, np.nan, 150.0, 151.0, np.nan])
    fit = fit_thickness_mixture(d, max_components=5)
    assert fit.n_samples == 4
    assert max(fit.bic_by_k) <= 1 + (4 + 1) // 3  # p = 3K − 1 <= n_effective
    assert fit.degenerate


def test_thickness_weights():
    rng = np.random.default_rng(6)
    d = np.concatenate([rng.normal(120, 3, 5000), rng.normal(140, 3, 5000)])
    w = np.where(d < 130, 3.0, 1.0)
    fit = fit_thickness_mixture(d, weights=w, max_components=3)
    assert fit.n_components == 2
    np.testing.assert_allclose(fit.mixture.weights, [0.75, 0.25], atol=0.03)
    assert fit.n_effective < 10000


@pytest.mark.parametrize("bad, kw, match", [
    (np.full(10, np.nan), {}, "thickness_nm"),
    ([], {}, "thickness_nm"),
    ([1.0, np.inf], {}, "thickness_nm"),
    ([1.0, 2.0], {"group": [1, 2, 3]}, "group"),
    ([1.0, 2.0], {"weights": [1.0]}, "weights"),
    ([1.0, 2.0], {"weights": [1.0, -1.0]}, "weights"),
    ([1.0, 2.0], {"max_components": 0}, "max_components"),
    ([1.0, 2.0], {"sd_floor_nm": 0}, "sd_floor_nm"),
])
def test_thickness_errors(bad, kw, match):
    with pytest.raises(ValueError, match=match):
        fit_thickness_mixture(bad, **kw)


# ------------------------------------------------------------------------------- NDF


def test_ndf_two_lobes_recovered():
    rng = np.random.default_rng(7)
    tilt = _tilt_samples(rng, [(0.6, 3.0), (0.4, 9.0)], 20000)
    fit = fit_ndf_mixture(tilt)
    assert isinstance(fit.mixture, NDFMixture)
    assert fit.n_components == 2
    assert min(fit.bic_by_k, key=fit.bic_by_k.get) == 2
    np.testing.assert_allclose(fit.mixture.sds_deg, [3.0, 9.0], atol=0.5)
    np.testing.assert_allclose(fit.mixture.weights, [0.6, 0.4], atol=0.05)
    js = fit.to_json()
    assert js["form"] == "gaussian-slope"
    assert all(c["mean_deg"] == 0.0 for c in js["components"])
    assert NDFMixture.from_json(js) == fit.mixture


def test_ndf_single_lobe_and_bic_is_tilt_pdf_likelihood():
    rng = np.random.default_rng(8)
    tilt = _tilt_samples(rng, [(1.0, 6.0)], 4000)
    fit = fit_ndf_mixture(tilt, max_components=3)
    assert fit.n_components == 1
    assert abs(fit.mixture.sds_deg[0] - 6.0) < 0.2
    # the BIC is that of the tilt density per degree that NDFMixture.tilt_pdf models
    ll = np.sum(np.log(fit.mixture.tilt_pdf(tilt)))
    assert fit.bic == pytest.approx(-2 * ll + math.log(4000), rel=1e-9)


def test_ndf_all_zero_is_degenerate_and_zeros_tolerated():
    fit = fit_ndf_mixture(np.zeros((20, 20)))
    assert fit.n_components == 1
    assert fit.mixture.sds_deg[0] == pytest.approx(0.05)
    assert isinstance(fit.degenerate, str) and "0" in fit.degenerate
    rng = np.random.default_rng(9)
    tilt = _tilt_samples(rng, [(1.0, 5.0)], 3000)
    tilt[:30] = 0.0                       # a few exactly-flat pixels
    fit = fit_ndf_mixture(tilt, max_components=2)
    assert math.isfinite(fit.bic) and abs(fit.mixture.sds_deg.max() - 5.0) < 0.5


def test_ndf_group():
    rng = np.random.default_rng(10)
    # 8 facets, each with one tilt (from 2 lobes) plus a little scatter
    centre = np.concatenate([_tilt_samples(rng, [(1.0, 3.0)], 4),
                             _tilt_samples(rng, [(1.0, 9.0)], 4)])
    tilt = np.clip(centre[:, None] + rng.normal(0, 0.1, (8, 1500)), 0, None)
    g = np.repeat(np.arange(8), 1500).reshape(8, 1500)
    naive = fit_ndf_mixture(tilt, max_components=4)
    grouped = fit_ndf_mixture(tilt, max_components=4, group=g)
    assert grouped.n_effective == 8
    assert grouped.n_components <= 2 < naive.n_components


@pytest.mark.parametrize("bad, match", [
    (np.full(5, np.nan), "tilt_deg"),
    ([1.0, 90.0], "tilt_deg"),
    ([-1.0, 3.0], "tilt_deg"),
])
def test_ndf_errors(bad, match):
    with pytest.raises(ValueError, match=match):
        fit_ndf_mixture(bad)


def test_to_json_serialisable():
    fit = fit_thickness_mixture(np.random.default_rng(11).normal(130, 3, 2000), max_components=2)
    js = json.loads(json.dumps(fit.to_json()))
    assert set(js) >= {"components", "bic", "bic_by_k", "n_effective"}
    assert set(js["bic_by_k"]) == {"1", "2"}
    assert ThicknessMixture.from_json(js) == fit.mixture


# ---------------------------------------------------------------------- tables, D, W1


def test_histogram_density_integrates_to_one():
    rng = np.random.default_rng(12)
    c, d = histogram_density(rng.normal(0, 1, 1000), bins=20, range=(-2, 2))
    assert c.shape == d.shape == (20,)
    assert np.sum(d) * 0.2 == pytest.approx(1.0)
    with pytest.raises(ValueError, match="values"):
        histogram_density([10.0, np.nan], bins=5, range=(0, 1))


def test_pdf_table_thickness_and_tilt():
    rng = np.random.default_rng(13)
    g = ThicknessMixture([(0.5, 120, 3), (0.5, 140, 3)])
    d = _thickness_samples(rng, g.components, 20000)
    grid = np.arange(100.0, 160.0, 1.0) + 0.5
    t = pdf_table(d, g, grid=grid)
    assert t.shape == (60, 3)
    np.testing.assert_array_equal(t[:, 0], grid)
    assert np.sum(t[:, 1]) * 1.0 == pytest.approx(1.0)
    assert np.sum(t[:, 2]) * 1.0 == pytest.approx(1.0)
    np.testing.assert_allclose(t[:, 2], g.pdf(grid), atol=4e-4)  # cell average ≈ point value
    assert np.max(np.abs(t[:, 1] - t[:, 2])) < 0.01

    # the tilt histogram matches tilt_pdf directly: no sin θ division
    f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    tilt = _tilt_samples(rng, f.components, 20000)
    grid = np.arange(0.0, 30.0, 0.5) + 0.25
    t = pdf_table(tilt, f, grid=grid)
    assert np.sum(t[:, 1]) * 0.5 == pytest.approx(1.0)
    assert np.sum(t[:, 2]) * 0.5 == pytest.approx(1.0)   # renormalised over [0, 30]
    assert wasserstein1_pdf(grid, t[:, 1], t[:, 2]) < 0.1
    np.testing.assert_allclose(t[:, 2], f.tilt_pdf(grid) / np.trapezoid(f.tilt_pdf(grid), grid),
                               atol=3e-3)


def test_pdf_table_errors():
    with pytest.raises(ValueError, match="grid"):
        pdf_table([1.0], ThicknessMixture([(1, 1, 1)]), grid=[2.0, 1.0])
    with pytest.raises(ValueError, match="mixture"):
        pdf_table([1.0], object(), grid=[0.0, 1.0, 2.0])


def test_ndf_D_from_tilt_histogram():
    f = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
    th = np.linspace(0.0, 60.0, 121)
    D = ndf_D_from_tilt_histogram(th, f.tilt_pdf(th))
    assert np.isnan(D[0])
    np.testing.assert_allclose(D[1:], f.D(th[1:]), rtol=1e-9)


def test_wasserstein():
    rng = np.random.default_rng(14)
    a = rng.normal(130, 3, 5000)
    assert wasserstein1(a, a) == 0.0
    assert wasserstein1(a, a + 2.5) == pytest.approx(2.5)
    assert wasserstein1(np.append(a, np.nan), a) == 0.0
    with pytest.raises(ValueError, match="samples_b"):
        wasserstein1(a, [np.nan])
    x = np.linspace(80, 180, 4001)
    p = ThicknessMixture([(0.5, 120, 3), (0.5, 140, 3)]).pdf(x)
    q = ThicknessMixture([(0.5, 124, 3), (0.5, 144, 3)]).pdf(x)
    assert wasserstein1_pdf(x, p, p) == 0.0
    assert wasserstein1_pdf(x, p, q) == pytest.approx(4.0, abs=1e-3)
    with pytest.raises(ValueError, match="pdf_b"):
        wasserstein1_pdf(x, p, q[:-1])
