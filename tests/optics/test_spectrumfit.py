"""Thickness from a spectrum (microfacet.optics.spectrumfit): recovery of known thicknesses,
the runner-up, the scale fitted by default (and the warning when it is fixed). Reading
spectrum files: tests/io/test_spectrum.py."""

import logging

import numpy as np
import pytest

from microfacet.optics.constants import resolve_index
from microfacet.optics.spectrumfit import fit_thickness
from microfacet.optics.thinfilm import reflectance

FILM, SUB = "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974"
WL = np.arange(400.0, 751.0, 5.0)


# The seed's Table 1 thicknesses, recovered from model spectra with noise.
@pytest.mark.parametrize("d", [15.9, 50.8, 60.6, 87.5, 121.4, 138.4, 160.6, 173.9, 226.6, 264.4])
def test_recovers_thickness_with_noise(d):
    rng = np.random.default_rng(int(d * 10))
    R = reflectance(WL, 0.0, d, FILM, SUB) + rng.normal(0, 0.005, WL.size)
    fit = fit_thickness(WL, R)
    assert fit.thickness_nm == pytest.approx(d, abs=1.0)
    assert fit.residual_rms == pytest.approx(0.005, rel=0.3)
    assert np.isfinite(fit.runner_up_thickness_nm)
    assert abs(fit.runner_up_thickness_nm - d) > 2
    assert fit.runner_up_residual_rms > fit.residual_rms


def test_exact_spectrum_refines_below_the_grid_step():
    R = reflectance(WL, 25.0, 142.37, FILM, SUB)
    fit = fit_thickness(WL, R, angle_deg=25.0, grid_step_nm=1.0)
    assert fit.thickness_nm == pytest.approx(142.37, abs=1e-3)
    assert fit.residual_rms < 1e-6


def test_global_search_finds_a_minimum_a_local_optimiser_misses():
    from scipy.optimize import minimize_scalar

    R = reflectance(WL, 0.0, 250.0, FILM, SUB)
    def obj(d):
        return float(np.sqrt(np.mean((reflectance(WL, 0.0, d, FILM, SUB) - R) ** 2)))

    local = minimize_scalar(obj, bracket=(60.0, 70.0))
    assert abs(local.x - 250.0) > 20  # a local start far away lands elsewhere
    assert fit_thickness(WL, R).thickness_nm == pytest.approx(250.0, abs=1e-2)


def test_scale_fit_recovers_a_scaled_spectrum():
    R = 0.8 * reflectance(WL, 0.0, 95.0, FILM, SUB)
    fit = fit_thickness(WL, R, fit_scale=True)
    assert fit.thickness_nm == pytest.approx(95.0, abs=0.05)
    assert fit.scale == pytest.approx(0.8, rel=1e-3)


def test_model_spectrum_agrees_with_tmm():
    """The model the scale tests rely on, checked at one point against ``tmm``."""
    tmm = pytest.importorskip("tmm")
    wl, d, th = 550.0, 80.0, 30.0
    n1 = complex(resolve_index(FILM, np.array([wl]))[0])
    n2 = complex(resolve_index(SUB, np.array([wl]))[0])
    ref = np.mean([tmm.coh_tmm(pol, [1.0, n1, n2], [np.inf, d, np.inf], np.deg2rad(th), wl)["R"]
                   for pol in ("s", "p")])
    assert float(reflectance(np.array([wl]), th, d, FILM, SUB)[0]) == pytest.approx(ref, abs=1e-10)


def test_a_spectrum_scaled_by_0_8_returns_its_thickness_by_default(caplog):
    R = 0.8 * reflectance(WL, 0.0, 80.0, FILM, SUB)
    fit = fit_thickness(WL, R)                          # the scale is fitted by default
    assert fit.scale_fitted
    assert fit.thickness_nm == pytest.approx(80.0, abs=0.05)
    assert fit.scale == pytest.approx(0.8, rel=1e-3)
    with caplog.at_level(logging.WARNING, logger="microfacet.optics.spectrumfit"):
        fixed = fit_thickness(WL, R, fit_scale=False)   # the level trusted: a wrong thickness
    assert not fixed.scale_fitted and fixed.scale == 1.0
    assert abs(fixed.thickness_nm - 80.0) > 3
    assert "the spectrum looks scaled" in caplog.text
    assert "fitted scale 0.8 it is 80.0 nm" in caplog.text


def test_fixed_scale_on_calibrated_data_agrees_and_is_quiet(caplog):
    rng = np.random.default_rng(3)
    R = reflectance(WL, 0.0, 80.0, FILM, SUB) + rng.normal(0, 0.005, WL.size)
    with caplog.at_level(logging.WARNING, logger="microfacet.optics.spectrumfit"):
        fixed = fit_thickness(WL, R, fit_scale=False)
        free = fit_thickness(WL, R)
    assert fixed.thickness_nm == pytest.approx(80.0, abs=1.0)
    assert free.thickness_nm == pytest.approx(fixed.thickness_nm, abs=0.5)
    assert free.scale == pytest.approx(1.0, abs=0.02)
    assert caplog.text == ""


def test_an_implausible_fitted_scale_is_warned(caplog):
    R = 0.2 * reflectance(WL, 0.0, 80.0, FILM, SUB)
    with caplog.at_level(logging.WARNING, logger="microfacet.optics.spectrumfit"):
        fit = fit_thickness(WL, R)
    assert fit.thickness_nm == pytest.approx(80.0, abs=0.05)
    assert "the fitted scale is 0.2" in caplog.text
