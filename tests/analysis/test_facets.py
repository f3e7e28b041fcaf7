"""Facets (microfacet.analysis.facets): segmentation into facets, a plane per facet, the
thickness of each facet, and the helper maps (blocks, distance from a facet boundary).

References are analytic: images of known colour regions (a straight edge, a Voronoi
mosaic), planes of known slope, images rendered by 1 nm spectral integration at a known
thickness and tilt per facet (:func:`~microfacet.colour.table.direct_xyz`, not the table the
search uses).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from microfacet import colour as color
from microfacet.analysis.facets import (
    facet_edge_distance,
    facet_thickness,
    fit_facet_planes,
    segment_facets,
    thickness_blocks,
)
from microfacet.colour.table import build_colour_table, direct_xyz

H, W = 128, 160


# ------------------------------------------------------------------------ segment_facets


def _boundary(labels):
    """Pixels whose right or lower neighbour has another label (one pixel thick)."""
    e = np.zeros(labels.shape, bool)
    e[:, 1:] |= labels[:, 1:] != labels[:, :-1]
    e[1:, :] |= labels[1:, :] != labels[:-1, :]
    return e


def _boundary_recall(truth, labels):
    """Fraction of the true boundary pixels within 1 px of a boundary of ``labels``."""
    d = ndimage.distance_transform_edt(~_boundary(labels))
    return float(np.mean(d[_boundary(truth)] <= 1.0))


def _two_colours():
    """Two Lab colours (ΔE00 ≈ 80) either side of a straight, slanted edge."""
    yy, xx = np.mgrid[0:H, 0:W]
    truth = (xx > 0.6 * yy + 40).astype(np.int32)
    colours = np.array([[55.0, 40.0, -20.0], [60.0, -30.0, 35.0]])
    return truth, colours[truth]


def _voronoi(cell_px=24, seed=0):
    """A Voronoi mosaic of cells ~``cell_px`` across, each a distinct random Lab colour."""
    rng = np.random.default_rng(seed)
    n = int(H * W / cell_px ** 2)
    yy, xx = np.mgrid[0:H, 0:W]
    _, truth = cKDTree(rng.uniform(0, [H, W], (n, 2))).query(
        np.stack([yy.ravel(), xx.ravel()], axis=1))
    truth = truth.reshape(H, W)
    colours = np.stack([rng.uniform(35, 75, n), rng.uniform(-50, 50, n),
                        rng.uniform(-50, 50, n)], axis=1)
    return truth, colours[truth]


def _square_grid(count):
    """A square grid of about ``count`` cells over the image (the chance reference)."""
    side = int(round(math.sqrt(H * W / count)))
    yy, xx = np.mgrid[0:H, 0:W]
    return (yy // side) * 1000 + xx // side


@pytest.mark.parametrize("facet_px", [12.0, 24.0, 40.0])
def test_labels_are_contiguous_connected_and_of_the_requested_size(facet_px):
    _, lab = _voronoi()
    labels = segment_facets(lab, facet_px=facet_px)
    assert labels.shape == (H, W) and labels.dtype == np.int32
    S = int(labels.max()) + 1
    np.testing.assert_array_equal(np.unique(labels), np.arange(S))   # 0..S-1, none empty
    # S segments of mean diameter facet_px: H·W / (π (facet_px / 2)²), within 30 %
    expected = H * W / (math.pi * (facet_px / 2) ** 2)
    assert 0.7 * expected <= S <= 1.3 * expected, (S, expected)
    # every segment is one connected piece (4-connectivity)
    for s in range(S):
        _, n = ndimage.label(labels == s)
        assert n == 1, s


def test_nan_pixels_are_segmented_too():
    truth, lab = _two_colours()
    lab = lab.copy()
    lab[:20, :30] = np.nan
    labels = segment_facets(lab, facet_px=16)
    assert labels.shape == (H, W) and labels.min() == 0
    np.testing.assert_array_equal(np.unique(labels), np.arange(labels.max() + 1))


def test_a_strong_colour_edge_draws_segment_boundaries():
    """What holds today: along a straight edge between two very different colours more of
    the edge lies on segment boundaries than on the boundaries of a square grid with as
    many cells (the grid: ~0.3; the segmentation: ~0.8)."""
    truth, lab = _two_colours()
    labels = segment_facets(lab, facet_px=24)
    recall = _boundary_recall(truth, labels)
    chance = _boundary_recall(truth, _square_grid(labels.max() + 1))
    assert recall > 1.5 * chance, (recall, chance)


@pytest.mark.xfail(strict=True, reason="issue: facets follow a grid, not edges")
@pytest.mark.parametrize("scene", ["straight edge", "voronoi mosaic"])
def test_segment_boundaries_follow_colour_edges(scene, record_property):
    """The goal (module notes: "one colour in the microscope image is one flat facet"):
    ≥ 90 % of the true boundary pixels lie within 1 px of a segment boundary. Today SLIC
    (compactness 2 on input rescaled to [0, 1]) draws a near-square grid: measured ~0.78 on
    the edge and ~0.32 on the mosaic (a square grid: ~0.29 and ~0.27)."""
    truth, lab = _two_colours() if scene == "straight edge" else _voronoi(cell_px=24)
    labels = segment_facets(lab, facet_px=24)
    recall = _boundary_recall(truth, labels)
    record_property("boundary_recall", recall)
    assert recall >= 0.90, f"{scene}: {recall:.3f} of the true boundary within 1 px"


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


def test_planes_are_recovered_exactly_without_noise():
    labels = _block_labels(10, 4, 5)
    a, b, h = _planes(labels, np.random.default_rng(0))
    w = np.ones(h.shape)
    ff = fit_facet_planes(labels, h, w, pixel_size_um=PX,
                          fallback_tilt_deg=np.zeros(h.shape))
    assert ff.fitted.all()
    np.testing.assert_allclose(ff.slope_x, a, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ff.slope_y, b, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ff.tilt_deg, np.degrees(np.arctan(np.hypot(a, b))), atol=1e-7)
    np.testing.assert_allclose(ff.n_eff, 100.0)
    np.testing.assert_allclose(ff.tilt_sigma_deg, 0.25)     # no residual: the σ floor


def test_weights_and_non_finite_heights_leave_the_plane_exact():
    """Pixels of weight 0, NaN heights and a wildly wrong pixel of weight 0 change nothing;
    a weight scales the segment's n_eff."""
    labels = _block_labels(12, 2, 3)
    a, b, h = _planes(labels, np.random.default_rng(1))
    w = np.full(h.shape, 2.0)
    h = h.copy()
    h[3, 3] = np.nan
    h[5, 5], w[5, 5] = 1e6, 0.0
    ff = fit_facet_planes(labels, h, w, pixel_size_um=PX, fallback_tilt_deg=np.zeros(h.shape))
    np.testing.assert_allclose(ff.slope_x, a, atol=1e-9)
    np.testing.assert_allclose(ff.slope_y, b, atol=1e-9)
    np.testing.assert_allclose(ff.n_eff, [2.0 * (144 - 2)] + [2.0 * 144] * 5)


