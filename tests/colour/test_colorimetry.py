"""microfacet.colour.colorimetry: spectral integration (colour-science's) and XYZ ↔ Lab.

The spectral weights and whites are delegated to colour-science, so they are tested by
properties and published values, not against colour-science: the CIE 15:2018 white points,
the perfect reflector at Y = 1 and L* = 100, linearity, convergence between grids, and the
uniform / non-uniform grid conventions agreeing. XYZ ↔ Lab (kept ours) is tested against
the CIE definition: whites, the L* breakpoint, round trips.
"""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from microfacet.colour.colorimetry import (
    lab_to_xyz,
    spectral_weights,
    spectrum_to_lab,
    spectrum_to_xyz,
    white_xyz,
    xyz_to_lab,
)

WL = np.arange(360.0, 831.0)


def _smooth_spectra(rng, n, wl=WL):
    period = rng.uniform(20, 120, (n, 1))
    phase = rng.uniform(0, 2 * np.pi, (n, 1))
    return lambda w=wl: 0.5 + 0.45 * np.sin(w[None, :] / period + phase)


@pytest.mark.slow
def test_importing_the_colour_package_is_light():
    code = (
        "import sys, microfacet.colour, microfacet.colour.colorimetry, microfacet.colour.srgb,"
        " microfacet.colour.table, microfacet.colour.difference; "
        "bad = [m for m in ('colour', 'sklearn', 'matplotlib') if m in sys.modules]; "
        "print(bad)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# ----------------------------------------------------------------------------- whites


@pytest.mark.parametrize("illuminant, observer, xy", [
    # CIE 15:2018 Table 11.3 (white points of the CIE illuminants)
    ("D65", "2", (0.31272, 0.32903)),
    ("D65", "10", (0.31382, 0.33100)),
    ("A", "2", (0.44757, 0.40745)),
    ("A", "10", (0.45117, 0.40594)),
    ("D50", "2", (0.34567, 0.35850)),
    ("D50", "10", (0.34773, 0.35952)),
])
def test_white_points_match_cie_15(illuminant, observer, xy):
    w = white_xyz(illuminant=illuminant, observer=observer)
    assert w[1] == pytest.approx(1.0, abs=1e-12)
    # 5-decimal table; A's table stops at 780 nm (constant beyond), hence 3e-5
    np.testing.assert_allclose(w[:2] / w.sum(), xy, rtol=0, atol=3e-5)


def test_white_is_the_perfect_reflector_on_the_1nm_grid():
    for ill, obs in (("D65", "2"), ("A", "10")):
        white = spectrum_to_xyz(np.ones(WL.size), WL, illuminant=ill, observer=obs)
        np.testing.assert_allclose(white, white_xyz(illuminant=ill, observer=obs), atol=1e-14)


# ----------------------------------------------------------------------------- weights


@pytest.mark.parametrize("step", [1.0, 5.0, 10.0, 20.0])
def test_weights_normalise_the_perfect_reflector_to_y_1(step):
    wl = np.arange(380.0, 780.0 + step / 2, step)
    W = spectral_weights(wl)
    assert W.shape == (wl.size, 3) and W.dtype == np.float64 and not W.flags.writeable
    assert W[:, 1].sum() == pytest.approx(1.0, abs=1e-12)
    assert (W > -1e-20).all()  # the CIE table's z-bar has -3e-22 at 651 nm
    np.testing.assert_allclose(spectrum_to_lab(np.ones(wl.size), wl), [100, 0, 0], atol=1e-10)
    assert spectral_weights(wl) is W  # cached


def test_uniform_and_non_uniform_grids_use_the_same_summation():
    # A uniform grid goes through colour-science, a non-uniform one through our own sum;
    # moving one sample by 1e-6 nm must change the weights by ~1e-6 of a weight, not by
    # a convention (e.g. half weights at the ends would move the end weights by 50 %).
    wl = np.arange(380.0, 781.0, 10.0)
    nudged = wl.copy()
    nudged[17] += 1e-6
    a, b = spectral_weights(wl), spectral_weights(nudged)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-7 * np.abs(a).max())


def test_weights_do_not_depend_on_colour_sciences_domain_range_scale(colour_science):
    with colour_science.domain_range_scale("1"):
        w = white_xyz(illuminant="D55")  # not computed (cached) before in the reference scale
    assert w[1] == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(w[:2] / w.sum(), (0.33242, 0.34743), atol=3e-5)  # CIE 15


