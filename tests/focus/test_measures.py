"""Focus measures (microfacet.focus.measures): sharper is larger, flat is zero, RGB is its
grey."""

import cv2
import numpy as np
import pytest

from microfacet.focus.measures import (
    focus_measure,
    focus_measures,
    measure_spread_px,
    noise_shape,
)


@pytest.mark.parametrize("op", ["tenengrad", "sml", "glv"])
def test_focus_measure_decreases_with_blur(op):
    rng = np.random.default_rng(0)
    tex = rng.random((64, 64)).astype(np.float32)
    vals = [focus_measure(cv2.GaussianBlur(tex, (0, 0), s), operator=op)[8:-8, 8:-8].mean()
            for s in (0.5, 1.0, 2.0, 4.0)]
    assert all(a > b for a, b in zip(vals, vals[1:]))
    assert focus_measure(np.full((16, 16), 0.3, np.float32), operator=op).max() < 1e-6
    rgb = np.repeat(tex[..., None], 3, axis=2)
    np.testing.assert_allclose(focus_measure(rgb, operator=op), focus_measure(tex, operator=op),
                               rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("op", ["tenengrad", "sml", "glv"])
def test_rgb_colour_is_the_sum_of_the_channels(op):
    """colour="rgb": the measure of each channel on its own, summed."""
    rng = np.random.default_rng(1)
    img = cv2.GaussianBlur(rng.random((48, 40, 3)).astype(np.float32), (0, 0), 0.8)
    ref = sum(focus_measure(np.ascontiguousarray(img[..., c]), operator=op)
              for c in range(3))
    np.testing.assert_allclose(focus_measure(img, operator=op, colour="rgb"), ref,
                               rtol=1e-4, atol=1e-7)


def test_rgb_colour_sees_isoluminant_texture():
    """Texture along a zero-luma colour axis: luma sees (almost) nothing, rgb sees it."""
    rng = np.random.default_rng(2)
    f = cv2.GaussianBlur(rng.standard_normal((64, 64)).astype(np.float32), (0, 0), 0.8)
    axis = np.array([1.0, -0.509, 0.0], np.float32)       # 0.299 − 0.587·0.509 ≈ 0
    img = 0.5 + 0.05 * f[..., None] * axis
    luma = focus_measure(img)[8:-8, 8:-8].mean()
    rgb = focus_measure(img, colour="rgb")[8:-8, 8:-8].mean()
    assert luma < 1e-4 * rgb
    with pytest.raises(ValueError):
        focus_measure(img, colour="hsv")


@pytest.mark.parametrize("op", ["tenengrad", "sml", "glv"])
@pytest.mark.parametrize("px", [11, 15, 21])
def test_downsampled_window_matches_full_grid(op, px):
    """A window evaluated on the grid downsampled by 2 equals the full-grid measure at the
    even pixels within a few per cent (windows ≥ 11 px)."""
    rng = np.random.default_rng(px)
    tex = cv2.GaussianBlur(rng.random((128, 128)).astype(np.float32), (0, 0), 1.0)
    tex *= 0.5 + np.linspace(0, 1, 128, dtype=np.float32)[None]    # varying contrast
    full, half = focus_measures(tex, [(px, "gaussian", 1), (px, "gaussian", 2)], operator=op)
    assert half.shape == (64, 64)
    ref = full[::2, ::2][8:-8, 8:-8]
    rel = np.abs(half[8:-8, 8:-8] - ref) / ref
    assert np.median(rel) < 0.03 and np.percentile(rel, 99) < 0.12, op


def test_noise_shape_of_box_variance_is_chi_square():
    """GLV over a box of n pixels of white Gaussian noise is σ²χ²(n−1)/n: Gamma shape
    (n−1)/2 = 24 for a 7×7 box."""
    k = noise_shape(operator="glv", window_px=7, window="box", downsample=1, colour="luma",
                    channels=1)
    assert 0.9 * 24 < k < 1.1 * 24
    # a larger window averages more independent samples
    k15 = noise_shape(operator="tenengrad", window_px=15, window="gaussian", downsample=1,
                      colour="luma", channels=1)
    k7 = noise_shape(operator="tenengrad", window_px=7, window="gaussian", downsample=1,
                     colour="luma", channels=1)
    assert 3.0 < k15 / k7 < 6.0


@pytest.mark.parametrize("op", ["tenengrad", "sml", "glv"])
def test_measures_written_into_given_arrays_are_the_same(op):
    """``out=``: each window's map is written into the array given (the trackers' ring
    buffers) and returned, bitwise equal to the maps made without it; the full and the
    downsampled grids, a 1-px window (the energy itself), a box window."""
    rng = np.random.default_rng(3)
    img = rng.random((37, 41, 3)).astype(np.float32)
    windows = [(7, "gaussian", 1), (15, "gaussian", 2), (1, "gaussian", 1), (5, "box", 1),
               (11, "box", 2)]
    ref = focus_measures(img, windows, operator=op)
    out = [np.full(r.shape, -1.0, np.float32) for r in ref]
    got = focus_measures(img, windows, operator=op, out=out)
    for r, g, o in zip(ref, got, out):
        assert g is o
        np.testing.assert_array_equal(g, r)
    with pytest.raises(ValueError, match="one array per window"):
        focus_measures(img, windows, operator=op, out=out[:2])


@pytest.mark.parametrize("op", ["tenengrad", "sml"])
@pytest.mark.parametrize("px, window", [(3, "gaussian"), (5, "box"), (1, "box")])
def test_measure_spread_is_the_second_moment_of_a_points_focus(op, px, window):
    """A single bright pixel's focus measure spreads over the pixels around it: its second
    moment about the pixel (per axis, averaged) is the spread's square. The reference is
    the measure OpenCV computes, not the kernel arithmetic of measure_spread_px."""
    img = np.zeros((41, 41), np.float32)
    img[20, 20] = 1.0
    m = focus_measure(img, operator=op, window_px=px, window=window).astype(np.float64)
    yy, xx = np.mgrid[-20:21, -20:21]
    var = 0.5 * float(np.sum(m * (yy ** 2 + xx ** 2)) / np.sum(m))
    assert measure_spread_px(operator=op, window_px=px, window=window) == pytest.approx(
        np.sqrt(var), rel=0.03)


def test_measure_spread_refuses_an_unknown_operator():
    with pytest.raises(ValueError, match="operator"):
        measure_spread_px(operator="laplace", window_px=3, window="gaussian")
