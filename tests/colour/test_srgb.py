"""microfacet.colour.srgb: RGB ↔ XYZ, image ↔ Lab, model colours as sRGB (kept ours).

References: IEC 61966-2-1:1999 (the matrix and its white), the published CIELAB values
of the sRGB primaries (D65), and the defining property of the white-balanced image path:
RGB white is exactly L* = 100, a* = b* = 0 for every illuminant and observer.
"""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.colour.colorimetry import spectral_weights, white_xyz
from microfacet.colour.srgb import (
    SRGB_TO_XYZ,
    SRGB_WHITE_XYZ,
    XYZ_TO_SRGB,
    colours_from_spectra,
    image_white_xyz,
    lab_to_srgb,
    linear_srgb_to_xyz,
    model_xyz_to_linear_srgb,
    srgb_to_lab,
    xyz_to_linear_srgb,
)

ILLUMINANTS = [("D65", "2"), ("A", "2"), ("D50", "10"), ("FL2", "2")]


def test_matrix_is_the_iec_one():
    np.testing.assert_array_equal(SRGB_TO_XYZ, [[0.4124, 0.3576, 0.1805],
                                                [0.2126, 0.7152, 0.0722],
                                                [0.0193, 0.1192, 0.9505]])
    np.testing.assert_allclose(SRGB_WHITE_XYZ, [0.9505, 1.0, 1.0890], atol=1e-15)
    np.testing.assert_allclose(XYZ_TO_SRGB @ SRGB_TO_XYZ, np.eye(3), atol=1e-15)
    assert image_white_xyz().tolist() == [0.9505, 1.0, 1.089]


@pytest.mark.parametrize("illuminant, observer", ILLUMINANTS)
def test_rgb_white_is_the_illuminant_white(illuminant, observer):
    kw = dict(illuminant=illuminant, observer=observer)
    white = image_white_xyz(**kw)
    if illuminant != "D65":
        np.testing.assert_allclose(white, white_xyz(**kw), atol=1e-15)
    xyz = linear_srgb_to_xyz(np.ones(3), **kw)
    assert xyz.dtype == np.float32
    np.testing.assert_allclose(xyz, white, atol=1e-6)
    np.testing.assert_allclose(xyz_to_linear_srgb(white, **kw), 1.0, atol=1e-6)


def test_d65_primaries_are_the_matrix_columns():
    np.testing.assert_allclose(linear_srgb_to_xyz(np.eye(3)), SRGB_TO_XYZ.T, atol=1e-7)


@pytest.mark.slow
def test_linear_rgb_xyz_round_trip_and_shapes():
    rgb = np.random.default_rng(6).uniform(0, 1, (4, 5, 3))
    for ill in ("D65", "A"):
        xyz = linear_srgb_to_xyz(rgb, illuminant=ill)
        assert xyz.shape == rgb.shape and xyz.dtype == np.float32
        np.testing.assert_allclose(xyz_to_linear_srgb(xyz, illuminant=ill), rgb, atol=1e-6)
    xyz = linear_srgb_to_xyz(rgb.astype(np.float32))
    assert xyz.dtype == np.float32


@pytest.mark.parametrize("rgb, lab", [
    # CIELAB (D65) of the sRGB primaries, as published (e.g. Lindbloom's calculator)
    ([255, 0, 0], [53.24, 80.09, 67.20]),
    ([0, 255, 0], [87.73, -86.18, 83.18]),
    ([0, 0, 255], [32.30, 79.19, -107.86]),
    # sRGB 119 is the L* = 50 grey
    ([119, 119, 119], [50.03, 0.0, 0.0]),
])
def test_published_lab_of_srgb_colours(rgb, lab):
    # the IEC matrix's 4 decimals move these by up to 0.02 from the exact-matrix values
    np.testing.assert_allclose(srgb_to_lab(np.array(rgb, np.uint8)), lab, atol=0.03)


@pytest.mark.parametrize("illuminant, observer", ILLUMINANTS)
def test_white_and_greys_are_neutral_under_every_illuminant(illuminant, observer):
    kw = dict(illuminant=illuminant, observer=observer)
    np.testing.assert_allclose(srgb_to_lab(np.full(3, 255, np.uint8), **kw), [100, 0, 0],
                               atol=1e-4)
    greys = srgb_to_lab(np.repeat(np.arange(0, 256, 17, dtype=np.uint8)[:, None], 3, 1), **kw)
    np.testing.assert_allclose(greys[:, 1:], 0, atol=1e-4)
    assert np.all(np.diff(greys[:, 0]) > 0)


