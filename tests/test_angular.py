"""Angular colour maps, ΔE00 maps, the map file format and fitting."""

import numpy as np
import pytest

from microfacet import colour as color
from microfacet.colour.srgb import colours_from_spectra
from microfacet.core.angular import AngularMap
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.forward.compare import (delta_e_map, fit_eq6, fit_exposure, mean_delta_e,
                                        specular_mask)
from microfacet.forward.halfvector import spectra
from microfacet.io.angular_map import load_map, save_map

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = np.arange(0.0, 86.0, 5.0)


def test_half_vector_map_of_one_film_equals_the_film_at_the_half_angle():
    """The map (film reflectance tabulated over θ_d, averaged over g(d)) equals the film
    evaluated directly at each cell's half angle (:func:`halfvector.spectra`)."""
    m = simulate_map(model="half-vector", thickness=51.0, theta_light_deg=GRID,
                     theta_view_deg=GRID, exposure=0.7)
    wl, R = spectra(GRID[:, None], GRID[None, :], 51.0, wavelength_nm=m.wavelength_nm)
    _, ref_lab, ref_srgb, _ = colours_from_spectra(R, wl, exposure=0.7)
    assert np.max(color.delta_e_2000(m.lab.astype(float), ref_lab.astype(float))) < 1e-3
    assert np.abs(m.srgb.astype(int) - ref_srgb.astype(int)).max() <= 1


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


def test_map_file_round_trip_and_lab_from_spectra(tmp_path):
    m = simulate_map(model="eq6", thickness=G3, ndf=F2, n=20, theta_light_deg=GRID[:5],
                     theta_view_deg=GRID, exposure=3.0)
    save_map(tmp_path / "m.npz", m)
    r = load_map(tmp_path / "m.npz")
    np.testing.assert_array_equal(r.theta_light_deg, m.theta_light_deg)
    np.testing.assert_array_equal(r.lab, m.lab)
    np.testing.assert_allclose(r.spectra, m.spectra, rtol=1e-6)
    # A measured map with spectra only: Lab is computed on read, same as the model's.
    np.savez(tmp_path / "s.npz", theta_light_deg=m.theta_light_deg,
             theta_view_deg=m.theta_view_deg, spectra=m.spectra, wavelength_nm=m.wavelength_nm)
    s = load_map(tmp_path / "s.npz")
    assert np.max(delta_e_map(m, s)) < 1e-3
    np.savez(tmp_path / "bad.npz", theta_light_deg=GRID, theta_view_deg=GRID)
    with pytest.raises(ValueError, match="lab"):
        load_map(tmp_path / "bad.npz")
    np.savez(tmp_path / "bad2.npz", theta_light_deg=GRID, theta_view_deg=GRID,
             lab=np.zeros((2, 2, 3)))
    with pytest.raises(ValueError, match="lab shape"):
        load_map(tmp_path / "bad2.npz")


def test_colours_white_is_lab_100_and_nan_propagates():
    wl = np.arange(380.0, 781.0, 5.0)
    R = np.ones((2, wl.size))
    R[1, 3] = np.nan
    xyz, lab, rgb, white = colours_from_spectra(R, wl)
    np.testing.assert_allclose(lab[0], [100, 0, 0], atol=1e-3)
    assert np.all(np.isnan(lab[1]))
    with pytest.raises(ValueError, match="exposure"):
        colours_from_spectra(R, wl, exposure=0)


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


def test_simulate_map_argument_errors():
    with pytest.raises(ValueError, match="model"):
        simulate_map(model="phong", thickness=100.0)
    with pytest.raises(ValueError, match="ndf"):
        simulate_map(model="microfacet", thickness=100.0)
    with pytest.raises(ValueError, match="n:"):
        simulate_map(model="eq6", thickness=100.0, ndf=F2)
    with pytest.raises(ValueError, match="theta_view_deg"):
        simulate_map(model="half-vector", thickness=100.0, theta_view_deg=[0, 90])


def test_in_plane_90x90_map_is_fast():
    import time

    t = np.arange(90.0)
    simulate_map(model="microfacet", thickness=G3, ndf=F2, theta_light_deg=t[:5],
                 theta_view_deg=t[:5])  # warm-up (imports, colour tables)
    for model in ("microfacet", "eq6"):
        t0 = time.perf_counter()
        simulate_map(model=model, thickness=G3, ndf=F2, n=50, theta_light_deg=t,
                     theta_view_deg=t)
        assert time.perf_counter() - t0 < 2.0  # benchmark target 1 s; slack for CI noise