def test_tilt_sigma_is_calibrated_and_shrinks_with_more_pixels():
    """Height noise σ_h: the reported σ of the tilt matches the scatter of the fitted tilts
    about the truth, and for square segments it scales as 1/√(n²(n²−1)) with the side n
    (the slope variance of a least-squares plane): 8 → 16 px is 4.0 times smaller."""
    rng = np.random.default_rng(2)
    sigma = {}
    for side in (8, 16):
        labels = _block_labels(side, 20, 20)
        a, b, h = _planes(labels, rng, slope=(0.2, 0.6))
        h = h + rng.normal(0, 0.3, h.shape)
        ff = fit_facet_planes(labels, h, np.ones(h.shape), pixel_size_um=PX,
                              fallback_tilt_deg=np.zeros(h.shape))
        assert ff.fitted.all()
        z = (ff.tilt_deg - np.degrees(np.arctan(np.hypot(a, b)))) / ff.tilt_sigma_deg
        assert abs(np.mean(z)) < 0.25 and 0.8 < np.std(z) < 1.25, (side, np.std(z))
        sigma[side] = np.median(ff.tilt_sigma_deg)
        assert sigma[side] > 0.25                      # above the floor: really measured
    expected = math.sqrt(256 * 255) / math.sqrt(64 * 63)
    assert sigma[8] / sigma[16] == pytest.approx(expected, rel=0.1)


def test_too_few_weighted_pixels_fall_back_to_the_mean_tilt():
    labels = _block_labels(10, 1, 4)
    _, _, h = _planes(labels, np.random.default_rng(3))
    w = np.ones(h.shape)
    w[:, 10:20] = 0.0                      # segment 1: no weight at all
    w[:, 20:30] = 0.0
    w[0, 20:25] = 1.0                      # segment 2: 5 weighted pixels (< min_weight 6)
    w[:, 30:40] = 0.0
    w[4, 30:40] = 1.0                      # segment 3: 10 pixels, all on one row: no plane
    fb = np.full(h.shape, 4.0)
    fb[:, 10:15] = 6.0                     # segment 1: mean 5
    fb[0, 10] = np.nan                     # ignored
    ff = fit_facet_planes(labels, h, w, pixel_size_um=PX, fallback_tilt_deg=fb,
                          fallback_sigma_deg=8.0)
    assert ff.fitted.tolist() == [True, False, False, False]
    np.testing.assert_allclose(ff.tilt_deg[1:], [(49 * 6.0 + 50 * 4.0) / 99, 4.0, 4.0])
    np.testing.assert_array_equal(ff.tilt_sigma_deg[1:], 8.0)
    assert np.isnan(ff.slope_x[1:]).all() and np.isnan(ff.slope_y[1:]).all()
    np.testing.assert_allclose(ff.n_eff, [100.0, 0.0, 5.0, 10.0])


