"""Drawing helpers of the report (microfacet.report.layout): the numbers they prepare."""

from __future__ import annotations

import numpy as np
import pytest

from microfacet.core.densities import histogram_density
from microfacet.report.layout import (
    MAX_MAP_PX,
    Page,
    colour_limits,
    downsample,
    finite,
    fmt,
    histogram,
    number,
    quantile_range,
)


def test_histogram_is_the_project_density_with_display_defaults():
    v = np.random.default_rng(0).normal(10.0, 2.0, 5000)
    c, d = histogram(v, 5.0, 15.0, bins=40)
    c2, d2 = histogram_density(v, bins=40, range=(5.0, 15.0))
    assert np.array_equal(c, c2) and np.array_equal(d, d2)
    ref, e = np.histogram(v, bins=40, range=(5.0, 15.0), density=True)
    assert np.allclose(d, ref) and np.allclose(c, 0.5 * (e[1:] + e[:-1]))
    # default range: that of the values; NaN ignored
    c, d = histogram(np.array([1.0, np.nan, 3.0]), bins=2)
    assert c.tolist() == [1.5, 2.5] and d.tolist() == [0.5, 0.5]
    # nothing to draw
    assert histogram(np.array([1.0])) is None
    assert histogram(np.array([1.0, 2.0]), 5.0, 6.0) is None
    assert histogram(np.array([2.0, 2.0]), bins=4)[0][0] == pytest.approx(2.125)


def test_downsample_is_a_nan_aware_block_mean():
    a = np.arange(16.0).reshape(4, 4)
    a[0, 0] = np.nan
    small, block = downsample(a, max_px=2)
    assert block == 2 and np.allclose(small, [[(1 + 4 + 5) / 3, 4.5], [10.5, 12.5]])
    big = np.zeros((3 * MAX_MAP_PX + 1, 10), np.float32)
    small, block = downsample(big)
    assert block == 4 and max(small.shape) <= MAX_MAP_PX
    same, block = downsample(a)
    assert same is a and block == 1
    m = np.zeros((4, 4), bool)
    m[:2, :2] = [[True, True], [False, False]]  # half of a block: True
    assert downsample(m, max_px=2)[0].tolist() == [[True, False], [False, False]]


def test_colour_limits():
    assert colour_limits(np.arange(101.0)) == (1.0, 99.0, "both")
    assert colour_limits(np.arange(101.0), 0.0, 99.0, floor=0.0) == (0.0, 99.0, "max")
    assert colour_limits(np.full(5, 3.0)) == (2.0, 4.0, "neither")   # constant: ±1
    assert colour_limits(np.full(5, 0.5), floor=0.0) == (0.0, 1.5, "neither")
    assert colour_limits(np.array([np.nan])) == (0.0, 1.0, "neither")


def test_quantile_range_and_finite():
    x = np.arange(10.0)
    assert quantile_range(x, np.ones(10), q=(0.25, 0.75)) == (2.0, 7.0)
    assert quantile_range(x, np.zeros(10)) is None
    a = np.array([[1.0, np.nan], [3.0, 4.0]])
    assert finite(a).tolist() == [1.0, 3.0, 4.0]
    assert finite(a, np.array([[True, False], [False, False]])).tolist() == [3.0, 4.0]
    assert finite(None).size == 0


def test_numbers_for_tables():
    assert [number(v) for v in (True, "1", np.nan, 2)] == [None, None, None, 2.0]
    assert fmt(float("inf")) == "—" and fmt(12.34, ".1f", "%") == "12.3 %"
    assert fmt(26.565, ".1f", "°") == "26.6°"


class _Fig:
    def get_size_inches(self):
        return (11.69, 8.27)


def test_page_grid_tiles_the_content_area():
    pg = Page(_Fig())
    cells = pg.grid(2, 3, hgap=0.2, vgap=0.1, widths=[1, 2, 1])
    assert len(cells) == 6
    x, y, w, h = cells[0]
    assert x == pg.left and y + h == pytest.approx(pg.top)
    x, y, w, h = cells[-1]
    assert x + w == pytest.approx(pg.right) and y == pytest.approx(pg.bottom)
    assert cells[1][2] == pytest.approx(2 * cells[0][2])
    assert pg.content() == (pg.left, pg.bottom, pg.right - pg.left, pg.top - pg.bottom)


@pytest.mark.slow
def test_a_map_colour_bar_is_one_small_image_not_a_page_sized_raster(tmp_path):
    """The bar of a map of many colours is drawn as an image of its colormap's colours from
    vmin to vmax (the mesh matplotlib would rasterize on a canvas of the whole page in a
    PDF is hidden): saved as a PDF, nothing on the page is rasterized; a bar of a few
    categories is left as matplotlib draws it."""
    from matplotlib.backends.backend_mixed import MixedModeRenderer
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    from microfacet.report.layout import PAGE_IN, Geometry, category_panel, map_panel

    pg = Page(Figure(figsize=PAGE_IN))
    cells = pg.grid(1, 2)
    a = np.linspace(100.0, 150.0, 60 * 80).reshape(60, 80)
    ax = map_panel(pg, cells[0], a, Geometry(0.2), title="t", label="nm", cmap="viridis",
                   limits=(110.0, 140.0, "both"))
    category_panel(pg, cells[1], np.arange(60 * 80).reshape(60, 80) % 3, Geometry(0.2),
                   colours=["r", "g", "b"], names=["a", "b", "c"], title="c", label="",
                   no_value=0.0)
    bar = [x for x in pg.fig.axes if x.get_ylabel() == "nm"]
    assert len(bar) == 1 and len(bar[0].images) == 1 and ax.images
    img = bar[0].images[0]
    values = np.asarray(img.get_array()).ravel()
    assert values[0] == 110.0 and values[-1] == 140.0 and values.size == ax.images[0].cmap.N
    assert tuple(img.get_extent()[2:]) == (110.0, 140.0)
    assert bar[0].get_ylim() == pytest.approx((110.0, 140.0))
    categories = [x for x in pg.fig.axes if x.get_yticklabels()
                  and [t.get_text() for t in x.get_yticklabels()] == ["a", "b", "c"]]
    assert len(categories) == 1 and not categories[0].images
    rasterized = []
    start = MixedModeRenderer.start_rasterizing

    def counting(self):
        rasterized.append(1)
        return start(self)

    MixedModeRenderer.start_rasterizing = counting
    try:
        with PdfPages(tmp_path / "p.pdf") as pdf:
            pdf.savefig(pg.fig, dpi=150)
    finally:
        MixedModeRenderer.start_rasterizing = start
    assert rasterized == []