@pytest.mark.parametrize("wl", [
    np.linspace(380.0, 780.0, 4001),  # 0.1 nm: colour-science does not see it as uniform
    np.arange(381.0, 780.0, 3.0) + 1e-7,
    np.linspace(380.0, 780.0, 8),  # a step of 400/7 nm
])
def test_awkward_grids_integrate_silently_and_consistently(wl):
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        W = spectral_weights(wl)
    assert W[:, 1].sum() == pytest.approx(1.0, abs=1e-12)
    if wl.size > 100:  # fine grids integrate like the 1 nm grid
        spectra = _smooth_spectra(np.random.default_rng(1), 4)
        fine = np.arange(380.0, 781.0)
        np.testing.assert_allclose(spectrum_to_xyz(spectra(wl), wl),
                                   spectrum_to_xyz(spectra(fine), fine), atol=3e-4)


def test_non_uniform_grid_integrates_like_the_1nm_grid():
    wl = np.concatenate([np.arange(380.0, 500.0, 2.0), np.arange(500.0, 781.0, 10.0)])
    W = spectral_weights(wl)
    assert W[:, 1].sum() == pytest.approx(1.0, abs=1e-12)
    spectra = _smooth_spectra(np.random.default_rng(2), 6)
    fine = np.arange(380.0, 781.0)
    # the 10 nm part sums to within ~2e-3 of the 1 nm integral (measured 2.2e-3)
    np.testing.assert_allclose(spectrum_to_xyz(spectra(wl), wl),
                               spectrum_to_xyz(spectra(fine), fine), atol=3e-3)
    np.testing.assert_allclose(spectrum_to_lab(np.ones(wl.size), wl), [100, 0, 0], atol=1e-10)


@pytest.mark.parametrize("illuminant, observer", [("D65", "2"), ("A", "10")])
def test_integration_converges_with_the_spectral_step(illuminant, observer):
    spectra = _smooth_spectra(np.random.default_rng(11), 8)
    kw = dict(illuminant=illuminant, observer=observer)
    ref = spectrum_to_xyz(spectra(WL), WL, **kw)
    # measured on such spectra: 2.2e-4 at 5 nm, 6.9e-4 at 10 nm, 7.8e-3 at 20 nm
    for step, tol in ((5.0, 3e-4), (10.0, 1e-3), (20.0, 1e-2)):
        wl = np.arange(360.0, 831.0, step)
        np.testing.assert_allclose(spectrum_to_xyz(spectra(wl), wl, **kw), ref, atol=tol)


def test_integration_is_linear_and_scales_the_white():
    rng = np.random.default_rng(5)
    spectra = _smooth_spectra(rng, 2)(WL)
    x = spectrum_to_xyz(spectra, WL)
    np.testing.assert_allclose(spectrum_to_xyz(0.3 * spectra[0] + 0.7 * spectra[1], WL),
                               0.3 * x[0] + 0.7 * x[1], atol=1e-14)
    np.testing.assert_allclose(spectrum_to_xyz(np.full(WL.size, 0.25), WL),
                               0.25 * white_xyz(), atol=1e-14)


def test_a_narrow_band_has_the_chromaticity_of_the_spectrum_locus():
    # a reflectance that is 1 at 520 nm only: its XYZ is proportional to cmf(520)
    r = (WL == 520.0).astype(float)
    xyz = spectrum_to_xyz(r, WL)
    # CIE 1931 spectrum locus at 520 nm: x = 0.07430, y = 0.83380
    np.testing.assert_allclose(xyz[:2] / xyz.sum(), [0.07430, 0.83380], atol=5e-5)


def test_spectrum_to_xyz_shapes_dtype_nan():
    rng = np.random.default_rng(2)
    spectra = _smooth_spectra(rng, 24)(WL).reshape(2, 3, 4, WL.size)
    spectra[1, 2, 3, 100] = np.nan
    xyz = spectrum_to_xyz(spectra, WL)
    assert xyz.shape == (2, 3, 4, 3) and xyz.dtype == np.float64
    assert np.isnan(xyz[1, 2, 3]).all() and np.isnan(xyz).sum() == 3
    xyz32 = spectrum_to_xyz(spectra.astype(np.float32), WL)
    assert xyz32.dtype == np.float32
    np.testing.assert_allclose(xyz32, xyz, atol=1e-5)


def test_spectral_bad_input():
    with pytest.raises(ValueError, match="wavelength_nm"):
        spectral_weights([500.0, 400.0])
    with pytest.raises(ValueError, match="wavelength_nm"):
        spectral_weights([350.0, 400.0])
    with pytest.raises(ValueError, match="wavelength_nm"):
        spectral_weights([500.0])
    with pytest.raises(ValueError, match="reflectance"):
        spectrum_to_xyz(np.ones((2, 5)), WL)
    with pytest.raises(ValueError, match="reflectance"):
        spectrum_to_xyz(np.array(["a"] * WL.size), WL)
    with pytest.raises(ValueError, match="D65"):
        spectral_weights(WL, illuminant="nope")
    with pytest.raises(ValueError, match="observer"):
        white_xyz(observer="5")


# ----------------------------------------------------------------------------- Lab


