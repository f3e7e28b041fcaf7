"""NDF lobes (microfacet.analysis.ndf_fit): Rayleigh EM recovery of Gaussian-slope lobes, the
BIC of the tilt density, degenerate and grouped samples."""

import math

import numpy as np
import pytest

from microfacet.analysis.ndf_fit import fit_ndf_mixture
from microfacet.analysis.options import FitOptions
from microfacet.core.distributions import NDFMixture
from microfacet.core.errors import InputError


def _k(max_components, **kw):
    """The fit options with at most ``max_components`` lobes."""
    return FitOptions(max_components=max_components, **kw)


@pytest.mark.slow
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
    fit = fit_ndf_mixture(tilt, options=_k(3))
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
    fit = fit_ndf_mixture(tilt, options=_k(2))
    assert math.isfinite(fit.bic) and abs(fit.mixture.sds_deg.max() - 5.0) < 0.5


@pytest.mark.slow
def test_ndf_group(tilt_samples):
    rng = np.random.default_rng(10)
    # 8 facets, each with one tilt (from 2 lobes) plus a little scatter
    centre = np.concatenate([tilt_samples(rng, [(1.0, 3.0)], 4),
                             tilt_samples(rng, [(1.0, 9.0)], 4)])
    tilt = np.clip(centre[:, None] + rng.normal(0, 0.1, (8, 1500)), 0, None)
    g = np.repeat(np.arange(8), 1500).reshape(8, 1500)
    naive = fit_ndf_mixture(tilt, options=_k(4))
    grouped = fit_ndf_mixture(tilt, options=_k(4), group=g)
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


# ------------------------------------------------------------------ added: deconvolution,
# censoring, closed-form references, weights, width_relative_error

from microfacet.analysis.ndf_fit import width_relative_error  # noqa: E402

NA_LIMIT_DEG = math.degrees(math.asin(0.8)) / 2.0     # 26.57°: coaxial acceptance at NA 0.8


def _measured_tilts(rng, sd_deg, n, noise=None):
    """True slopes N(0, s² I), s = tan(sd_deg), plus slope noise N(0, noise_i² I)."""
    s = math.tan(math.radians(sd_deg))
    m = rng.normal(0.0, s, (2, n))
    if noise is not None:
        m = m + rng.normal(0.0, 1.0, (2, n)) * noise
    return np.degrees(np.arctan(np.hypot(m[0], m[1])))


def _sd_deg_se(sd_deg, v, a=None):
    """1-σ error (deg) of a lobe's sd_deg from the Fisher information of s² in the
    deconvolved Rayleigh model: I = Σ a_i / V_i², V_i = s² + v_i (independent of the code)."""
    s2 = math.tan(math.radians(sd_deg)) ** 2
    a = np.ones_like(v) if a is None else a
    se_s = 1.0 / (2.0 * math.sqrt(s2) * math.sqrt(np.sum(a / (s2 + v) ** 2)))
    return math.degrees(se_s / (1.0 + s2))            # d atan(s) / ds = 1 / (1 + s²)


@pytest.mark.slow
@pytest.mark.parametrize("sd_deg", [5.0, 10.0])
def test_ndf_deconvolves_heteroscedastic_slope_noise(sd_deg):
    rng = np.random.default_rng(30)
    n = 4000
    noise = rng.uniform(0.03, 0.12, n)          # per-axis slope noise, comparable to tan 5°
    tilt = _measured_tilts(rng, sd_deg, n, noise)
    fit = fit_ndf_mixture(tilt, slope_sigma=noise, options=_k(3))
    se = _sd_deg_se(sd_deg, noise ** 2)
    naive = fit_ndf_mixture(tilt, options=_k(1)).mixture.sds_deg[0]
    # what no deconvolution gives: atan sqrt(s² + mean σ²); the test tells it from sd_deg
    convolved = math.degrees(math.atan(math.sqrt(math.tan(math.radians(sd_deg)) ** 2
                                                 + np.mean(noise ** 2))))
    assert convolved - sd_deg > 8 * se and naive - sd_deg > 8 * se
    assert fit.n_components == 1
    assert abs(fit.mixture.sds_deg[0] - sd_deg) < 4 * se


