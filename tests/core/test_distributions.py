"""The two distributions (microfacet.core.distributions): the thickness mixture and the NDF
lobes. Checked against their definitions by numerical integration and against the slope
distribution they come from (slopes N(0, s² I) per lobe), never against numbers of a run.
"""

from __future__ import annotations

import json
import math
import time

import numpy as np
import pytest
from scipy import integrate, special

from microfacet.core.distributions import NDF_FORM, NDFMixture, ThicknessMixture

THICKNESS = [
    ThicknessMixture([(1.0, 51.0, 2.0)]),
    ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)]),
    ThicknessMixture([(2.0, 300.0, 40.0), (1.0, 120.0, 0.5)]),      # unnormalised, unsorted
]
NDFS = [
    NDFMixture([(1.0, 3.0)]),
    NDFMixture([(0.6, 3.0), (0.4, 9.0)]),
    NDFMixture([(0.2, 1.0), (0.5, 12.0), (0.3, 30.0)]),
]


# ------------------------------------------------------------------------------ thickness


@pytest.mark.parametrize("g", THICKNESS)
def test_thickness_pdf_is_a_density_with_the_stated_moments(g):
    lo, hi = g.support_nm(n_sd=10)
    d = np.linspace(lo, hi, 400_001)
    p = g.pdf(d)
    assert np.all(p >= 0)
    assert np.trapezoid(p, d) == pytest.approx(1.0, abs=1e-9)
    mean = np.trapezoid(p * d, d)
    assert g.mean_nm == pytest.approx(mean, abs=1e-6)
    assert g.sd_nm == pytest.approx(math.sqrt(np.trapezoid(p * (d - mean) ** 2, d)), rel=1e-6)
    # support_nm(4 SD) holds all but a negligible mass
    a, b = g.support_nm()
    inside = (d >= a) & (d <= b)
    assert np.trapezoid(p[inside], d[inside]) > 1 - 1e-4
    assert p.shape == d.shape and np.ndim(g.pdf(120.0)) == 0


def test_thickness_components_are_normalised_and_sorted():
    g = THICKNESS[2]
    np.testing.assert_allclose(g.weights, [1 / 3, 2 / 3])
    np.testing.assert_array_equal(g.means_nm, [120.0, 300.0])
    np.testing.assert_array_equal(g.sds_nm, [0.5, 40.0])
    assert g == ThicknessMixture([(0.5, 120.0, 0.5), (1.0, 300.0, 40.0)])


@pytest.mark.parametrize("g", THICKNESS)
def test_thickness_json_round_trip(g):
    data = json.loads(json.dumps(g.to_json()))
    assert set(data) == {"components"}
    assert all(set(c) == {"weight", "mean_nm", "sd_nm"} for c in data["components"])
    assert ThicknessMixture.from_json(data) == g


# ---------------------------------------------------------------------------------- NDF


def _theta_grid(n=400_001):
    return np.linspace(0.0, 89.999, n)


@pytest.mark.parametrize("f", NDFS)
def test_D_is_normalised_over_the_projected_hemisphere(f):
    """∫ D(ω) cos θ dω = 2π ∫ D(θ) cos θ sin θ dθ = 1."""
    th = _theta_grid()
    r = np.radians(th)
    total = 2 * math.pi * np.trapezoid(f.D(th) * np.cos(r) * np.sin(r), r)
    assert total == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("f", NDFS)
def test_D_is_the_slope_density_over_cos4(f):
    """The NDF of a surface whose slopes (p, q) have density P(p, q) is
    D(θ) = P(tan θ) / cos⁴ θ; here P is a mixture of isotropic normals N(0, s² I)."""
    th = np.linspace(0.0, 80.0, 161)
    t = np.tan(np.radians(th))
    P = sum(w * np.exp(-0.5 * t * t / s ** 2) / (2 * math.pi * s ** 2)
            for w, s in zip(f.weights, np.tan(np.radians(f.sds_deg))))
    np.testing.assert_allclose(f.D(th), P / np.cos(np.radians(th)) ** 4, rtol=1e-12,
                               atol=1e-300)
    np.testing.assert_allclose(f.beckmann_alpha, math.sqrt(2) * f.slope_sd)


@pytest.mark.slow
@pytest.mark.parametrize("f", NDFS)
def test_tilt_pdf_is_2pi_D_cos_sin_and_the_rayleigh_slope_law(f):
    th = _theta_grid()
    r = np.radians(th)
    np.testing.assert_allclose(f.tilt_pdf(th), 2 * math.pi * f.D(th) * np.cos(r) * np.sin(r)
                               * math.pi / 180, rtol=1e-10, atol=1e-300)
    assert np.trapezoid(f.tilt_pdf(th), th) == pytest.approx(1.0, abs=1e-6)
    # CDF: the slope magnitude tan θ is Rayleigh(s) per lobe
    cdf = integrate.cumulative_trapezoid(f.tilt_pdf(th), th, initial=0.0)
    t = np.tan(r)
    ref = sum(w * -np.expm1(-0.5 * t * t / s ** 2)
              for w, s in zip(f.weights, f.slope_sd))
    np.testing.assert_allclose(cdf[::1000], ref[::1000], atol=1e-6)


