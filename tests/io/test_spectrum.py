"""Measured spectra (microfacet.io.spectrum): CSV reading, percent values, errors naming the
file and the line."""

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.spectrum import read_spectrum_csv
from microfacet.optics.thinfilm import reflectance

FILM, SUB = "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974"
WL = np.arange(400.0, 751.0, 5.0)


def test_csv_round_trip_and_percent(tmp_path):
    p = tmp_path / "s.csv"
    R = reflectance(WL, 0.0, 70.0, FILM, SUB)
    p.write_text("wavelength_nm,reflectance\n" + "".join(f"{w},{100 * r}\n" for w, r in zip(WL, R)))
    wl, R2 = read_spectrum_csv(p)
    np.testing.assert_array_equal(wl, WL)
    np.testing.assert_allclose(R2, R, rtol=1e-9)  # percent values read as fractions


@pytest.mark.parametrize("text, msg", [
    ("wavelength,reflectance\n400,0.1\n", "missing column 'wavelength_nm'"),
    ("wavelength_nm,reflectance\n400,0.1\n500,abc\n600,0.2\n", "line 3"),
    ("wavelength_nm,reflectance\n400,0.1\n", "at least 3"),
])
def test_bad_csv_names_file_and_line(tmp_path, text, msg):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=msg) as e:
        read_spectrum_csv(p)
    assert "bad.csv" in str(e.value)
