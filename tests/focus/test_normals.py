"""Analytic checks of microfacet.focus.normals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from microfacet.focus.normals import normals_from_height, tilt_azimuth_deg


def angle_deg(a, b):
    c = np.clip(np.sum(a * b, axis=-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1),
                -1, 1)
    return np.degrees(np.arccos(c))


@settings(max_examples=40, deadline=None)
@given(gx=st.floats(-3, 3), gy=st.floats(-3, 3), px=st.floats(0.05, 20))
def test_tilted_plane_exact(gx, gy, px):
    """h = gx·x + gy·y (µm, with x right and y up): tilt = atan|∇h|, azimuth of -∇h."""
    rows, cols = np.mgrid[0:7, 0:9]
    x = cols * px
    y = -rows * px
    h = gx * x + gy * y + 3.0
    n = normals_from_height(h, pixel_size_um=px)
    expect = np.array([-gx, -gy, 1.0]) / np.sqrt(1 + gx * gx + gy * gy)
    np.testing.assert_allclose(n, np.broadcast_to(expect, n.shape), atol=2e-6)
    tilt, az = tilt_azimuth_deg(n)
    np.testing.assert_allclose(tilt, np.degrees(np.arctan(np.hypot(gx, gy))), atol=2e-4)
    if np.hypot(gx, gy) > 1e-3:
        d = (az - np.degrees(np.arctan2(-gy, -gx)) + 180) % 360 - 180
        assert np.abs(d).max() < 1e-2


@settings(max_examples=30, deadline=None)
@given(gx=st.floats(-2, 2), gy=st.floats(-2, 2), py=st.floats(0.05, 5), ratio=st.floats(0.2, 5))
def test_non_square_pixels_give_the_plane_of_square_ones(gx, gy, py, ratio):
    """The same plane sampled on (y, x) = (py, py·ratio) pixels has the normal of the plane;
    read as square pixels of either size it would not (unless the plane is level along x)."""
    px = py * ratio
    rows, cols = np.mgrid[0:6, 0:8]
    h = gx * cols * px - gy * rows * py
    n = normals_from_height(h, pixel_size_um=(py, px))
    expect = np.array([-gx, -gy, 1.0]) / np.sqrt(1 + gx * gx + gy * gy)
    np.testing.assert_allclose(n, np.broadcast_to(expect, n.shape), atol=2e-6)
    if abs(gx) > 0.05 and abs(ratio - 1) > 0.1:
        wrong = normals_from_height(h, pixel_size_um=py)
        assert angle_deg(wrong, np.broadcast_to(expect, n.shape)).min() > 0.1


def test_pixel_size_matters():
    h = np.tile(np.arange(10.0), (5, 1))          # 1 µm per pixel along x
    t1, _ = tilt_azimuth_deg(normals_from_height(h, pixel_size_um=1.0))
    t2, _ = tilt_azimuth_deg(normals_from_height(h, pixel_size_um=2.0))
    np.testing.assert_allclose(t1, 45.0, atol=1e-4)
    np.testing.assert_allclose(t2, np.degrees(np.arctan(0.5)), atol=1e-4)


def test_sphere_cap():
    """Cap of radius R = 60 px: normals match (x, y, h)/R within the documented error."""
    R, px = 60.0, 0.5
    N = 121
    rows, cols = np.mgrid[0:N, 0:N]
    x = (cols - 60) * 1.0
    y = -(rows - 60) * 1.0
    r2 = x * x + y * y
    inside = r2 < (R * np.sin(np.radians(70))) ** 2
    h = np.where(inside, np.sqrt(np.maximum(R * R - r2, 0)), np.nan) * px   # µm
    n = normals_from_height(h, pixel_size_um=px)
    truth = np.stack([x, y, np.sqrt(np.maximum(R * R - r2, 0))], -1) / R
    tilt_true = np.degrees(np.arccos(truth[..., 2]))
    err = angle_deg(n.astype(np.float64), truth)
    assert np.isnan(n[~inside]).all()
    assert np.isfinite(n[inside]).all()
    # interior (central differences)
    core45 = inside & (tilt_true < 45)
    core60 = inside & (tilt_true < 60)
    assert err[core45].max() < 0.05
    # pixels next to the NaN rim use one-sided differences: first order, larger error
    interior = core60 & np.roll(inside, 1, 0) & np.roll(inside, -1, 0) & \
        np.roll(inside, 1, 1) & np.roll(inside, -1, 1)
    assert err[interior].max() < 0.25
    np.testing.assert_allclose(np.linalg.norm(n[inside], axis=-1), 1.0, atol=1e-6)
    tilt, _ = tilt_azimuth_deg(n)
    assert np.abs(tilt - tilt_true)[core45].max() < 0.05


def test_nan_handling_and_smoothing():
    rng = np.random.default_rng(0)
    rows, cols = np.mgrid[0:40, 0:50]
    h = 0.2 * cols + rng.normal(0, 0.05, (40, 50))
    h[10:14, 20:25] = np.nan
    n0 = normals_from_height(h, pixel_size_um=1.0)
    assert np.isnan(n0[10:14, 20:25]).all()
    assert np.isfinite(n0[~np.isnan(h)]).all()    # one-sided next to the hole
    n3 = normals_from_height(h, pixel_size_um=1.0, smooth_sigma_px=3)
    t0, _ = tilt_azimuth_deg(n0)
    t3, _ = tilt_azimuth_deg(n3)
    true = np.degrees(np.arctan(0.2))
    ok = np.isfinite(t3)
    assert np.nanstd(t3[ok] - true) < 0.3 * np.nanstd(t0[ok] - true)
    assert abs(np.nanmedian(t3) - true) < 0.2
    assert n0.dtype == np.float32 and n0.shape == (40, 50, 3)


def test_bad_arguments():
    with pytest.raises(ValueError, match="pixel_size_um"):
        normals_from_height(np.zeros((3, 3)), pixel_size_um=0)
    with pytest.raises(ValueError, match="pixel_size_um"):
        normals_from_height(np.zeros((3, 3)), pixel_size_um=float("nan"))
    for bad in ([1.0, 2.0, 3.0], [1.0, -1.0], "0.5", True):
        with pytest.raises(ValueError, match="pixel_size_um"):
            normals_from_height(np.zeros((3, 3)), pixel_size_um=bad)
    with pytest.raises(ValueError, match="height_um"):
        normals_from_height(np.zeros(3), pixel_size_um=1.0)
    with pytest.raises(ValueError, match="smooth_sigma_px"):
        normals_from_height(np.zeros((3, 3)), pixel_size_um=1.0, smooth_sigma_px=-1)
