"""Fixtures of the microfacet.colour tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

SHARMA_CSV = Path(__file__).resolve().parents[2] / "fixtures" / "ciede2000_sharma2005.csv"


@pytest.fixture(scope="session")
def sharma():
    """Sharma, Wu & Dalal (2005) Table 1: ``(lab1, lab2, dE00)``, 34 pairs."""
    data = np.loadtxt(SHARMA_CSV, delimiter=",", skiprows=1)
    assert data.shape == (34, 8)
    return data[:, 1:4], data[:, 4:7], data[:, 7]


@pytest.fixture(scope="session")
def colour_science():
    """colour-science, for independent reference computations (skip if missing)."""
    return pytest.importorskip("colour")


@pytest.fixture
def random_lab():
    """``random_lab(rng, n)``: uniform Lab in L 0-100, a, b within ±128."""
    def draw(rng, n):
        return np.column_stack(
            [rng.uniform(0, 100, n), rng.uniform(-128, 128, n), rng.uniform(-128, 128, n)]
        )
    return draw