# ------------------------------------------------------------------------ facet_thickness


@pytest.fixture(scope="module")
def table():
    return build_colour_table(thickness_range_nm=(80.0, 200.0), theta_range_deg=(0.0, 27.0))


def _facet_image(table, labels, d_facet, t_facet, exposure):
    """Lab image of facets at thickness ``d_facet`` and tilt ``t_facet`` (per label), by
    1 nm spectral integration."""
    xyz = direct_xyz(t_facet[labels], d_facet[labels], spectral_step_nm=1.0) * exposure
    white = color.spectral_weights(np.arange(380.0, 781.0, 1.0)).sum(axis=0)
    return color.xyz_to_lab(xyz, white=white).astype(np.float32)


def test_facet_thickness_is_recovered_at_the_facet_tilt(table):
    rng = np.random.default_rng(4)
    labels = _block_labels(8, 6, 8)
    S = int(labels.max()) + 1
    d = rng.uniform(100.0, 170.0, S)
    t = rng.uniform(0.0, 25.0, S)
    lab = _facet_image(table, labels, d, t, exposure=0.9)
    # the ROI stage's thickness: within ±20 nm of the truth (same interference order)
    roi = (d + rng.uniform(-20, 20, S))[labels]
    usable = np.ones(labels.shape, bool)
    usable[labels == 5] = False                             # a facet with no usable pixel
    th, de = facet_thickness(labels, lab, usable, t, roi, table, exposure=0.9)
    assert th.shape == de.shape == (S,)
    assert np.isnan(th[5]) and np.isnan(de[5])
    ok = np.arange(S) != 5
    np.testing.assert_allclose(th[ok], d[ok], atol=0.3)
    assert np.all(de[ok] < 0.3)
    # at a wrong tilt the colour fits worse (tilt and thickness are not interchangeable)
    _, de_wrong = facet_thickness(labels, lab, usable, np.clip(t + 10, 0, 27), roi, table,
                                  exposure=0.9)
    assert np.median(de_wrong[ok]) > np.median(de[ok])


def test_interior_pixels_keep_a_dark_rim_out_of_the_facet_colour(table):
    """Each facet's boundary ring is shadowed (half as bright): with ``interior`` (distance
    from the facet boundary ≥ 1.5 px) the thickness is that of the facet; without, the mean
    colour is pulled off."""
    rng = np.random.default_rng(5)
    labels = _block_labels(12, 4, 5)
    S = int(labels.max()) + 1
    d = rng.uniform(100.0, 170.0, S)
    t = rng.uniform(0.0, 20.0, S)
    lab = _facet_image(table, labels, d, t, exposure=1.0)
    edge = facet_edge_distance(labels) < 1.5
    shadow = _facet_image(table, labels, d, t, exposure=0.5)
    lab[edge] = shadow[edge]
    usable = np.ones(labels.shape, bool)
    roi = d[labels]
    th_in, _ = facet_thickness(labels, lab, usable, t, roi, table, exposure=1.0,
                               interior=~edge)
    th_all, _ = facet_thickness(labels, lab, usable, t, roi, table, exposure=1.0)
    np.testing.assert_allclose(th_in, d, atol=0.3)
    assert np.max(np.abs(th_all - d)) > 1.0


# ------------------------------------------------------------------ thickness_blocks


@pytest.mark.parametrize("shape, px, block_um, side", [
    ((45, 61), 0.5, 10.0, 20),      # 20 px blocks, the last row and column partial
    ((30, 30), 0.216, 10.0, 46),    # one block larger than the image
    ((17, 9), 1.0, 1.0, 4),         # at least 4 px
])
def test_thickness_blocks_are_squares_of_the_block_size(shape, px, block_um, side):
    ids = thickness_blocks(shape, pixel_size_um=px, block_um=block_um)
    assert ids.shape == shape
    rows, cols = -(-shape[0] // side), -(-shape[1] // side)
    np.testing.assert_array_equal(np.unique(ids), np.arange(rows * cols))
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    np.testing.assert_array_equal(ids, (yy // side) * cols + xx // side)


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
