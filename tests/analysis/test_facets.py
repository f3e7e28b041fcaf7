"""Facets (microfacet.analysis.facets): a plane per facet through reliable heights, the
thickness of each facet within its interference order, the distance from a facet boundary.

References are analytic: planes of known slope with white or correlated noise, images
rendered by 1 nm spectral integration at a known thickness and tilt per facet
(:func:`~microfacet.colour.table.direct_xyz`, not the table the search uses).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from microfacet import colour as color
from microfacet.analysis.facets import (
    facet_edge_distance,
    facet_thickness,
    fit_facet_planes,
    order_half_width_nm,
)
from microfacet.colour.table import build_colour_table, direct_xyz

# ------------------------------------------------------------------------ fit_facet_planes

PX = 0.5  # µm per pixel


def _block_labels(side, rows, cols):
    """Square segments of ``side`` px on a rows × cols grid, labelled row-major."""
    yy, xx = np.mgrid[0:rows * side, 0:cols * side]
    return ((yy // side) * cols + xx // side).astype(np.int32)


def _planes(labels, rng, slope=(-0.5, 0.5)):
    """Height (µm) of a plane per segment: z = a·x + b·y + c, x = columns, y = rows (µm)."""
    S = int(labels.max()) + 1
    a, b = rng.uniform(*slope, S), rng.uniform(*slope, S)
    c = rng.uniform(-5, 5, S)
    yy, xx = np.mgrid[0:labels.shape[0], 0:labels.shape[1]] * PX
    return a, b, a[labels] * xx + b[labels] * yy + c[labels]


def _fit(labels, h, sigma=0.01, reliable=None, **kw):
    rel = np.ones(h.shape, bool) if reliable is None else reliable
    return fit_facet_planes(labels, h, height_sigma_um=sigma, reliable=rel, pixel_size_um=PX,
                            **kw)


def test_planes_are_recovered_exactly_without_noise():
    labels = _block_labels(10, 4, 5)
    a, b, h = _planes(labels, np.random.default_rng(0))
    ff = _fit(labels, h)
    assert ff.fitted.all() and (ff.n_pixels == 100).all()
    np.testing.assert_allclose(ff.slope_x, a, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ff.slope_y, b, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ff.tilt_deg, np.degrees(np.arctan(np.hypot(a, b))), atol=1e-7)


def test_planes_on_non_square_pixels_are_the_planes_on_the_sample():
    """Slopes are dz/dx and dz/dy in µm/µm on (y, x) = (0.2, 0.5) µm pixels; read as square
    pixels the x slopes would come out 2.5× too steep."""
    labels = _block_labels(10, 4, 5)
    rng = np.random.default_rng(1)
    a, b = rng.normal(0, 0.3, 20), rng.normal(0, 0.3, 20)
    yy, xx = np.mgrid[0:labels.shape[0], 0:labels.shape[1]]
    h = a[labels] * xx * 0.5 + b[labels] * yy * 0.2
    rel = np.ones(h.shape, bool)
    ff = fit_facet_planes(labels, h, height_sigma_um=0.01, reliable=rel,
                          pixel_size_um=(0.2, 0.5))
    np.testing.assert_allclose(ff.slope_x, a, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ff.slope_y, b, rtol=0, atol=1e-9)
    sq = fit_facet_planes(labels, h, height_sigma_um=0.01, reliable=rel, pixel_size_um=0.2)
    np.testing.assert_allclose(sq.slope_x, 2.5 * a, rtol=1e-9, atol=1e-9)


def test_only_reliable_heights_are_used():
    """Unreliable pixels, however wrong, change nothing; NaN heights are skipped; a facet
    with fewer than ``min_pixels`` reliable heights, or all on one line, gets no tilt (NaN),
    not a guess."""
    labels = _block_labels(12, 1, 4)
    a, b, h = _planes(labels, np.random.default_rng(1))
    rel = np.ones(h.shape, bool)
    h = h.copy()
    h[2:6, 2:6] = 1e3
    rel[2:6, 2:6] = False                  # wild but unreliable: ignored
    h[7, 7] = np.nan
    rel[:, 12:24] = False
    rel[0, 12:17] = True                   # segment 1: 5 reliable pixels (< 8)
    rel[:, 24:36] = False
    rel[4, 24:36] = True                   # segment 2: 12 pixels on one row: no plane
    ff = _fit(labels, h, reliable=rel)
    assert ff.fitted.tolist() == [True, False, False, True]
    np.testing.assert_allclose(ff.slope_x[[0, 3]], a[[0, 3]], atol=1e-9)
    assert np.isnan(ff.tilt_deg[1:3]).all() and np.isnan(ff.tilt_sigma_deg[1:3]).all()
    assert np.isnan(ff.slope_sigma[1:3]).all()
    assert ff.n_pixels.tolist() == [144 - 16 - 1, 5, 12, 144]


@pytest.mark.parametrize("side", [8, 16])
def test_slope_noise_is_calibrated_for_independent_errors(side):
    """White height noise of known σ: the fitted slopes scatter about the truth as
    ``slope_sigma`` says (per axis), and the tilt as ``tilt_sigma_deg``."""
    rng = np.random.default_rng(2)
    labels = _block_labels(side, 20, 20)
    a, b, h = _planes(labels, rng, slope=(0.2, 0.6))
    ff = _fit(labels, h + rng.normal(0, 0.3, h.shape), sigma=0.3)
    z = np.concatenate([(ff.slope_x - a) / ff.slope_sigma, (ff.slope_y - b) / ff.slope_sigma])
    assert 0.85 < np.std(z) < 1.15, np.std(z)
    zt = (ff.tilt_deg - np.degrees(np.arctan(np.hypot(a, b)))) / ff.tilt_sigma_deg
    assert 0.8 < np.std(zt) < 1.25 and abs(np.mean(zt)) < 0.25


def test_an_underestimated_height_error_is_caught_by_the_residual():
    """σ given 10× too small: the reduced χ² (~100) inflates the covariance back."""
    rng = np.random.default_rng(3)
    labels = _block_labels(12, 20, 20)
    a, b, h = _planes(labels, rng)
    ff = _fit(labels, h + rng.normal(0, 0.2, h.shape), sigma=0.02)
    assert np.median(ff.chi2_dof) == pytest.approx(100, rel=0.2)
    z = (ff.slope_x - a) / ff.slope_sigma
    assert 0.8 < np.std(z) < 1.25


@pytest.mark.parametrize("window, side", [(5, 6), (5, 20), (7, 9), (7, 30), (11, 12),
                                          (11, 20)])
def test_correlated_errors_need_the_correlation_area(window, side):
    """Height errors smoothed over a box (as the focus window does) are correlated; the
    residual about the plane hides it. With ``correlation_px`` = their correlation area the
    slope noise is calibrated (z within 0.7-1.4) for facets from a third to 36 correlation
    areas; taking the errors as independent underestimates it."""
    rng = np.random.default_rng(window * 100 + side)
    rows = 300 // side
    labels = _block_labels(side, rows, rows)
    a, b, h = _planes(labels, rng)
    e = ndimage.uniform_filter(rng.normal(0, 1, h.shape), window)
    e *= 0.05 / e.std()
    # a box of side w on white noise: ρ is a product of triangles, ∫ρ d²r = w² (analytic)
    corr = float(window ** 2)
    good = _fit(labels, h + e, sigma=0.05, correlation_px=corr)
    naive = _fit(labels, h + e, sigma=0.05)
    z_good = np.std(np.concatenate([(good.slope_x - a) / good.slope_sigma,
                                    (good.slope_y - b) / good.slope_sigma]))
    z_naive = np.std((naive.slope_x - a) / naive.slope_sigma)
    assert 0.7 < z_good < 1.4 and z_naive > 1.5, (z_good, z_naive)


# ------------------------------------------------------------------------ facet_thickness


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(0.0, 400.0), theta_range_deg=(0.0, 27.0))


def _facet_image(labels, d_facet, t_facet, exposure):
    """Lab image of facets at thickness ``d_facet`` and tilt ``t_facet`` (per label), by
    1 nm spectral integration."""
    xyz = direct_xyz(t_facet[labels], d_facet[labels], spectral_step_nm=1.0) * exposure
    white = color.spectral_weights(np.arange(380.0, 781.0, 1.0)).sum(axis=0)
    return color.xyz_to_lab(xyz, white=white).astype(np.float32)


def test_the_order_window_is_less_than_half_a_colour_period(table):
    """TiO2 at 560 nm (n ≈ 2.5): the colours repeat every ~110 nm; ±0.45 of that."""
    hw = order_half_width_nm(table)
    assert 45 < hw < 55


def test_facet_thickness_is_recovered_at_the_facet_tilt(table):
    """The ROI's thickness may be up to ±40 nm off (a ROI mixing 112/130/148 nm regions read
    118 nm, and the old ±30 nm window piled 18 % of the pixels at its edge)."""
    rng = np.random.default_rng(4)
    labels = _block_labels(8, 6, 8)
    S = int(labels.max()) + 1
    d = rng.uniform(100.0, 170.0, S)
    t = rng.uniform(0.0, 25.0, S)
    lab = _facet_image(labels, d, t, exposure=0.9)
    roi = (d + rng.uniform(-40, 40, S))[labels]
    usable = np.ones(labels.shape, bool)
    usable[labels == 5] = False                             # a facet with no usable pixel
    ft = facet_thickness(labels, lab, usable, t, roi, table, exposure=0.9)
    assert ft.thickness_nm.shape == ft.delta_e.shape == ft.sigma_nm.shape == (S,)
    assert np.isnan(ft.thickness_nm[5]) and np.isnan(ft.delta_e[5])
    ok = np.arange(S) != 5
    np.testing.assert_allclose(ft.thickness_nm[ok], d[ok], atol=0.3)
    assert np.all(ft.delta_e[ok] < 0.3) and not ft.at_window_edge[ok].any()
    # the neighbouring orders fit worse (by 1.5-15 ΔE00 here): the order is not in doubt
    assert np.all(ft.delta_e_other_order[ok] > ft.delta_e[ok] + 1.0)
    assert np.median(ft.delta_e_other_order[ok]) > 5.0
    # at a wrong tilt the colour fits worse (tilt and thickness are not interchangeable)
    wrong = facet_thickness(labels, lab, usable, np.clip(t + 10, 0, 27), roi, table,
                            exposure=0.9)
    assert np.median(wrong.delta_e[ok]) > np.median(ft.delta_e[ok])


def test_thickness_sigma_is_calibrated_against_colour_noise(table):
    """Gaussian Lab noise of 2 per component on 36-pixel facets, its ΔE00 size measured as
    the analysis does: the thickness errors scatter as ``sigma_nm`` says (z within
    0.7-1.4)."""
    rng = np.random.default_rng(5)
    labels = _block_labels(6, 20, 20)      # 36-px facets
    S = int(labels.max()) + 1
    d = rng.uniform(110.0, 160.0, S)
    t = np.zeros(S)
    lab = _facet_image(labels, d, t, exposure=1.0) + rng.normal(0, 2.0, labels.shape + (3,))
    from microfacet.analysis.colour_image import estimate_colour_noise
    noise = estimate_colour_noise(lab, np.zeros(labels.shape, bool))
    ft = facet_thickness(labels, lab, np.ones(labels.shape, bool), t, d[labels], table,
                         exposure=1.0, noise_de=noise)
    z = (ft.thickness_nm - d) / ft.sigma_nm
    assert 0.7 < np.std(z) < 1.4, np.std(z)


def test_the_tilt_error_adds_to_the_thickness_error(table):
    rng = np.random.default_rng(6)
    labels = _block_labels(8, 4, 4)
    S = int(labels.max()) + 1
    d = np.full(S, 130.0)
    t = np.full(S, 15.0)
    lab = _facet_image(labels, d, t, exposure=1.0)
    base = facet_thickness(labels, lab, np.ones(labels.shape, bool), t, d[labels], table,
                           exposure=1.0)
    more = facet_thickness(labels, lab, np.ones(labels.shape, bool), t, d[labels], table,
                           exposure=1.0, tilt_sigma_deg=np.full(S, 5.0))
    # d·tanθ₁·cosθ/(n cosθ₁)·σθ at 15°, n ≈ 2.5: ≈ 130 × 0.104 × 0.97 / 2.5 × 0.087 ≈ 0.46
    extra = np.sqrt(more.sigma_nm ** 2 - base.sigma_nm ** 2)
    np.testing.assert_allclose(extra, 0.46, rtol=0.25)
    assert rng is not None


def test_interior_pixels_keep_a_dark_rim_out_of_the_facet_colour(table):
    """Each facet's boundary ring is shadowed (half as bright): with ``interior`` (distance
    from the facet boundary ≥ 1.5 px) the thickness is that of the facet; without, the mean
    colour is pulled off."""
    rng = np.random.default_rng(5)
    labels = _block_labels(12, 4, 5)
    S = int(labels.max()) + 1
    d = rng.uniform(100.0, 170.0, S)
    t = rng.uniform(0.0, 20.0, S)
    lab = _facet_image(labels, d, t, exposure=1.0)
    edge = facet_edge_distance(labels) < 1.5
    shadow = _facet_image(labels, d, t, exposure=0.5)
    lab[edge] = shadow[edge]
    usable = np.ones(labels.shape, bool)
    roi = d[labels]
    th_in = facet_thickness(labels, lab, usable, t, roi, table, exposure=1.0,
                            interior=~edge).thickness_nm
    th_all = facet_thickness(labels, lab, usable, t, roi, table, exposure=1.0).thickness_nm
    np.testing.assert_allclose(th_in, d, atol=0.3)
    assert np.max(np.abs(th_all - d)) > 1.0


# ------------------------------------------------------------------ facet_edge_distance


def test_edge_distance_of_a_vertical_and_a_horizontal_boundary():
    """Labels split at column 23 and row 11: the boundary pixels are the first column and
    row of the new label (0 there); elsewhere the distance is to the nearer of the two
    lines, exactly."""
    yy, xx = np.mgrid[0:40, 0:50]
    labels = (xx >= 23).astype(int) + 2 * (yy >= 11)
    d = facet_edge_distance(labels)
    np.testing.assert_allclose(d, np.minimum(np.abs(xx - 23), np.abs(yy - 11)))
    one = facet_edge_distance((xx >= 23).astype(int))
    np.testing.assert_allclose(one, np.abs(xx - 23))


def test_edge_distance_without_any_boundary_is_not_small():
    """One facet covering the image (a small image, or a large facet size: segment_facets
    then returns one segment) has no boundary; no pixel is near one. Today the distances
    are measured from outside the top-left corner, so pixel (0, 0) is 'on the rim' and is
    left out of the interior (distance < 1.5) in joint_tilts."""
    d = facet_edge_distance(np.zeros((20, 30), np.int32))
    assert np.all(d > 30), d.min()
