"""Angular map files (microfacet.io.angular_map): the ``.npz`` round trip, a measured map
given as spectra only, malformed files, the PNG picture."""

import cv2
import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.forward.compare import delta_e_map
from microfacet.io.angular_map import load_map, save_map, save_png

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = np.arange(0.0, 86.0, 5.0)


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


def test_map_png_written(tmp_path):
    m = simulate_map(model="half-vector", thickness=120.0, theta_light_deg=[0, 20],
                     theta_view_deg=[0, 20, 40])
    save_png(tmp_path / "m.png", m, scale=2)
    img = cv2.imread(str(tmp_path / "m.png"))
    assert img.shape == (4, 6, 3)