def test_ndf_single_lobe_is_the_closed_form_mle():
    # K = 1, exact slopes, weights: s² = Σ a m² / (2 Σ a) (Rayleigh MLE)
    rng = np.random.default_rng(31)
    tilt = _measured_tilts(rng, 7.0, 800)
    a = rng.uniform(0.5, 2.0, 800)
    fit = fit_ndf_mixture(tilt, weights=a, options=_k(1))
    m2 = np.tan(np.radians(tilt)) ** 2
    s2 = np.sum(a * m2) / (2.0 * np.sum(a))
    assert fit.mixture.sds_deg[0] == pytest.approx(math.degrees(math.atan(math.sqrt(s2))),
                                                   abs=1e-3)


@pytest.mark.slow
def test_ndf_censoring_recovers_a_wide_lobe():
    # a 22° lobe seen through NA 0.8: 46 % of the facets are past 26.6° (dark, unmeasured)
    rng = np.random.default_rng(32)
    n = 5000
    tilt = _measured_tilts(rng, 22.0, n)
    seen = tilt <= NA_LIMIT_DEG
    n_obs, c = int(seen.sum()), float(n - seen.sum())
    L2 = math.tan(math.radians(NA_LIMIT_DEG)) ** 2
    assert c / n == pytest.approx(math.exp(-L2 / (2 * math.tan(math.radians(22.0)) ** 2)),
                                  abs=0.03)
    fit = fit_ndf_mixture(tilt[seen], censored=(c, NA_LIMIT_DEG),
                          options=_k(3))
    dropped = fit_ndf_mixture(tilt[seen], options=_k(3))
    # censored exponential law of m² (mean 2s²): I(2s²) = n_obs / (2s²)², so the relative
    # error of s is 1 / (2 sqrt(n_obs)): 0.19° here
    s = math.tan(math.radians(22.0))
    se = math.degrees(s / (2.0 * math.sqrt(n_obs)) / (1.0 + s * s))
    assert fit.n_components == 1
    assert abs(fit.mixture.sds_deg[0] - 22.0) < 4 * se
    assert fit.info["censored_fraction"] == pytest.approx(c / n)
    assert fit.n_effective == pytest.approx(n)          # censored weight counted in proportion
    # dropped instead of censored: clearly narrower (docs: "a 22° lobe read as 12.5°")
    assert dropped.mixture.rms_sd_deg < 22.0 - 5.0
    # against the closed-form censored MLE of one lobe: s² = (Σ m² + C L²) / (2 n_obs)
    one = fit_ndf_mixture(tilt[seen], censored=(c, NA_LIMIT_DEG),
                          options=_k(1))
    m2 = np.tan(np.radians(tilt[seen])) ** 2
    s2 = (m2.sum() + c * L2) / (2.0 * n_obs)
    assert one.mixture.sds_deg[0] == pytest.approx(math.degrees(math.atan(math.sqrt(s2))),
                                                   abs=0.01)


def test_ndf_censored_weight_in_weight_units():
    # the censored weight is an area, in the units of ``weights``: doubling both is the same
    rng = np.random.default_rng(33)
    tilt = _measured_tilts(rng, 20.0, 2000)
    seen = tilt <= NA_LIMIT_DEG
    c = float((~seen).sum())
    a = fit_ndf_mixture(tilt[seen], censored=(c, NA_LIMIT_DEG),
                        n_effective=500, options=_k(1))
    b = fit_ndf_mixture(tilt[seen], weights=np.full(int(seen.sum()), 2.0),
                        censored=(2 * c, NA_LIMIT_DEG), n_effective=500,
                        options=_k(1))
    assert a.mixture.sds_deg[0] == pytest.approx(b.mixture.sds_deg[0], abs=1e-6)
    assert a.info["censored_fraction"] == pytest.approx(b.info["censored_fraction"])