def test_tilt_pdf_of_sampled_slopes():
    """Monte Carlo: tilts of slopes drawn from the lobes follow tilt_pdf (per degree)."""
    f = NDFS[1]
    rng = np.random.default_rng(0)
    n = 400_000
    k = rng.choice(2, n, p=f.weights)
    s = f.slope_sd[k]
    tilt = np.degrees(np.arctan(np.hypot(rng.normal(0, 1, n) * s, rng.normal(0, 1, n) * s)))
    hist, edges = np.histogram(tilt, bins=60, range=(0, 30), density=True)
    centres = 0.5 * (edges[1:] + edges[:-1])
    np.testing.assert_allclose(hist, f.tilt_pdf(centres), atol=0.006)


@pytest.mark.parametrize("limit", [None, 40.0, 20.0, 8.0])
def test_rms_slope_of_sampled_slopes(limit):
    """Monte Carlo: the RMS of |∇h| of slopes drawn from the lobes, of all or of those
    tilted less than ``limit``, is rms_slope(limit)."""
    f = NDFS[1]
    rng = np.random.default_rng(1)
    n = 1_000_000
    s = f.slope_sd[rng.choice(len(f.weights), n, p=f.weights)]
    m2 = (rng.normal(0, 1, n) * s) ** 2 + (rng.normal(0, 1, n) * s) ** 2
    if limit is not None:
        m2 = m2[m2 < math.tan(math.radians(limit)) ** 2]
    assert f.rms_slope(limit) == pytest.approx(math.sqrt(m2.mean()), rel=3e-3)


@pytest.mark.parametrize("factor", [0.5, 1.0, 1.7])
def test_scaled_lobes_are_the_slopes_times_the_factor(factor):
    """scaled(k): the lobes of the slopes k·∇h — the same weights, slope SDs × k, so the
    tilt density is the original's in tan θ / k and the RMS slope k times as large."""
    f = NDFS[1]
    g = f.scaled(factor)
    np.testing.assert_allclose(g.weights, f.weights, rtol=1e-12)
    np.testing.assert_allclose(g.slope_sd, factor * f.slope_sd, rtol=1e-12)
    assert g.rms_slope() == pytest.approx(factor * f.rms_slope(), rel=1e-12)
    th = np.linspace(0.5, 60.0, 50)
    t = np.tan(np.radians(th))
    # density of m = tan θ: p_g(m) = p_f(m / k) / k, with p(m) = tilt_pdf · dθ/dm
    pm_g = g.tilt_pdf(th) * np.cos(np.radians(th)) ** 2
    th_f = np.degrees(np.arctan(t / factor))
    pm_f = f.tilt_pdf(th_f) * np.cos(np.radians(th_f)) ** 2
    np.testing.assert_allclose(pm_g, pm_f / factor, rtol=1e-9, atol=1e-15)


def _smith_lambda_by_integration(f, theta_deg):
    """Λ(θ) = (1/μ) ∫_μ^∞ (q − μ) p(q) dq with μ = cot θ and p the slope density along the
    direction's azimuth (a mixture of N(0, s²)): Smith's definition."""
    mu = 1.0 / math.tan(math.radians(theta_deg))

    def p(q):
        return sum(w * math.exp(-0.5 * (q / s) ** 2) / (s * math.sqrt(2 * math.pi))
                   for w, s in zip(f.weights, f.slope_sd))

    val, _ = integrate.quad(lambda q: (q - mu) * p(q), mu, np.inf, epsabs=1e-14)
    return val / mu


@pytest.mark.parametrize("f", NDFS)
@pytest.mark.parametrize("theta", [10.0, 45.0, 70.0, 85.0, 89.0])
def test_smith_lambda_by_its_definition(f, theta):
    assert f.smith_lambda(theta) == pytest.approx(_smith_lambda_by_integration(f, theta),
                                                  rel=1e-6, abs=1e-12)


def test_smith_lambda_closed_form_of_one_beckmann_lobe():
    """One lobe: Λ = (erf(a) − 1)/2 + exp(−a²)/(2a√π), a = 1/(α tan θ) (Walter et al.
    2007, eq. 27 with the exact Λ); 0 at normal incidence."""
    f = NDFMixture([(1.0, 12.0)])
    alpha = math.sqrt(2) * math.tan(math.radians(12.0))
    th = np.array([5.0, 30.0, 60.0, 80.0, 88.0])
    a = 1 / (alpha * np.tan(np.radians(th)))
    ref = (special.erf(a) - 1) / 2 + np.exp(-a * a) / (2 * a * math.sqrt(math.pi))
    np.testing.assert_allclose(f.smith_lambda(th), ref, rtol=1e-12)
    assert f.smith_lambda(0.0) == 0.0
    lam = f.smith_lambda(np.linspace(0, 89, 90))
    assert np.all(np.diff(lam) >= 0) and np.all(lam >= 0)