@pytest.mark.parametrize("illuminant", ["D65", "A", "D50"])
def test_srgb_lab_round_trip_is_exact_in_8_bits(illuminant):
    img = np.random.default_rng(9).integers(0, 256, (2, 3, 40, 3), dtype=np.uint8)
    lab = srgb_to_lab(img, illuminant=illuminant)
    assert lab.shape == img.shape and lab.dtype == np.float32
    assert np.array_equal(lab_to_srgb(lab, illuminant=illuminant), img)
    f = lab_to_srgb(lab, illuminant=illuminant, dtype=np.float32)
    np.testing.assert_allclose(f * 255, img, atol=2e-3)


def test_out_of_gamut_lab_is_clipped():
    assert lab_to_srgb(np.array([100.0, 0.0, 0.0])).tolist() == [255, 255, 255]
    assert lab_to_srgb(np.array([120.0, 0.0, 0.0])).tolist() == [255, 255, 255]
    assert lab_to_srgb(np.array([50.0, 150.0, 0.0]))[1] == 0


def test_nan_propagates_to_float_and_zero_to_integers():
    lab = srgb_to_lab(np.array([[np.nan, 0.5, 0.5], [0.5, 0.5, 0.5]]))
    assert lab.dtype == np.float32 and np.isnan(lab[0]).any() and not np.isnan(lab[1]).any()
    assert lab_to_srgb(np.array([[np.nan, 0.0, 0.0]])).tolist() == [[0, 0, 0]]


def test_model_white_maps_to_rgb_white():
    for wl in (np.arange(380.0, 781.0, 10.0), np.arange(400.0, 701.0, 20.0)):
        w = spectral_weights(wl).sum(axis=0)
        np.testing.assert_allclose(model_xyz_to_linear_srgb(w, white=w), 1.0, atol=1e-6)
        np.testing.assert_allclose(model_xyz_to_linear_srgb(0.2 * w, white=w), 0.2, atol=1e-6)
        # another illuminant: still the perfect reflector -> RGB white
        wa = spectral_weights(wl, illuminant="A").sum(axis=0)
        np.testing.assert_allclose(model_xyz_to_linear_srgb(wa, white=wa, illuminant="A"), 1.0,
                                   atol=1e-6)
    with pytest.raises(ValueError, match="white"):
        model_xyz_to_linear_srgb(np.ones(3), white=[1.0, 0.0, 1.0])


def test_colours_from_spectra():
    wl = np.arange(380.0, 781.0, 10.0)
    R = np.stack([np.ones(wl.size), np.full(wl.size, 0.18), (wl > 600).astype(float)])
    xyz, lab, rgb, white = colours_from_spectra(R, wl)
    np.testing.assert_allclose(white, spectral_weights(wl).sum(axis=0))
    np.testing.assert_allclose(xyz[0], white)
    np.testing.assert_allclose(lab[0], [100, 0, 0], atol=1e-4)
    np.testing.assert_allclose(lab[1, 1:], 0, atol=1e-4)
    assert lab.dtype == np.float32 and rgb.dtype == np.uint8
    assert rgb[0].tolist() == [255, 255, 255] and rgb[1].tolist() == [118, 118, 118]
    assert rgb[2, 0] > 200 and rgb[2, 2] < 50  # long-pass reflector: red
    xyz2, *_ = colours_from_spectra(R, wl, exposure=0.5)
    np.testing.assert_allclose(xyz2, 0.5 * xyz)
    with pytest.raises(ValueError, match="exposure"):
        colours_from_spectra(R, wl, exposure=0)
    with pytest.raises(ValueError, match="spectra"):
        colours_from_spectra(R[:, :5], wl)


def test_bad_input():
    with pytest.raises(ValueError, match="image"):
        srgb_to_lab(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="rgb"):
        linear_srgb_to_xyz(np.zeros((3, 2)))
    with pytest.raises(ValueError, match="xyz"):
        xyz_to_linear_srgb(np.zeros(4))
    with pytest.raises(ValueError, match="illuminant"):
        srgb_to_lab(np.zeros(3, np.uint8), illuminant="nope")
