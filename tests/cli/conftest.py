"""Fixtures of the command-line tests."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.optics.thinfilm import reflectance


@pytest.fixture(scope="session")
def spectrum_csv():
    """``spectrum_csv(path, d, angle=0.0)``: write the model spectrum of a ``d`` nm film at
    incidence ``angle`` (400-750 nm, 5 nm steps) as a CSV at ``path``; returns ``path``."""
    def write(path, d, angle=0.0):
        wl = np.arange(400.0, 751.0, 5.0)
        R = reflectance(wl, angle, d, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
        path.write_text("wavelength_nm,reflectance\n"
                        + "".join(f"{w},{r}\n" for w, r in zip(wl, R)))
        return path
    return write
