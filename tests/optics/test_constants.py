"""Optical-constant sets: loading, interpolation and errors."""

import csv
from importlib import resources

import numpy as np
import pytest

from microfacet import optics


def _raw(name):
    path = resources.files("microfacet.data").joinpath("optical_constants", name + ".csv")
    with path.open() as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["wavelength_nm", "n", "k"]
    return np.array(rows[1:], dtype=float)


def test_every_bundled_set_loads_and_reproduces_its_tabulated_points():
    names = optics.known_sets()
    assert optics.DEFAULT_FILM in names and optics.DEFAULT_SUBSTRATE in names
    assert len(names) == 13
    for name in names:
        raw = _raw(name)
        lo, hi = optics.load_set(name).range_nm
        inside = (raw[:, 0] >= lo) & (raw[:, 0] <= hi)
        got = optics.optical_constants(name, raw[inside, 0])
        np.testing.assert_allclose(got.real, raw[inside, 1], rtol=1e-12)
        np.testing.assert_allclose(got.imag, raw[inside, 2], rtol=1e-12, atol=1e-15)
        assert np.all(got.imag >= 0)


def test_interpolation_is_linear_between_points():
    raw = _raw("Ti_JohnsonChristy1974")
    i = np.searchsorted(raw[:, 0], 550.0)
    (w0, n0, k0), (w1, n1, k1) = raw[i - 1], raw[i]
    t = (550.0 - w0) / (w1 - w0)
    got = optics.optical_constants("Ti_JohnsonChristy1974", 550.0)
    assert got == pytest.approx(complex(n0 + t * (n1 - n0), k0 + t * (k1 - k0)), rel=1e-12)
    assert got.real == pytest.approx(2.54, abs=0.01) and got.imag == pytest.approx(3.43, abs=0.01)


def test_shape_is_kept_and_nan_passes_through():
    wl = np.array([[400.0, np.nan], [500.0, 600.0]])
    n = optics.optical_constants(optics.DEFAULT_FILM, wl)
    assert n.shape == (2, 2) and n.dtype == np.complex128
    assert np.isnan(n[0, 1]) and np.isfinite(n[1, 1])


def test_default_sets_cover_the_visible():
    for name in (optics.DEFAULT_FILM, optics.DEFAULT_SUBSTRATE):
        lo, hi = optics.load_set(name).range_nm
        assert lo <= 380 and hi >= 780


def test_unknown_name_lists_known_sets():
    with pytest.raises(ValueError, match="Ti_JohnsonChristy1974"):
        optics.optical_constants("Ti_Nonexistent", 550.0)


@pytest.mark.parametrize("wl", [100.0, 900.0, np.inf])
def test_out_of_range_wavelength_is_refused(wl):
    with pytest.raises(ValueError, match="wavelength_nm.*TiO2_Jolivet2023_amorphous"):
        optics.optical_constants("TiO2_Jolivet2023_amorphous", [500.0, wl])


def test_resolve_index_accepts_names_and_numbers():
    wl = np.array([500.0, 600.0])
    np.testing.assert_array_equal(
        optics.resolve_index("Ti_Palm2018", wl), optics.optical_constants("Ti_Palm2018", wl)
    )
    assert optics.resolve_index(2.0 + 1j, wl) == 2.0 + 1j
