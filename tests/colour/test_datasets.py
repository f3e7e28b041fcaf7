"""microfacet.colour.datasets: CIE tables (colour-science's data) and name validation.

References: the CIE 1931 2° CMF table, CIE illuminant A's defining Planck formula
(CIE 15:2018 §3.1), the D65 table (CIE S 014-2).
"""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.colour.datasets import (
    CMF_RANGE_NM,
    OBSERVERS,
    cmfs,
    illuminant_key,
    illuminant_sd,
    known_illuminants,
    observer_name,
)


def test_cmfs_against_the_cie_1931_table():
    # CIE 1931 2° standard observer, 1 nm table
    got = cmfs([450.0, 550.0, 600.0])
    expected = [[0.336200, 0.038000, 1.772110],
                [0.4334499, 0.9949501, 0.0087500],
                [1.062200, 0.631000, 0.000800]]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-7)
    assert got.shape == (3, 3) and got.dtype == np.float64
    # ybar is the photopic luminosity function, 1 at 555 nm
    assert cmfs([555.0])[0, 1] == pytest.approx(1.0, abs=1e-6)


def test_cmfs_interpolate_linearly_between_1nm_samples():
    a, b, mid = cmfs([555.0, 556.0, 555.5])
    np.testing.assert_allclose(mid, 0.5 * (a + b), rtol=0, atol=1e-15)


def test_ten_degree_observer_differs_and_is_selected_by_name():
    two, ten = cmfs([600.0]), cmfs([600.0], observer="10")
    assert not np.allclose(two, ten, atol=1e-3)
    np.testing.assert_array_equal(ten, cmfs([600.0], observer=OBSERVERS["10"]))


def test_illuminant_a_follows_its_defining_planck_formula():
    # CIE A: 100 (560/λ)^5 (e^(c2 / (2848 × 560)) - 1) / (e^(c2 / (2848 λ)) - 1), c2 = 1.435e7
    def planck_a(wl):
        c2 = 1.435e7
        return 100 * (560 / wl) ** 5 * np.expm1(c2 / (2848 * 560)) / np.expm1(c2 / (2848 * wl))

    wl = np.arange(380.0, 781.0, 5.0)  # the tabulated range
    np.testing.assert_allclose(illuminant_sd(wl, illuminant="A"), planck_a(wl), rtol=2e-5)
    # between the 5 nm samples: linear interpolation, as CIE 15 prescribes for the tables
    off = np.arange(382.3, 779.0, 7.1)
    np.testing.assert_allclose(illuminant_sd(off, illuminant="A"),
                               np.interp(off, wl, planck_a(wl)), rtol=2e-5)


def test_d65_table_values():
    np.testing.assert_allclose(illuminant_sd([400.0, 500.0, 560.0, 700.0]),
                               [82.7549, 109.354, 100.0, 71.6091], rtol=0, atol=1e-9)


def test_illuminant_names_are_validated_case_insensitively():
    assert {"D65", "D50", "A"} <= set(known_illuminants())
    assert illuminant_key("d65") == "D65" and illuminant_key("a") == "A"
    with pytest.raises(ValueError, match="illuminant 'nope' is unknown.*D65"):
        illuminant_key("nope")
    with pytest.raises(ValueError, match="illuminant"):
        illuminant_sd([500.0], illuminant=65)


def test_observer_names():
    assert observer_name("2") == observer_name(2) == "CIE 1931 2 Degree Standard Observer"
    assert observer_name("10") == "CIE 1964 10 Degree Standard Observer"
    with pytest.raises(ValueError, match="observer"):
        observer_name("5")
    with pytest.raises(ValueError, match="observer"):
        cmfs([500.0], observer="5")


def test_wavelengths_are_validated():
    lo, hi = CMF_RANGE_NM
    cmfs([lo, hi])
    for bad in ([lo - 1.0, 500.0], [500.0, hi + 1.0], [[500.0]], [], [np.nan]):
        with pytest.raises(ValueError, match="wavelength_nm"):
            cmfs(bad)
    with pytest.raises(ValueError, match="wavelength_nm"):
        illuminant_sd([100.0])
