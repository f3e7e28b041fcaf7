"""Imaging effects of synthetic stacks (microfacet.forward.imaging): tilt-dependent
brightness, vignetting, white balance, drift."""

import math

import numpy as np
import pytest

from microfacet.forward.imaging import (
    apply_white_balance,
    drift_offsets_px,
    pupil_fraction,
    pupil_limit_deg,
    shift_image,
    vignetting_factor,
)


@pytest.mark.parametrize("fill", [0.2, 0.5, 1.0])
def test_pupil_fraction_falls_monotonically_from_one_to_zero(fill):
    th = np.linspace(0, 89, 2000)
    f = pupil_fraction(th, numerical_aperture=0.8, fill=fill)
    assert f[0] == pytest.approx(1.0)
    assert np.all(np.diff(f) <= 0) and f[-1] == 0
    lim = pupil_limit_deg(numerical_aperture=0.8, fill=fill)
    # all light is lost by (asin NA + asin(fill NA))/2, and not before (asin NA)/2
    assert math.degrees(math.asin(0.8)) / 2 < lim
    assert lim <= (math.degrees(math.asin(0.8)) + math.degrees(math.asin(fill * 0.8))) / 2 + 0.3
    assert np.all(f[th >= lim] == 0) and np.all(f[th < lim - 0.2] > 0)


def test_pupil_fraction_tends_to_the_hard_cut_for_axial_light():
    th = np.array([10.0, 20.0, 25.5, 27.5, 35.0])
    hard = pupil_fraction(th, numerical_aperture=0.8, fill=0.0)
    assert hard.tolist() == [1, 1, 1, 0, 0]
    narrow = pupil_fraction(th, numerical_aperture=0.8, fill=0.02)
    np.testing.assert_allclose(narrow, hard, atol=1e-6)


def test_pupil_fraction_is_the_overlap_of_two_discs_for_a_small_na():
    """Paraxially a tilt θ moves the reflected cone by sin 2θ in direction sines: the
    collected fraction is the overlap of two discs of radius NA (lens area formula)."""
    na = 0.1
    th = np.array([0.5, 1.0, 2.0, 2.8])
    q = np.sin(np.deg2rad(2 * th)) / (2 * na)
    lens = 2 / np.pi * (np.arccos(q) - q * np.sqrt(1 - q * q))
    f = pupil_fraction(th, numerical_aperture=na, fill=1.0)
    np.testing.assert_allclose(f, lens, atol=0.02)


@pytest.mark.parametrize("kw, name", [(dict(numerical_aperture=1.0, fill=0.5),
                                       "numerical_aperture"),
                                      (dict(numerical_aperture=0.5, fill=1.5), "fill")])
def test_pupil_fraction_bad_arguments(kw, name):
    with pytest.raises(ValueError, match=name):
        pupil_fraction([1.0], **kw)


def test_vignetting_factor_is_radial_with_the_corner_loss():
    v = vignetting_factor((40, 60), corner_loss=0.25)
    assert v.dtype == np.float32
    assert v[0, 0] == pytest.approx(0.75) and v[-1, 0] == pytest.approx(0.75)
    assert v[0, -1] == pytest.approx(0.75) and v[-1, -1] == pytest.approx(0.75)
    assert v.max() <= 1.0 and v[19:21, 29:31].min() > 0.999
    np.testing.assert_allclose(v, v[::-1, ::-1])
    assert vignetting_factor((8, 8), corner_loss=0.0).min() == 1.0
    with pytest.raises(ValueError, match="corner_loss"):
        vignetting_factor((8, 8), corner_loss=1.0)


def test_white_balance_gains_scale_channels():
    rgb = np.random.default_rng(0).random((5, 7, 3), dtype=np.float32)
    out = apply_white_balance(rgb, (0.9, 1.0, 1.2))
    np.testing.assert_allclose(out / rgb, np.broadcast_to([0.9, 1.0, 1.2], rgb.shape),
                               rtol=1e-6)
    with pytest.raises(ValueError, match="gains"):
        apply_white_balance(rgb, (1.0, -1.0, 1.0))


def test_drift_is_a_zero_mean_random_walk():
    d = drift_offsets_px(np.random.default_rng(1), 400, step_px=0.2)
    assert np.allclose(d.mean(axis=0), 0)
    steps = np.diff(d, axis=0)
    assert steps.std() == pytest.approx(0.2, rel=0.1)
    assert np.all(drift_offsets_px(np.random.default_rng(1), 5, step_px=0.0) == 0)


def test_shift_image_moves_content_by_the_offset():
    img = np.zeros((32, 32, 3), np.float32)
    img[10, 12] = 1.0
    out = shift_image(img, 3.0, -2.0)
    assert np.unravel_index(out[..., 0].argmax(), (32, 32)) == (13, 10)
    half = shift_image(img, 0.5, 0.0)[..., 0]
    assert half[10, 12] == pytest.approx(half[11, 12], abs=1e-6) and half[10, 12] > 0.4
