"""Thickness from a spectrum (microfacet.optics.spectrumfit): recovery of known thicknesses,
the runner-up, scale fitting. Reading spectrum CSVs: tests/io/test_spectrum.py."""

import numpy as np
import pytest

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
