"""Maps reduced to the pixels a page shows (microfacet.report.arrays) and the panels that
draw them (microfacet.report.layout): the reduction is the NaN-aware block mean (nearest for
categories), no finer than MAX_MAP_PX and no coarser than the panel shows at PDF_DPI."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from microfacet.report.arrays import block_mean, display_block, downsample, value_stats
from microfacet.report.context import Context
from microfacet.report.layout import (
    MAX_MAP_PX,
    PAGE_IN,
    PDF_DPI,
    Geometry,
    Page,
    category_panel,
    map_panel,
)
from microfacet.report.page_distributions import plain_math

figure = pytest.importorskip("matplotlib.figure")


def _nanmean_blocks(a, f):
    """The reference: pad with NaN to whole blocks, np.nanmean over each block."""
    h, w = a.shape[:2]
    H, W = -(-h // f) * f, -(-w // f) * f
    x = np.full((H, W) + a.shape[2:], np.nan)
    x[:h, :w] = a
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks
        return np.nanmean(x.reshape((H // f, f, W // f, f) + a.shape[2:]), axis=(1, 3))


@pytest.mark.parametrize("shape, f", [((37, 53), 4), ((40, 40), 2), ((9, 31, 3), 5),
                                      ((7, 7), 7), ((5, 12), 3)])
def test_block_mean_is_the_nan_aware_mean_of_each_block(shape, f):
    rng = np.random.default_rng(1)
    a = rng.normal(10.0, 3.0, shape).astype(np.float32)
    assert np.allclose(block_mean(a, f), _nanmean_blocks(a, f), rtol=1e-6)  # no NaN
    a[rng.random(shape) < 0.3] = np.nan
    a[:f, :f] = np.nan  # an all-NaN block stays NaN: no value
    got, ref = block_mean(a, f), _nanmean_blocks(a, f)
    assert got.dtype == np.float32 and got.shape == ref.shape
    assert np.array_equal(np.isnan(got), np.isnan(ref)) and np.isnan(got[0, 0]).all()
    assert np.allclose(got, ref, rtol=1e-6, equal_nan=True)
    m = rng.random(shape[:2]) < 0.5  # booleans: True where at least half the block is
    small, block = downsample(m, block=f)
    assert small.dtype == bool and block == f
    assert np.array_equal(small, _nanmean_blocks(m.astype(float), f) >= 0.5)


@pytest.mark.parametrize("q", [[0.0, 1.0, 99.0, 100.0], [0.5, 99.9], [50.0], [1.0, 99.0]])
def test_value_stats_are_numpy_percentiles_of_the_finite_unmasked_values(q):
    """Exact also for large maps, whose order statistics are picked near the ends."""
    rng = np.random.default_rng(2)
    a = rng.lognormal(0.0, 1.0, (700, 800)).astype(np.float32)  # over _OrderStats.SMALL
    a[rng.random(a.shape) < 0.1] = np.nan
    a[3, 4], a[5, 6] = np.inf, -np.inf
    b = rng.normal(5.0, 1.0, (300, 300)).astype(np.float32)
    mask = rng.random(a.shape) < 0.2
    for values, m, ref in (
            (a, None, a[np.isfinite(a)]),
            (a, mask, a[np.isfinite(a) & ~mask]),
            ([a, b], None, np.concatenate([a[np.isfinite(a)], b.ravel()]))):
        ref = ref.astype(np.float64)
        want = (tuple(float(v) for v in np.percentile(ref, q)), ref.min(), ref.max())
        assert value_stats(values, q, mask=m) == want
    assert value_stats(np.full((3, 3), np.nan), q) is None


def test_display_block_shows_the_panel_at_pdf_dpi_and_at_most_max_map_px():
    for n in (300, 992, 1984, 4000, 20000):
        for side_in in (2.19, 3.25):
            f = display_block((n, n), (side_in, side_in), dpi=PDF_DPI)
            px = -(-n // f)
            assert px <= MAX_MAP_PX
            assert px >= min(n, side_in * PDF_DPI, MAX_MAP_PX // 2)
            if n >= side_in * PDF_DPI and -(-n // MAX_MAP_PX) < f:  # reduced for the panel
                assert side_in * PDF_DPI <= px < 2 * side_in * PDF_DPI


def _page():
    return Page(figure.Figure(figsize=PAGE_IN))


@pytest.mark.slow
def test_a_huge_map_is_drawn_at_the_pixels_its_panel_shows():
    """A 3000 × 2250 map on a maps-page panel: at most MAX_MAP_PX a side and at least
    PDF_DPI pixels per inch of the image box; the axes span the full map."""
    a = np.linspace(0.0, 1.0, 3000 * 2250, dtype=np.float32).reshape(2250, 3000)
    a[:, :300] = np.nan
    pg = _page()
    geom = Geometry(0.5)
    cell = pg.grid(2, 3)[0]
    ax = map_panel(pg, cell, a, geom, title="t", label="l", cmap="viridis",
                   limits=(0.0, 1.0, "neither"))
    drawn = ax.images[0].get_array()
    assert max(drawn.shape) <= MAX_MAP_PX
    w_in = ax.get_position().width * PAGE_IN[0]
    assert drawn.shape[1] >= w_in * PDF_DPI
    assert list(ax.images[0].get_extent()) == [0.0, 1500.0, 1125.0, 0.0]
    assert np.ma.getmaskarray(np.ma.masked_invalid(drawn))[:, 0].all()  # no value stays
    # categories: nearest, computed for the drawn pixels only
    seen = []

    def to_codes(x):
        seen.append(x.shape)
        return (x > 0.5).astype(np.int8)
    ax = category_panel(pg, pg.grid(2, 3)[1], a, geom, colours=("r", "b"), names=("a", "b"),
                        title="c", label="", no_value=None, to_codes=to_codes)
    drawn = ax.images[0].get_array()
    assert seen == [drawn.shape] and max(drawn.shape) <= MAX_MAP_PX
    assert set(np.unique(np.ma.compressed(drawn))) <= {0.0, 1.0}


def test_numbers_of_the_maps_are_computed_once_and_match_numpy(results):
    ctx = Context.open(results)
    th = ctx.res.map("thickness_nm")
    p = ctx.percentiles("thickness_nm")
    assert ctx.percentiles("thickness_nm") is p  # cached
    v = th[np.isfinite(th)].astype(np.float64)
    assert p[0] == pytest.approx(tuple(np.percentile(v, [1, 99])), rel=1e-6)
    assert (p[1], p[2]) == (v.min(), v.max())
    assert ctx.no_value("thickness_nm") == pytest.approx(np.mean(~np.isfinite(th)))
    both = ctx.percentiles(("tilt_deg", "tilt_height_deg"), (0.0, 99.0))
    assert both == value_stats([ctx.res.map("tilt_deg"), ctx.res.map("tilt_height_deg")],
                               [0.0, 99.0])


def test_log_axis_labels_are_plain_text():
    """The D(θ) axis: matplotlib's labels without mathtext (parsed per renderer, slow)."""
    assert plain_math(r"$\mathdefault{10^{-12}}$") == "10⁻¹²"
    assert plain_math(r"$\mathdefault{5\times10^{-3}}$") == "5×10⁻³"
    assert plain_math(r"$\mathdefault{10^{0}}$") == "10⁰"
    assert plain_math(r"$\mathdefault{\alpha}$") == r"$\mathdefault{\alpha}$"  # as it was
    assert plain_math("1.5") == "1.5"


