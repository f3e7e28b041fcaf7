"""Comparing angular maps (microfacet.forward.compare): ΔE00 maps, their means with and
without the specular band, fitting eq. 6's lobe exponent and the exposure."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.core.angular import AngularMap
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.forward.compare import (
    delta_e_map,
    fit_eq6,
    fit_exposure,
    mean_delta_e,
    specular_mask,
)

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = np.arange(0.0, 86.0, 5.0)


def test_delta_e_of_identical_maps_is_zero_and_means_are_zero():
    m = simulate_map(model="microfacet", thickness=G3, ndf=F2, theta_light_deg=GRID,
                     theta_view_deg=GRID, exposure=0.2)
    de = delta_e_map(m, m)
    assert de.shape == (GRID.size, GRID.size) and np.all(de == 0)
    s = mean_delta_e(de, GRID, GRID)
    assert s["mean"] == 0 and s["mean_excluding_specular"] == 0
    assert s["n_cells"] == GRID.size ** 2


def test_mean_delta_e_excludes_the_specular_band_and_nan_cells():
    tl = np.array([0.0, 30.0, 60.0])
    tv = np.array([0.0, 25.0, 30.0, 50.0])
    de = np.arange(12.0).reshape(3, 4)
    de[2, 0] = np.nan
    s = mean_delta_e(de, tl, tv, specular_halfwidth_deg=10.0)
    spec = np.abs(tv[None, :] - tl[:, None]) <= 10
    assert (specular_mask(tl, tv, halfwidth_deg=10) == spec).all()
    ok = np.isfinite(de)
    assert s["mean"] == pytest.approx(np.mean(de[ok]))
    assert s["mean_excluding_specular"] == pytest.approx(np.mean(de[ok & ~spec]))
    assert s["n_cells"] == 11 and s["n_cells_excluding_specular"] == int((ok & ~spec).sum())


def test_delta_e_map_differs_between_models_and_needs_the_same_grid():
    a = simulate_map(model="microfacet", thickness=G3, ndf=F2, theta_light_deg=GRID,
                     theta_view_deg=GRID, exposure=0.2)
    b = simulate_map(model="eq6", thickness=G3, ndf=F2, n=50, theta_light_deg=GRID,
                     theta_view_deg=GRID)
    assert np.nanmean(delta_e_map(a, b)) > 1
    c = simulate_map(model="half-vector", thickness=G3, theta_light_deg=GRID[:-1],
                     theta_view_deg=GRID)
    with pytest.raises(ValueError, match="theta_light_deg"):
        delta_e_map(a, c)


@pytest.mark.slow
def test_fit_recovers_lobe_exponent_and_exposure():
    grid = np.arange(0.0, 86.0, 3.0)
    meas = simulate_map(model="eq6", thickness=G3, ndf=F2, n=37.0, exposure=2.2,
                        theta_light_deg=grid, theta_view_deg=grid)
    meas = AngularMap(meas.theta_light_deg, meas.theta_view_deg, meas.lab)  # Lab only
    r = fit_eq6(meas, thickness=G3, ndf=F2)
    assert r.n == pytest.approx(37.0, rel=0.01)
    assert r.exposure == pytest.approx(2.2, rel=0.005)
    assert r.mean_delta_e < 0.01
    # Exposure fixed at the truth, on the diffuse cells only.
    r2 = fit_eq6(meas, thickness=G3, ndf=F2, fit_exposure_too=False, exposure=2.2,
                 region="diffuse")
    assert r2.n == pytest.approx(37.0, rel=0.01)


def test_fit_exposure_of_the_microfacet_model():
    m1 = simulate_map(model="microfacet", thickness=G3, ndf=F2, theta_light_deg=GRID,
                      theta_view_deg=GRID)
    white = color.spectral_weights(m1.wavelength_nm).sum(axis=0)
    meas_lab = color.xyz_to_lab(0.37 * m1.xyz, white=white)
    meas_lab[0, :] = np.nan  # unmeasured row
    e, c = fit_exposure(m1.xyz, meas_lab, white=white)
    assert e == pytest.approx(0.37, rel=1e-3) and c < 0.01
