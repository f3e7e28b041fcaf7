"""Peak fits of the focus curve (microfacet.focus.peaks) against analytic curves and Monte
Carlo references."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from microfacet.focus.measures import focus_measure
from microfacet.focus.peaks import detection_threshold, fit_peak, peak_fit, pertuz_db


def lorentz_curve(x, mu, s=1.0, beta=1.0):
    """Gradient energy of Gaussian-correlated texture under Gaussian defocus β|x − μ|."""
    return 1.0 / (s * s + beta * beta * (x - mu) ** 2) ** 2


@pytest.mark.parametrize("radius", [1, 2, 3])
def test_lorentz_recovers_analytic_peak(radius):
    mu = np.linspace(-0.5, 0.5, 41)                     # true peak, z steps from the best
    x = np.arange(-radius, radius + 1, dtype=float)
    for s, beta in ((0.7, 1.55), (1.0, 1.0), (2.0, 0.6)):
        vals = lorentz_curve(x[:, None], mu[None], s, beta) * 3.7
        fit = fit_peak(vals, x, model="lorentz")
        assert fit.ok.all()
        assert np.max(np.abs(fit.offset - mu)) < 0.01 * 0.01      # exact model: ≪ 0.01 step
        # the half width at 1/4 height of F = (s² + β²x²)^-2 is s/β
        np.testing.assert_allclose(fit.width, s / beta, rtol=1e-6)
        # float32 working precision still far below 0.01 step
        f32 = fit_peak(vals.astype(np.float32), x.astype(np.float32), model="lorentz",
                       dtype=np.float32)
        assert np.max(np.abs(f32.offset - mu)) < 1e-3


def test_lorentz_on_rendered_tenengrad_curve_beats_gauss():
    """Tenengrad of a blurred random texture (cv2 blur, Sobel: not the model exactly): the
    Lorentz fit over ±2 slices lands within 0.01 step, and closer than the Gaussian fit."""
    rng = np.random.default_rng(3)
    tex = cv2.GaussianBlur(rng.standard_normal((96, 96)).astype(np.float32), (0, 0), 0.8)
    errs = {"lorentz": [], "gauss": []}
    for mu in np.linspace(-0.45, 0.45, 7):
        x = np.arange(-2.0, 3.0)
        f = [focus_measure(cv2.GaussianBlur(tex, (0, 0), math.hypot(0.67, 1.55 * (xk - mu))),
                           window_px=95, window="box")[48, 48] for xk in x]
        vals = np.array(f, float)[:, None]
        for model in errs:
            errs[model].append(abs(float(fit_peak(vals, x, model=model).offset[0]) - mu))
    assert max(errs["lorentz"]) < 0.01
    assert max(errs["lorentz"]) < 0.5 * max(errs["gauss"])


def test_fit_peak_non_uniform_positions_per_pixel():
    """Per-pixel positions (non-uniform z): the exact model is still recovered."""
    rng = np.random.default_rng(1)
    x = np.arange(-2.0, 3.0)[:, None] + rng.uniform(-0.3, 0.3, (5, 200))
    mu = rng.uniform(-0.4, 0.4, 200)
    vals = lorentz_curve(x, mu, 0.8, 1.3)
    fit = fit_peak(vals, x, model="lorentz")
    assert fit.ok.all() and np.max(np.abs(fit.offset - mu)) < 1e-6
    g = np.exp(-0.5 * ((x - mu) / 1.2) ** 2)
    fit = fit_peak(g, x, model="gauss")
    assert np.max(np.abs(fit.offset - mu)) < 1e-6
    np.testing.assert_allclose(fit.width, 1.2, rtol=1e-6)


@pytest.mark.parametrize("model", ["lorentz", "gauss"])
def test_fit_variance_matches_monte_carlo(model):
    """var(offset) ≈ s²·var_unit with s² = E[rss]/(K − 3) under a constant noise on F."""
    rng = np.random.default_rng(7)
    x = np.arange(-2.0, 3.0)
    mu = 0.2
    clean = lorentz_curve(x, mu, 1.0, 1.0) if model == "lorentz" else \
        np.exp(-0.5 * (x - mu) ** 2)
    n = 40000
    vals = clean[:, None] + 0.004 * rng.standard_normal((5, n))
    fit = fit_peak(vals, x, model=model)
    assert fit.ok.mean() > 0.999
    emp = np.var(fit.offset[fit.ok])
    s2 = np.mean(fit.rss[fit.ok]) / (5 - 3)
    pred = s2 * np.median(fit.var_unit[fit.ok])
    assert 0.8 < emp / pred < 1.25, (emp, pred)


def test_flat_and_missing_values_have_no_peak():
    x = np.arange(-2.0, 3.0)
    flat = fit_peak(np.full((5, 3), 2.0), x, model="lorentz")
    assert not flat.ok.any() and np.isinf(flat.var_unit).all()
    vals = lorentz_curve(x, 0.1)[:, None].repeat(2, 1)
    vals[:3, 1] = np.nan                                 # only two values left
    fit = fit_peak(vals, x, model="lorentz")
    assert fit.ok.tolist() == [True, False]
    with pytest.raises(ValueError):
        fit_peak(vals, x, model="spline")


def test_peak_fit_is_the_gaussian_fit():
    x = np.arange(-2.0, 3.0)
    v = np.exp(-0.5 * ((x - 0.3) / 1.1) ** 2)[:, None]
    off, coef, ok = peak_fit(v, x)
    assert ok[0] and abs(off[0] - 0.3) < 1e-9
    assert abs(coef[0][0] + 0.5 / 1.1 ** 2) < 1e-9       # a = −1/(2σ²)


def test_pertuz_db_against_direct_formula():
    """An exact Gaussian curve over 9 slices, fit over ±2: the residual is F outside the fit
    window, so R = 20·log10(N·F_max / Σ_outside F)."""
    z = np.arange(9.0)
    mu, sd = 4.2, 1.3
    f = np.exp(-0.5 * ((z - mu) / sd) ** 2) + 0.01
    best = int(np.argmax(f))
    sl = slice(best - 2, best + 3)
    x = (z[sl] - z[best])[:, None]
    vals = f[sl][:, None]
    fit = fit_peak(vals, x, model="gauss")
    r = pertuz_db(vals, x, fit, "gauss", np.array([f.max()]), np.array([f.sum()]), 9)
    g = np.exp(np.polyval(fit.coef[:, 0], x[:, 0]))
    ref = 20 * np.log10(9 * f.max() / (np.abs(f[sl] - g).sum() + f.sum() - f[sl].sum()))
    assert abs(float(r[0]) - ref) < 1e-6


@pytest.mark.parametrize("k", [2.0, 15.8])
def test_detection_threshold_false_peak_rate(k):
    """The max of n Gamma(k) values exceeds μ + t·μ/√k with probability alpha."""
    rng = np.random.default_rng(0)
    n, alpha, trials = 24, 0.01, 200_000
    t = detection_threshold(n, k, alpha)
    g = rng.gamma(k, 1.0 / k, (trials, n)).max(1)      # mean 1, spread 1/√k
    rate = np.mean(g > 1.0 + t / math.sqrt(k))
    assert 0.8 * alpha < rate < 1.2 * alpha, rate
    assert detection_threshold(n, k, 1e-5) > t
