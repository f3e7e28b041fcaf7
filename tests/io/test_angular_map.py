"""Angular map files (microfacet.io.angular_map): the ``.npz`` round trip, a measured map
given as spectra only, malformed files, the PNG picture."""

import cv2
import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
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


def _npz_claiming(path, **shapes):
    """An .npz whose arrays are tiny on disk but whose headers claim ``shapes`` (the data are
    never read: the header is refused first)."""
    import zipfile

    with zipfile.ZipFile(path, "w") as zf:
        for key, (shape, dtype) in shapes.items():
            with zf.open(f"{key}.npy", "w") as fh:
                np.lib.format.write_array_header_1_0(fh, {"descr": np.dtype(dtype).str,
                                                          "fortran_order": False,
                                                          "shape": shape})
    return path


@pytest.mark.parametrize("shapes, pattern", [
    ({"theta_light_deg": ((10**9,), "<f8"), "theta_view_deg": ((3,), "<f8")},
     r"key 'theta_light_deg': shape \(1000000000,\); at most 3,600 values"),
    ({"theta_light_deg": ((3,), "<f8"), "theta_view_deg": ((3,), "<f8"),
      "spectra": ((3, 3, 10**8), "<f8"), "wavelength_nm": ((10**8,), "<f8")},
     r"key 'wavelength_nm': shape \(100000000,\); at most 4,001 values"),
    ({"theta_light_deg": ((3,), "<f8"), "theta_view_deg": ((3,), "<f8"),
      "lab": ((30000, 30000, 3), "<f4")}, r"lab shape \(30000, 30000, 3\), expected \(3, 3, 3\)"),
    ({"theta_light_deg": ((3,), "<f8"), "theta_view_deg": ((3,), "<f8"),
      "spectra": ((3, 3, 4), "<f8"), "wavelength_nm": ((81,), "<f8")},
     r"spectra shape \(3, 3, 4\), expected \(3, 3, 81\)"),
    ({"theta_light_deg": ((3,), "<f8"), "theta_view_deg": ((3,), "<f8"),
      "illuminant": ((), "<U100000")}, r"key 'illuminant': expected a short text"),
    ({"theta_light_deg": ((3,), "<c16"), "theta_view_deg": ((3,), "<f8")},
     r"key 'theta_light_deg': expected numbers, got dtype complex128"),
    ({"theta_light_deg": ((3600,), "<f8"), "theta_view_deg": ((3600,), "<f8"),
      "spectra": ((3600, 3600, 4001), "<f4"), "wavelength_nm": ((4001,), "<f8")},
     r"spectra of 3600 x 3600 angles x 4001 wavelengths needs about [\d,]+ MB of memory"),
    ({"theta_light_deg": ((3,), "<f8"), "theta_view_deg": ((3,), "<f8"),
      "lab": ((3, 3, 3), "<f4")}, r"cannot read \("),
])
def test_sizes_and_types_are_checked_from_the_headers(tmp_path, shapes, pattern):
    path = _npz_claiming(tmp_path / "m.npz", **shapes)
    with pytest.raises(InputError, match=pattern) as err:
        load_map(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_single_npy_is_not_a_map(tmp_path):
    np.save(tmp_path / "m.npy", np.zeros((3, 3)))
    with pytest.raises(InputError, match="not an .npz archive"):
        load_map(tmp_path / "m.npy")


def test_the_defaults_of_a_map_without_illuminant_are_the_package_defaults(tmp_path):
    from microfacet.core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER

    np.savez(tmp_path / "m.npz", theta_light_deg=GRID[:2], theta_view_deg=GRID[:3],
             lab=np.zeros((2, 3, 3), np.float32))
    m = load_map(tmp_path / "m.npz")
    assert (m.illuminant, m.observer) == (DEFAULT_ILLUMINANT, DEFAULT_OBSERVER)