@pytest.mark.slow
def test_ndf_integer_weights_equal_repeated_samples(tilt_samples):
    rng = np.random.default_rng(34)
    tilt = tilt_samples(rng, [(0.6, 3.0), (0.4, 10.0)], 600)
    noise = rng.uniform(0.005, 0.02, 600)
    w = rng.integers(1, 5, 600)
    kw = dict(n_effective=150, options=_k(3))
    a = fit_ndf_mixture(tilt, slope_sigma=noise, weights=w, **kw)
    b = fit_ndf_mixture(np.repeat(tilt, w), slope_sigma=np.repeat(noise, w), **kw)
    assert a.n_components == b.n_components
    np.testing.assert_allclose(np.array(a.mixture.components), np.array(b.mixture.components),
                               rtol=1e-6)
    for k in a.bic_by_k:
        assert a.bic_by_k[k] == pytest.approx(b.bic_by_k[k], rel=1e-8)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_ndf_single_lobe_of_facets_gets_one_lobe(seed):
    rng = np.random.default_rng(40 + seed)
    noise = rng.uniform(0.01, 0.05, 300)
    fit = fit_ndf_mixture(_measured_tilts(rng, 8.0, 300, noise), slope_sigma=noise,
                          options=_k(4))
    assert fit.n_components == 1
    assert abs(fit.mixture.sds_deg[0] - 8.0) < 4 * _sd_deg_se(8.0, noise ** 2)


def test_width_relative_error_closed_forms():
    rng = np.random.default_rng(35)
    tilt = _measured_tilts(rng, 6.0, 400)
    # exact slopes: 1 / (2 sqrt(n_eff)) whatever the tilts
    for n_eff in (25.0, 100.0, 400.0):
        assert width_relative_error(tilt, 0.0, 1.0, n_eff) == pytest.approx(
            0.5 / math.sqrt(n_eff), rel=1e-6)
    # one noise σ for all: the MLE is V = Σ m² / (2n), s² = V − σ², error V / (2 s² √n)
    sigma = 0.04
    noisy = _measured_tilts(rng, 6.0, 400, np.full(400, sigma))
    V = np.mean(np.tan(np.radians(noisy)) ** 2) / 2.0
    expected = V / (2.0 * (V - sigma ** 2) * math.sqrt(400))
    assert width_relative_error(noisy, sigma, 1.0, 400) == pytest.approx(expected, rel=2e-3)
    # heteroscedastic: the Fisher error at the true width, within the sampling spread
    noise = rng.uniform(0.03, 0.12, 4000)
    het = _measured_tilts(rng, 5.0, 4000, noise)
    s = math.tan(math.radians(5.0))
    ref = 1.0 / (2.0 * s * s * math.sqrt(np.sum(1.0 / (s * s + noise ** 2) ** 2)))
    assert width_relative_error(het, noise, 1.0, 4000) == pytest.approx(ref, rel=0.1)
    # NaN and zero-weight samples are left out; fewer than two: infinite
    assert width_relative_error([5.0, np.nan], 0.0, 1.0, 10) == math.inf


@pytest.mark.parametrize("kw, match", [
    ({"censored": (10.0, None)}, "censored: a limit"),
    ({"censored": (10.0, 95.0)}, "censored: a limit"),
    ({"censored": (-1.0, 20.0)}, "censored: weight"),
    ({"censored": (np.nan, 20.0)}, "censored: weight"),
    ({"slope_sigma": [0.1, -0.1, 0.1]}, "slope_sigma"),
])
def test_ndf_argument_errors(kw, match):
    with pytest.raises(ValueError, match=match):
        fit_ndf_mixture([1.0, 2.0, 3.0], **kw)


def test_no_censored_weight_is_no_censoring():
    tilt = _measured_tilts(np.random.default_rng(36), 6.0, 500)
    a = fit_ndf_mixture(tilt, options=_k(2))
    b = fit_ndf_mixture(tilt, censored=(0.0, None), options=_k(2))
    assert a.mixture == b.mixture and b.info["censored_fraction"] == 0.0


@pytest.mark.parametrize("kw, param", [({"ndf_sd_floor_deg": 0.0}, "ndf_sd_floor_deg"),
                                       ({"ndf_sd_floor_deg": 89.5}, "ndf_sd_floor_deg"),
                                       ({"ndf_max_samples": 0}, "ndf_max_samples")])
def test_ndf_option_errors_name_the_option(kw, param):
    with pytest.raises(InputError, match=param) as err:
        FitOptions(**kw)
    assert err.value.param == param


def test_ndf_sd_floor_is_the_options():
    fit = fit_ndf_mixture(np.zeros(40), options=FitOptions(ndf_sd_floor_deg=0.5))
    assert fit.mixture.sds_deg[0] == pytest.approx(0.5)


