"""Property tests (hypothesis) of the colour conversions (microfacet.colour).

The thin-film properties that were here are in tests/optics/test_thinfilm_properties.py.
These belong in tests/colour/ (owned by the colour work: to be moved there by its owner,
split by module); they stay here meanwhile so that nothing is lost.

Only properties that tests/colour/ does not already check (there: XYZ → Lab → XYZ,
integer sRGB round trips (exhaustive), CIEDE2000 symmetry, identity and non-negativity);
here: L* in [0, 100] for physical reflectances (any spectrum and thin-film spectra),
Lab → XYZ → Lab, float sRGB round trips and monotonicity, linear sRGB ↔ XYZ for adapted
illuminants, sRGB ↔ Lab in float, ΔE76 symmetry / identity / triangle inequality, ΔE94
identity and its symmetry when the chromas are equal (it is not symmetric in general), one
colour against an image (broadcasting), empty inputs.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import microfacet.colour as mc
from microfacet.optics.thinfilm import reflectance

FAST = settings(max_examples=60, deadline=None)

theta = st.floats(0.0, 89.99)
thickness = st.floats(0.0, 5000.0)

lab_values = st.tuples(st.floats(0, 100), st.floats(-128, 128), st.floats(-128, 128)).map(
    np.array)


@pytest.mark.slow
@FAST
@given(th=theta, d=thickness)
def test_thin_film_colour_has_lightness_in_0_100(th, d):
    wl = np.arange(380.0, 781.0, 5.0)
    R = reflectance(wl, th, d, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    lab = mc.spectrum_to_lab(R, wl)
    assert np.all(np.isfinite(lab))
    assert -1e-9 <= lab[0] <= 100 + 1e-9


# --------------------------------------------------------------------------- colour


@FAST
@given(arrays(np.float64, (41,), elements=st.floats(0.0, 1.0)),
       st.sampled_from(["D65", "A", "D50"]), st.sampled_from(["2", "10"]))
def test_lightness_of_any_physical_reflectance_is_in_0_100(R, illuminant, observer):
    wl = np.arange(380.0, 781.0, 10.0)
    lab = mc.spectrum_to_lab(R, wl, illuminant=illuminant, observer=observer)
    assert -1e-9 <= lab[0] <= 100 + 1e-9
    # and the perfect reflector's lightness is an upper bound reached only by R = 1
    white = mc.spectrum_to_lab(np.ones_like(R), wl, illuminant=illuminant, observer=observer)
    assert lab[0] <= white[0] + 1e-9


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(lab_values, st.sampled_from(["D65", "A"]))
def test_lab_xyz_lab_round_trip(lab, illuminant):
    back = mc.xyz_to_lab(mc.lab_to_xyz(lab, illuminant=illuminant), illuminant=illuminant)
    np.testing.assert_allclose(back, lab, rtol=0, atol=1e-9)


@FAST
@given(arrays(np.float64, (16,), elements=st.floats(0.0, 1.0)))
def test_srgb_float_round_trips(x):
    enc = mc.srgb_encode(x, dtype=np.float32)
    assert enc.dtype == np.float32 and np.all((enc >= 0) & (enc <= 1))
    np.testing.assert_allclose(mc.srgb_decode(enc), x, rtol=1e-5, atol=2e-7)
    dec = mc.srgb_decode(x.astype(np.float32))
    np.testing.assert_allclose(mc.srgb_encode(dec, dtype=np.float32), x, rtol=1e-5, atol=2e-6)


@FAST
@given(arrays(np.float64, (32,), elements=st.floats(-0.5, 1.5)))
def test_srgb_transfer_is_monotonic(x):
    x = np.sort(x)
    for out in (mc.srgb_encode(x, dtype=np.float32), mc.srgb_encode(x),
                mc.srgb_encode(x, dtype=np.uint16), mc.srgb_decode(x)):
        assert np.all(np.diff(out.astype(np.float64)) >= 0)


@pytest.mark.slow
@FAST
@given(arrays(np.float64, (5, 3), elements=st.floats(0.0, 1.0)),
       st.sampled_from(["D65", "A", "D50", "FL2"]), st.sampled_from(["2", "10"]))
def test_linear_srgb_xyz_round_trip_for_adapted_illuminants(rgb, illuminant, observer):
    xyz = mc.linear_srgb_to_xyz(rgb, illuminant=illuminant, observer=observer)
    back = mc.xyz_to_linear_srgb(xyz, illuminant=illuminant, observer=observer)
    np.testing.assert_allclose(back, rgb, rtol=0, atol=5e-6)
    # white stays white: Y of RGB (1, 1, 1) is 1 whatever the illuminant
    w = mc.linear_srgb_to_xyz(np.ones(3), illuminant=illuminant, observer=observer)
    assert float(w[1]) == pytest.approx(1.0, abs=1e-6)


@pytest.mark.slow
@FAST
@given(arrays(np.float32, (6, 3), elements=st.floats(0.0, 1.0, width=32)),
       st.sampled_from(["D65", "A"]))
def test_srgb_lab_round_trip_in_float(img, illuminant):
    lab = mc.srgb_to_lab(img, illuminant=illuminant)
    assert np.all((lab[..., 0] >= -1e-3) & (lab[..., 0] <= 100 + 1e-3))
    back = mc.lab_to_srgb(lab, illuminant=illuminant, dtype=np.float32)
    np.testing.assert_allclose(back, img, rtol=0, atol=2e-4)


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(lab_values, lab_values, lab_values)
def test_delta_e_76_is_a_metric(x, y, z):
    d = float(mc.delta_e_76(x, y))
    assert d >= 0 and mc.delta_e_76(x, x) == 0
    assert d == float(mc.delta_e_76(y, x))
    assert d <= float(mc.delta_e_76(x, z)) + float(mc.delta_e_76(z, y)) + 1e-9


@settings(max_examples=100, deadline=None)
@given(lab_values, st.floats(0, 100), st.floats(-math.pi, math.pi))
def test_delta_e_94_identity_and_symmetry_at_equal_chroma(x, L2, dh):
    assert mc.delta_e_94(x, x) == 0
    # a second colour of the same chroma (hue rotated, other lightness): SC and SH are
    # then the same whichever is the reference, so the difference is symmetric
    c, s = math.cos(dh), math.sin(dh)
    y = np.array([L2, c * x[1] - s * x[2], s * x[1] + c * x[2]])
    d12, d21 = float(mc.delta_e_94(x, y)), float(mc.delta_e_94(y, x))
    assert d12 >= 0 and d12 == pytest.approx(d21, rel=1e-9, abs=1e-9)


def test_delta_e_94_is_not_symmetric_when_the_chromas_differ():
    # documented: lab1 is the reference. Independent value: the CIE 1994 formula by hand.
    x, y = np.array([50.0, 40.0, 0.0]), np.array([50.0, 10.0, 0.0])
    d12, d21 = float(mc.delta_e_94(x, y)), float(mc.delta_e_94(y, x))
    assert d12 == pytest.approx(30.0 / (1 + 0.045 * 40.0))
    assert d21 == pytest.approx(30.0 / (1 + 0.045 * 10.0))


@pytest.mark.slow
@settings(max_examples=100, deadline=None)
@given(arrays(np.float64, (4, 3), elements=st.floats(-100, 100)),
       arrays(np.float64, (4, 3), elements=st.floats(-100, 100)))
def test_delta_e_2000_and_76_symmetric_on_arrays(a, b):
    a[:, 0] = np.abs(a[:, 0])
    b[:, 0] = np.abs(b[:, 0])
    np.testing.assert_allclose(mc.delta_e_2000(a, b), mc.delta_e_2000(b, a), rtol=0,
                               atol=1e-9)
    np.testing.assert_array_equal(mc.delta_e_76(a, b), mc.delta_e_76(b, a))
    for fn in (mc.delta_e_2000, mc.delta_e_76, mc.delta_e_94):
        np.testing.assert_array_equal(fn(a, a), np.zeros(4))


def test_delta_e_of_empty_arrays_is_empty():
    # the no-pixel case (e.g. every pixel masked) must give an empty result, not an error
    for fn in (mc.delta_e_2000, mc.delta_e_76, mc.delta_e_94):
        for dtype in (np.float32, np.float64):
            out = fn(np.zeros((0, 3), dtype), np.zeros((0, 3), dtype))
            assert out.shape == (0,)
        assert fn(np.zeros((2, 0, 3)), np.zeros(3)).shape == (2, 0)


@pytest.mark.slow
@FAST
@given(arrays(np.float64, (2, 3, 3), elements=st.floats(-100, 100)), lab_values)
def test_one_colour_against_an_image_equals_the_pairwise_differences(img, ref):
    img[..., 0] = np.abs(img[..., 0])
    for fn in (mc.delta_e_2000, mc.delta_e_76, mc.delta_e_94):
        out = fn(img, ref)
        assert out.shape == (2, 3)
        pairwise = [[float(fn(img[i, j], ref)) for j in range(3)] for i in range(2)]
        np.testing.assert_allclose(out, pairwise, rtol=0, atol=1e-12)
        swapped = fn(ref, img)
        pairwise = [[float(fn(ref, img[i, j])) for j in range(3)] for i in range(2)]
        np.testing.assert_allclose(swapped, pairwise, rtol=0, atol=1e-12)