def test_lab_of_the_white_and_of_neutrals():
    np.testing.assert_allclose(xyz_to_lab(white_xyz()), [100, 0, 0], atol=1e-12)
    w_a = white_xyz(illuminant="A")
    np.testing.assert_allclose(xyz_to_lab(0.5 * w_a, illuminant="A")[1:], 0, atol=1e-12)
    # L* = 116 f(Y) - 16: Y = 0.18419 is L* = 50; the breakpoint Y = (6/29)^3 is L* = 8
    assert xyz_to_lab(((50 + 16) / 116) ** 3 * white_xyz())[0] == pytest.approx(50, abs=1e-12)
    assert xyz_to_lab((6 / 29) ** 3 * white_xyz())[0] == pytest.approx(8, abs=1e-12)


def test_lab_is_continuous_at_the_cie_breakpoint():
    eps = 216 / 24389
    y = np.array([eps * (1 - 1e-12), eps * (1 + 1e-12)])
    L = xyz_to_lab(y[:, None] * white_xyz())[:, 0]
    assert abs(L[1] - L[0]) < 1e-8
    # below the breakpoint L* is linear in Y: kappa * Y
    assert xyz_to_lab(0.001 * white_xyz())[0] == pytest.approx(24389 / 27 * 0.001, abs=1e-12)


def test_lab_of_a_known_colour():
    # a* > 0 when X/Xn > Y/Yn; exact from the CIE formula with f = cube root
    w = white_xyz()
    xyz = np.array([0.512, 0.343, 0.125]) * w  # ratios with exact cube roots 0.8, 0.7, 0.5
    np.testing.assert_allclose(xyz_to_lab(xyz), [116 * 0.7 - 16, 500 * 0.1, 200 * 0.2],
                               atol=1e-12)


def test_white_scale_does_not_matter():
    rng = np.random.default_rng(3)
    xyz = rng.uniform(0, 1, (50, 3))
    w = white_xyz(illuminant="D50")
    np.testing.assert_allclose(xyz_to_lab(100 * xyz, white=100 * w), xyz_to_lab(xyz, white=w),
                               atol=1e-12)
    np.testing.assert_allclose(xyz_to_lab(xyz, white=w), xyz_to_lab(xyz, illuminant="D50"),
                               atol=1e-12)


@pytest.mark.slow
@settings(max_examples=200, deadline=None)
@given(arrays(np.float64, (3,), elements=st.floats(0, 2)), st.sampled_from(["D65", "A"]))
def test_xyz_lab_round_trip(xyz, illuminant):
    back = lab_to_xyz(xyz_to_lab(xyz, illuminant=illuminant), illuminant=illuminant)
    np.testing.assert_allclose(back, xyz, atol=1e-12)


def test_lab_round_trip_float32_stays_float32():
    rng = np.random.default_rng(8)
    xyz = rng.uniform(0, 1, (1000, 3)).astype(np.float32)
    lab = xyz_to_lab(xyz)
    assert lab.dtype == np.float32
    back = lab_to_xyz(lab)
    assert back.dtype == np.float32
    np.testing.assert_allclose(back, xyz, atol=2e-6)
    np.testing.assert_allclose(lab, xyz_to_lab(xyz.astype(np.float64)), atol=2e-4)


def test_lab_shapes_nan_and_bad_input():
    rng = np.random.default_rng(8)
    xyz = rng.uniform(0, 1, (2, 3, 4, 3))
    xyz[0, 0, 0, 0] = np.nan
    lab = xyz_to_lab(xyz)
    assert lab.shape == xyz.shape and lab.dtype == np.float64
    # X feeds a* only; L* and b* of that pixel stay finite
    assert np.isnan(lab[0, 0, 0, 1]) and not np.isnan(lab[0, 0, 0, [0, 2]]).any()
    assert np.isnan(lab).sum() == 1
    assert np.isnan(lab_to_xyz([np.nan, 0, 0])).all()
    with pytest.raises(ValueError, match="xyz"):
        xyz_to_lab(np.ones((4, 4)))
    with pytest.raises(ValueError, match="lab"):
        lab_to_xyz(np.ones(2))
    with pytest.raises(ValueError, match="white"):
        xyz_to_lab(np.ones(3), white=[1.0, 0.0, 1.0])


def test_spectrum_to_lab_uses_the_white_of_its_grid():
    wl = np.arange(400.0, 701.0, 10.0)  # a short grid: its white differs from white_xyz()
    assert not np.allclose(spectral_weights(wl).sum(0), white_xyz(), atol=1e-3)
    np.testing.assert_allclose(spectrum_to_lab(np.ones(wl.size), wl), [100, 0, 0], atol=1e-10)
    grey = spectrum_to_lab(np.full(wl.size, 0.18), wl, illuminant="A", observer="10")
    np.testing.assert_allclose(grey[1:], 0, atol=1e-10)