# ------------------------------------------------------------------ the EM itself: the
# (lobe, sample) sums against the textbook updates, identical samples

from microfacet.analysis.ndf_fit import _rayleigh_em  # noqa: E402
from microfacet.analysis.sampling import collapse  # noqa: E402


def _rayleigh_em_textbook(m2, v, a, C, L2, w, s2, s2_floor, n_iter):
    """The deconvolved, censored Rayleigh-mixture EM of the module notes written out per
    (sample, lobe): the parameters after ``n_iter`` updates and ℓ′ there."""
    W = a.sum() + C
    w = w / w.sum()
    for it in range(n_iter + 1):
        V = s2 + v[:, None]
        dens = w / V * np.exp(-m2[:, None] / (2.0 * V))
        tail = w * np.exp(-L2 / (2.0 * s2))
        ll = float(np.sum(a * np.log(dens.sum(axis=1)))) + (C * math.log(tail.sum()) if C else 0)
        if it == n_iter:
            return w, s2, ll
        r = a[:, None] * dens / dens.sum(axis=1, keepdims=True)
        rc = C * tail / tail.sum()
        E = (s2 / V) ** 2 * m2[:, None] + 2.0 * s2 * v[:, None] / V
        nk = r.sum(axis=0) + rc
        s2 = np.maximum((0.5 * (r * E).sum(axis=0) + 0.5 * rc * (L2 + 2.0 * s2)) / nk, s2_floor)
        w = nk / W


@pytest.mark.parametrize("censored", [0.0, 150.0])
def test_rayleigh_em_updates_are_the_textbook_updates(censored):
    rng = np.random.default_rng(43)
    noise = rng.uniform(0.005, 0.03, 700)
    tilt = _measured_tilts(rng, 6.0, 700, noise)
    m2, v = np.tan(np.radians(tilt)) ** 2, noise ** 2
    a = rng.uniform(0.5, 2.0, 700)
    L2 = math.tan(math.radians(NA_LIMIT_DEG)) ** 2
    start = (np.array([1.0, 1.0, 2.0]), np.array([0.001, 0.01, 0.05]))
    for n_iter in (1, 9, 50):
        ours = _rayleigh_em((m2, v, a), (censored, L2), start, 1e-6, max_iter=n_iter,
                            tol=-np.inf)
        ref = _rayleigh_em_textbook(m2, v, a, censored, L2, *start, 1e-6, n_iter)
        for got, want in zip(ours, ref):
            np.testing.assert_allclose(got, want, rtol=1e-9)


def test_rayleigh_em_on_collapsed_samples_is_the_em_on_the_pixels():
    rng = np.random.default_rng(44)
    # per-pixel tilts: 30 facets, each one (tilt, slope noise) over its pixels
    noise = rng.uniform(0.005, 0.03, 30)
    tilt = _measured_tilts(rng, 8.0, 30, noise)
    reps = rng.integers(1, 80, 30)
    order = rng.permutation(reps.sum())
    m2 = np.repeat(np.tan(np.radians(tilt)) ** 2, reps)[order]
    v = np.repeat(noise ** 2, reps)[order]
    a = np.ones(m2.size)
    ac, m2c, vc = collapse(a, m2, v)
    assert m2c.size == 30 and ac.sum() == m2.size
    start = (np.ones(2), np.array([0.002, 0.03]))
    # update for update, and to convergence
    for n_iter in (3, 40):
        full = _rayleigh_em((m2, v, a), (40.0, 0.25), start, 1e-6, max_iter=n_iter,
                            tol=-np.inf)
        short = _rayleigh_em((m2c, vc, ac), (40.0, 0.25), start, 1e-6, max_iter=n_iter,
                             tol=-np.inf)
        for got, want in zip(short, full):
            np.testing.assert_allclose(got, want, rtol=1e-10)
    full = _rayleigh_em((m2, v, a), (40.0, 0.25), start, 1e-6)
    short = _rayleigh_em((m2c, vc, ac), (40.0, 0.25), start, 1e-6)
    for got, want in zip(short, full):
        np.testing.assert_allclose(got, want, rtol=1e-9)