@pytest.mark.slow
@pytest.mark.parametrize("f", NDFS[1:])
@pytest.mark.parametrize("theta_o", [0.0, 40.0, 75.0])
def test_D_and_lambda_are_consistent(f, theta_o):
    """The projected area of the visible microfacets onto a direction ω_o equals that of
    the macro surface (Heitz 2014, eq. 6): ∫ ⟨ω_o, m⟩⁺ D(m) dm = cos θ_o (1 + Λ(θ_o))."""
    n_t, n_p = 6000, 720
    th = (np.arange(n_t) + 0.5) * (89.99 / n_t)
    ph = (np.arange(n_p) + 0.5) * (2 * math.pi / n_p)
    r = np.radians(th)[:, None]
    o = math.radians(theta_o)
    dot = np.sin(r) * np.cos(ph)[None, :] * math.sin(o) + np.cos(r) * math.cos(o)
    dw = (np.sin(r) * math.radians(89.99 / n_t) * (2 * math.pi / n_p))
    lhs = float(np.sum(np.maximum(dot, 0) * f.D(th)[:, None] * dw))
    rhs = math.cos(o) * (1 + float(f.smith_lambda(theta_o)))
    assert lhs == pytest.approx(rhs, rel=2e-3)


@pytest.mark.parametrize("f", NDFS)
def test_ndf_json_round_trip(f):
    data = json.loads(json.dumps(f.to_json()))
    assert data["form"] == NDF_FORM == "gaussian-slope"
    assert all(c["mean_deg"] == 0.0 for c in data["components"])
    assert NDFMixture.from_json(data) == f
    assert NDFMixture.from_json({"components": data["components"]}) == f  # form optional
    assert f.rms_sd_deg == pytest.approx(math.sqrt(np.sum(f.weights * f.sds_deg ** 2)))


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize("make, match", [
    (lambda: ThicknessMixture([]), r"thickness mixture: at least one component"),
    (lambda: ThicknessMixture([(1.0, 120.0)]), r"thickness mixture: component 0 needs 3"),
    (lambda: ThicknessMixture([(1.0, 120.0, 3.0), (0.0, 140.0, 3.0)]),
     r"thickness mixture: component 1 has weight <= 0"),
    (lambda: ThicknessMixture([(1.0, 120.0, -3.0)]), r"thickness mixture: component 0 has sd"),
    (lambda: ThicknessMixture([(1.0, np.nan, 3.0)]),
     r"thickness mixture: component 0 is not finite"),
    (lambda: NDFMixture([(1.0, 3.0, 0.0)]), r"NDF mixture: component 0 needs 2"),
    (lambda: NDFMixture([(1.0, 3.0), (-1.0, 9.0)]), r"NDF mixture: component 1 has weight"),
    (lambda: NDFMixture([(1.0, 0.0)]), r"NDF mixture: component 0 has sd <= 0"),
    (lambda: NDFMixture([(1.0, 89.5)]), r"NDF mixture: sd_deg must be < 89"),
    (lambda: NDFMixture([(1.0, np.inf)]), r"NDF mixture: component 0 is not finite"),
    (lambda: ThicknessMixture.from_json({"components": [{"weight": 1, "mean_nm": 5}]}),
     r"thickness mixture: missing key 'sd_nm'"),
    (lambda: ThicknessMixture.from_json({}), r"thickness mixture: missing key 'components'"),
    (lambda: NDFMixture.from_json({"form": "ggx", "components": []}),
     r"NDF mixture: unsupported form 'ggx'"),
    (lambda: NDFMixture.from_json({"components": [{"weight": 1, "mean_deg": 2, "sd_deg": 3}]}),
     r"NDF mixture: lobes must have mean_deg 0"),
    (lambda: NDFMixture.from_json({"components": [{"weight": 1}]}),
     r"NDF mixture: missing key 'sd_deg'"),
])
def test_invalid_components_are_refused_naming_the_mixture_and_component(make, match):
    with pytest.raises(ValueError, match=match):
        make()


@pytest.mark.parametrize("cls, comp, name", [
    (ThicknessMixture, {"weight": 1, "mean_nm": 51, "sd_nm": 2}, "thickness mixture"),
    (NDFMixture, {"weight": 1, "mean_deg": 0, "sd_deg": 5}, "NDF mixture"),
])
def test_from_json_refuses_more_than_max_components_before_reading_them(cls, comp, name):
    """A file claiming a million components is refused at once (the forward models' cost
    grows with the count); MAX_COMPONENTS are read."""
    from microfacet.core.distributions import MAX_COMPONENTS

    assert len(cls.from_json({"components": [comp] * MAX_COMPONENTS}).components) == 10
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=rf"^{name}: 1,000,000 components, more than 10$"):
        cls.from_json({"components": [comp] * 10**6})
    assert time.perf_counter() - t0 < 0.1
    with pytest.raises(ValueError, match=rf"^{name}: 'components' must be a list, got dict"):
        cls.from_json({"components": {"0": comp}})
    with pytest.raises(ValueError, match=rf"^{name}: every component must be an object"):
        cls.from_json({"components": [comp, [1, 2, 3]]})
