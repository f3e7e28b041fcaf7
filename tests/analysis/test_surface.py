"""The surface stages (microfacet.analysis.surface): an instrument's height map is used as
measured — its slopes through ``analyse_stack`` are the central differences of the file's
heights — while a height from focus has its slopes smoothed by ``focus.slope_sigma_px``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import analyse_stack
from microfacet.analysis.surface import surface_normals
from microfacet.io.stack import read_stack

X3P = Path(__file__).resolve().parents[2] / "fixtures" / "exports" / "nd-x3p"


def _rms_slope(normals):
    n = np.asarray(normals, np.float64)
    s = np.hypot(n[..., 0], n[..., 1]) / n[..., 2]
    return float(np.sqrt(np.mean(s[1:-1, 1:-1] ** 2)))


def _rms_central(h, py, px):
    gy, gx = np.gradient(np.asarray(h, np.float64), py, px)
    return float(np.sqrt(np.mean(gx[1:-1, 1:-1] ** 2 + gy[1:-1, 1:-1] ** 2)))


def test_unsmoothed_normals_are_the_central_differences_on_non_square_pixels(focus_result):
    """A rough analytic surface on 0.31 × 0.13 µm pixels: without smoothing the RMS slope is
    that of central differences with each axis' own spacing; a 1-px σ lowers it, more along
    the axis whose pixels are larger (σ in px is not isotropic in µm)."""
    y, x = np.mgrid[0:96, 0:128]
    py, px = 0.31, 0.13
    h = 0.05 * np.sin(y * py * 2.1) * np.cos(x * px * 3.7) + 0.02 * np.sin(x * px * 9.0)
    ref = _rms_central(h, py, px)
    got = _rms_slope(surface_normals(focus_result(h), pixel_size_um=(py, px)).normals)
    assert got == pytest.approx(ref, rel=1e-4)
    smoothed = _rms_slope(surface_normals(focus_result(h), pixel_size_um=(py, px),
                                          smooth_sigma_px=1.0).normals)
    assert smoothed < 0.97 * ref


@pytest.mark.slow
def test_an_instrument_map_through_the_analysis_keeps_its_rms_slope():
    """The x3p fixture through ``analyse_stack``: RMS slope within 1 % of the file's central
    differences (the 1-px smoothing once took 30 % off), and summary records σ = 0."""
    st = read_stack(X3P)
    h = st.read_export_height()
    ref = _rms_central(h, st.pixel_size_um, st.pixel_size_um)
    r = analyse_stack(X3P)
    assert _rms_slope(r.surface.normals) == pytest.approx(ref, rel=0.01)
    assert not r.scene.from_focus