@pytest.mark.parametrize("pixel_um, shape", [(0.5, (300, 400)), ([0.25, 0.1], (120, 900)),
                                             (None, (64, 64)), (3.7, (50, 2000))])
def test_maps_carry_a_scale_bar_of_the_length_it_says(pixel_um, shape):
    """No tick marks; one bar whose length in the map's units is the number it is labelled
    with, a 1-2-5 length of 8-20 % of the field's width, inside the map; the axes still
    span the whole map."""
    pg = _page()
    geom = Geometry(pixel_um)
    a = np.ones(shape, np.float32)
    ax = map_panel(pg, pg.grid(2, 3)[0], a, geom, title="t", label="l", cmap="viridis",
                   limits=(0.0, 1.0, "neither"))
    assert list(ax.get_xticks()) == [] and list(ax.get_yticks()) == []
    (bar,) = ax.lines
    (x0, x1), (ya, yb) = bar.get_xdata(), bar.get_ydata()
    label = [t.get_text() for t in ax.texts]
    unit = "µm" if pixel_um is not None else "px"
    assert label == [f"{x1 - x0:g} {unit}"]
    left, right, bottom, top = geom.extent(shape)
    assert 0.08 <= (x1 - x0) / (right - left) <= 0.2
    mantissa = (x1 - x0) / 10 ** np.floor(np.log10(x1 - x0))
    assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9
    assert left < x0 < x1 < right and top < ya == yb < bottom
    assert tuple(ax.get_xlim()) == (left, right) and tuple(ax.get_ylim()) == (bottom, top)
