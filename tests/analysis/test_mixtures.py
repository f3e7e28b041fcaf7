"""Thickness mixtures (microfacet.analysis.mixtures): recovery of known components, the
number of components by BIC with correlated samples (groups), weights, degenerate inputs."""

import json
import math

import numpy as np
import pytest

from microfacet.analysis.mixtures import MixtureFit, fit_thickness_mixture
from microfacet.core.distributions import ThicknessMixture


def test_thickness_three_components_recovered(thickness_samples):
    rng = np.random.default_rng(1)
    d = thickness_samples(rng, [(0.3, 112, 3), (0.4, 130, 3), (0.3, 149, 3)], 15000)
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


def test_thickness_reproducible_and_subsampled(thickness_samples):
    rng = np.random.default_rng(3)
    d = thickness_samples(rng, [(0.5, 120, 3), (0.5, 140, 3)], 30000)
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


def test_to_json_serialisable():
    fit = fit_thickness_mixture(np.random.default_rng(11).normal(130, 3, 2000), max_components=2)
    js = json.loads(json.dumps(fit.to_json()))
    assert set(js) >= {"components", "bic", "bic_by_k", "n_effective"}
    assert set(js["bic_by_k"]) == {"1", "2"}
    assert ThicknessMixture.from_json(js) == fit.mixture
