"""NDF lobes (microfacet.analysis.ndf_fit): Rayleigh EM recovery of Gaussian-slope lobes, the
BIC of the tilt density, degenerate and grouped samples."""

import math

import numpy as np
import pytest

from microfacet.analysis.ndf_fit import fit_ndf_mixture
from microfacet.core.distributions import NDFMixture


def test_ndf_two_lobes_recovered(tilt_samples):
    rng = np.random.default_rng(7)
    tilt = tilt_samples(rng, [(0.6, 3.0), (0.4, 9.0)], 20000)
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


def test_ndf_single_lobe_and_bic_is_tilt_pdf_likelihood(tilt_samples):
    rng = np.random.default_rng(8)
    tilt = tilt_samples(rng, [(1.0, 6.0)], 4000)
    fit = fit_ndf_mixture(tilt, max_components=3)
    assert fit.n_components == 1
    assert abs(fit.mixture.sds_deg[0] - 6.0) < 0.2
    # the BIC is that of the tilt density per degree that NDFMixture.tilt_pdf models
    ll = np.sum(np.log(fit.mixture.tilt_pdf(tilt)))
    assert fit.bic == pytest.approx(-2 * ll + math.log(4000), rel=1e-9)


def test_ndf_all_zero_is_degenerate_and_zeros_tolerated(tilt_samples):
    fit = fit_ndf_mixture(np.zeros((20, 20)))
    assert fit.n_components == 1
    assert fit.mixture.sds_deg[0] == pytest.approx(0.05)
    assert isinstance(fit.degenerate, str) and "0" in fit.degenerate
    rng = np.random.default_rng(9)
    tilt = tilt_samples(rng, [(1.0, 5.0)], 3000)
    tilt[:30] = 0.0                       # a few exactly-flat pixels
    fit = fit_ndf_mixture(tilt, max_components=2)
    assert math.isfinite(fit.bic) and abs(fit.mixture.sds_deg.max() - 5.0) < 0.5


def test_ndf_group(tilt_samples):
    rng = np.random.default_rng(10)
    # 8 facets, each with one tilt (from 2 lobes) plus a little scatter
    centre = np.concatenate([tilt_samples(rng, [(1.0, 3.0)], 4),
                             tilt_samples(rng, [(1.0, 9.0)], 4)])
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
