"""Page geometry and drawing helpers shared by the report's pages.

A page is one A4-landscape matplotlib ``Figure`` laid out in inches (:class:`Page`): no layout
engine, so every report has pages of identical structure and draws quickly. On it the pages
place map panels (:func:`map_panel`, :func:`category_panel`, :func:`blank_panel`) and tables
(:func:`draw_table`). The small helpers format numbers for tables (:func:`fmt`, :func:`pct`,
:func:`shorten`); the arrays are prepared for display in :mod:`~microfacet.report.arrays`
(:func:`downsample`, :func:`colour_limits`, :func:`histogram`, :func:`quantile_range`, here
too). A map is drawn at the pixels its panel shows (:func:`shown`).

Colour maps are perceptually uniform and sequential (no quantity drawn is signed); a pixel
without a value (masked, or NaN) is drawn in :data:`NO_VALUE` grey on every map, and each map
states its share of such pixels next to a grey swatch.

Importing this module does not import matplotlib; drawing does.

Examples
--------
>>> fmt(1.23456, ".3g", "nm"), fmt(12.0, ".3g", "°"), fmt(None), pct(0.25)
('1.23 nm', '12°', '—', 25.0)
>>> shorten("/a/long/path/to/a/stack", 12)
'…/to/a/stack'
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from ..core.lazy import load
from ..core.pixels import pixel_size_yx
from .arrays import (
    MAX_MAP_PX,
    colour_limits,
    display_block,
    downsample,
    finite,
    histogram,
    quantile_range,
)

mpl = load("matplotlib")
mcolors = load("matplotlib.colors")
mpatches = load("matplotlib.patches")
mcollections = load("matplotlib.collections")

__all__ = ["Geometry", "MAX_MAP_PX", "NO_VALUE", "Page", "blank_panel", "category_panel",
           "colour_map", "colourbar", "draw_table", "finite", "histogram", "map_panel",
           "quantile_range"]

#: Colour of a pixel without a value (masked or NaN) on every map.
NO_VALUE = "#a3a3a3"

PAGE_IN = (11.69, 8.27)  # A4 landscape
PDF_DPI = 150   # resolution of the images the PDF resamples (all-in-focus, angular maps)
PNG_DPI = 110   # 1286 × 910 pixel page PNGs
_MARGIN_X = 0.45
_HEADER_IN = 0.82     # title, sub-title and a rule
_FOOTER_IN = 0.40
#: matplotlib rc parameters of every page.
RC = {
    "font.size": 9,
    "axes.titlesize": 10.5,
    "axes.labelsize": 9,
    "xtick.labelsize": 8,
    "ytick.labelsize": 8,
    "legend.fontsize": 7.5,
    "pdf.fonttype": 3,
    "pdf.compression": 6,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.titlepad": 4.0,
    "axes.titley": 1.0,   # fixed title position: no automatic placement (slow)
    "image.interpolation": "none",   # vector output embeds the pixels unresampled
    "image.interpolation_stage": "rgba",
    # unhinted glyphs: as legible at PNG_DPI and a fifth faster to render (the PDF's text
    # is never hinted)
    "text.hinting": "no_hinting",
}
#: Mixture components, sorted by mean thickness / lobe width (blue, green, red as the
#: seed's Fig. 18c for thin, middle and thick).
COMPONENT_COLOURS = ("#1f77b4", "#2ca02c", "#d62728", "#ff7f0e", "#8c564b", "#e377c2",
                     "#bcbd22", "#17becf", "#7f7f7f", "#9467bd")
HEIGHT_TILT = "#7b3294"   # tilt from the height map, overlaid on the tilt histogram
HIST_FILL, HIST_EDGE = "#dcdcdc", "#8a8a8a"
#: Colour map of each kind of map.
CMAPS = {"height": "plasma", "thickness": "viridis", "delta_e": "inferno",
         "tilt": "magma", "sigma": "inferno"}
DE = "ΔE₀₀"


def component_colour(i):
    """Colour of mixture component ``i`` (0-based)."""
    return COMPONENT_COLOURS[i % len(COMPONENT_COLOURS)]


# --------------------------------------------------------------------------- numbers, text
def number(v):
    """``float(v)`` if v is a finite real number (not bool), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def positive(v):
    """``float(v)`` if v is a finite number > 0, else None."""
    v = number(v)
    return v if v is not None and v > 0 else None


def fmt(v, spec=".3g", unit=""):
    """``v`` formatted with ``spec`` and ``unit`` ("°" without a space), "—" if not a number."""
    v = number(v)
    if v is None:
        return "—"
    return f"{v:{spec}}" + ((unit if unit == "°" else f" {unit}") if unit else "")


def pct(v):
    """A fraction as a percentage, or None if not a number."""
    v = number(v)
    return None if v is None else 100.0 * v


def shorten(s, n):
    """``str(s)``, its start replaced by "…" if longer than ``n`` characters."""
    s = str(s)
    return s if len(s) <= n else "…" + s[-(n - 1):]


def wrap(text, width):
    """Greedy wrap on ", " and spaces (a table cell holds one line per row)."""
    return textwrap.wrap(text, width=width, break_long_words=True) or [""]


# --------------------------------------------------------------------------- page
class Page:
    """One A4-landscape figure laid out in inches (bottom-left origin), no layout engine.

    Fixed positions are an order of magnitude cheaper to draw than constrained layout
    and keep the pages of every report identical in structure.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        Of size :data:`PAGE_IN`.

    Attributes
    ----------
    W, H : float
        Page size, inches.
    left, right, bottom, top : float
        The content area between the margins, the header and the footer, inches.
    """

    def __init__(self, fig):
        self.fig = fig
        self.W, self.H = fig.get_size_inches()
        self.top = self.H - _HEADER_IN          # content area: [bottom, top] × [left, right]
        self.bottom = _FOOTER_IN
        self.left = _MARGIN_X
        self.right = self.W - _MARGIN_X

    def axes(self, x, y, w, h, **kw):
        """Axes at ``(x, y)`` inches, ``w × h`` inches."""
        return self.fig.add_axes((x / self.W, y / self.H, w / self.W, h / self.H), **kw)

    def text(self, x, y, s, **kw):
        """Figure text at ``(x, y)`` inches."""
        return self.fig.text(x / self.W, y / self.H, s, **kw)

    def grid(self, nrows, ncols, *, top=None, bottom=None, hgap=0.0, vgap=0.0,
             widths=None, heights=None):
        """Cells ``(x, y, w, h)`` in inches, row-major from the top left."""
        top = self.top if top is None else top
        bottom = self.bottom if bottom is None else bottom
        widths = np.asarray(widths if widths is not None else [1.0] * ncols, float)
        heights = np.asarray(heights if heights is not None else [1.0] * nrows, float)
        ws = widths / widths.sum() * (self.right - self.left - hgap * (ncols - 1))
        hs = heights / heights.sum() * (top - bottom - vgap * (nrows - 1))
        cells = []
        y = top
        for r in range(nrows):
            y -= hs[r]
            x = self.left
            for c in range(ncols):
                cells.append((x, y, ws[c], hs[r]))
                x += ws[c] + hgap
            y -= vgap
        return cells

    def content(self):
        """The whole content area as one cell ``(x, y, w, h)``."""
        return (self.left, self.bottom, self.right - self.left, self.top - self.bottom)


class Geometry:
    """Axis units for the maps: µm if the pixel size is known (one number or ``[y, x]``),
    else pixels.

    >>> g = Geometry([0.25, 0.5])
    >>> g.extent((10, 20)), g.height_ratio((10, 20)), g.size_text(), g.field_text((10, 20))
    ((0.0, 10.0, 2.5, 0.0), 0.25, '0.25 × 0.5 µm (y × x)', '10 × 2.5 µm')
    >>> Geometry(None).unit, Geometry(-1.0).yx
    ('pixel', None)
    """

    def __init__(self, pixel_size_um):
        try:
            self.yx = None if pixel_size_um is None else pixel_size_yx(pixel_size_um)
        except ValueError:
            self.yx = None
        self.unit = "µm" if self.yx else "pixel"

    def extent(self, shape):
        """``imshow`` extent of a map of ``shape`` (H, W, ...) pixels."""
        py, px = self.yx or (1.0, 1.0)
        return (0.0, shape[1] * px, shape[0] * py, 0.0)

    def height_ratio(self, shape):
        """Height / width of a map of ``shape`` on the sample (pixels when unknown)."""
        py, px = self.yx or (1.0, 1.0)
        return shape[0] * py / (shape[1] * px)

    def size_text(self):
        """The pixel size for a table."""
        if not self.yx:
            return "unknown (axes in pixels)"
        py, px = self.yx
        return f"{px:.4g} µm" if py == px else f"{py:.4g} × {px:.4g} µm (y × x)"

    def field_text(self, shape):
        """Width × height of the field for a table."""
        if not self.yx or not shape:
            return "—"
        py, px = self.yx
        return f"{shape[1] * px:.4g} × {shape[0] * py:.4g} µm"

    def scale_bar(self, ax, shape):
        """A scale bar on the map of ``shape`` (H, W, ...) pixels drawn in ``ax`` (its
        :meth:`extent`), in place of tick marks: microscopy's convention, and cheaper (the
        maps' ticks and labels were a fifth of the report's time, docs/benchmarks.md). The bar is
        :func:`nice_length` of about a fifth of the field's width, bottom left, black with
        its length written above it, on a translucent white plate."""
        x0, x1, y1, _ = self.extent(shape)
        w = x1 - x0
        inch = w / (ax.get_position().width * ax.figure.get_size_inches()[0])  # data / in
        length = nice_length(0.2 * w)
        unit = "µm" if self.yx else "px"
        ax.set_xticks([])
        ax.set_yticks([])
        # on a translucent white plate as wide as the bar or its label, readable on any map
        plate_w = max(length, 0.42 * inch) + 0.1 * inch
        ax.add_patch(mpatches.Rectangle((x0 + 0.05 * inch, y1 - 0.05 * inch), plate_w,
                                        -0.27 * inch, facecolor="white", alpha=0.75,
                                        edgecolor="none"))
        xc, y = x0 + 0.05 * inch + 0.5 * plate_w, y1 - min(0.1 * inch, 0.5 * y1)
        ax.plot([xc - 0.5 * length, xc + 0.5 * length], [y, y], color="black", lw=2.0,
                solid_capstyle="butt")
        ax.text(xc, y - 0.04 * inch, f"{length:g} {unit}", color="black", fontsize=7,
                ha="center", va="bottom")
        ax.set_xlim(x0, x1)          # the bar does not widen the axes
        ax.set_ylim(y1, 0.0)


def nice_length(target):
    """The largest 1, 2 or 5 × 10ⁿ at most ``target`` (> 0).

    >>> nice_length(23.0), nice_length(0.7), nice_length(5.0)
    (20.0, 0.5, 5.0)
    """
    k = 10.0 ** math.floor(math.log10(target))
    return max(m * k for m in (1.0, 2.0, 5.0) if m * k <= target * (1 + 1e-12))


# --------------------------------------------------------------------------- map panels
_MAP_MARGINS = dict(left=0.55, right=0.86, top=0.30, bottom=0.50)


def colour_map(name):
    """The matplotlib colour map ``name`` in 255 levels, with NaN drawn in :data:`NO_VALUE`:
    a map then has at most 256 colours, which the PDF stores as an indexed image (a third
    of the bytes, several times faster to compress than RGB)."""
    return mpl.colormaps[name].resampled(255).with_extremes(bad=NO_VALUE)


def _image_box(cell, shape, geom=None):
    """The box ``(x0, y0, w, h)`` inches in ``cell`` of an image of ``shape``: exactly the
    image's aspect on the sample (``geom``, a :class:`Geometry`; pixels when None), as large
    as the margins (and a colour bar) allow, centred."""
    x, y, w, h = cell
    m = _MAP_MARGINS
    aw, ah = w - m["left"] - m["right"], h - m["top"] - m["bottom"]
    r = geom.height_ratio(shape) if geom is not None else shape[0] / shape[1]
    iw, ih = (aw, aw * r) if aw * r <= ah else (ah / r, ah)
    return x + m["left"] + 0.5 * (aw - iw), y + m["bottom"] + 0.5 * (ah - ih), iw, ih


def image_axes(pg, cell, shape, geom=None):
    """Axes on the :func:`_image_box` of ``shape`` in ``cell`` (so a colour bar beside it is
    as tall as the image), and that box."""
    box = _image_box(cell, shape, geom)
    ax = pg.axes(*box)
    for sp in ax.spines.values():
        sp.set_visible(True)
        sp.set_linewidth(0.6)
    return ax, box


def shown(a, box):
    """``a`` (H×W or H×W×C) block-averaged to the pixels the image ``box`` ``(x0, y0, w,
    h)`` inches shows at :data:`PDF_DPI`, at most :data:`MAX_MAP_PX` a side
    (:func:`~microfacet.report.arrays.display_block`); and the block size."""
    return downsample(a, block=display_block(a.shape, box[2:], dpi=PDF_DPI))


def blank_panel(pg, cell, text, title=None, shape=(1, 1)):
    """An empty panel saying why, where a map of ``shape`` would be."""
    ax, _ = image_axes(pg, cell, shape)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes,
            color="0.35", fontsize=9, wrap=True)
    return ax


def colourbar(pg, im, box, label, *, extend="neither", ticks=None, ticklabels=None,
              no_value=None):
    """A colour bar right of the image ``box``; below it, if ``no_value`` is a fraction,
    a grey swatch saying what share of the map has no value."""
    x0, y0, iw, ih = box
    cax = pg.axes(x0 + iw + 0.08, y0, 0.13, ih)
    cb = pg.fig.colorbar(im, cax=cax, extend=extend, ticks=ticks)
    if cb.solids is not None and cb.solids.get_rasterized():
        # a bar of many colours is a mesh that the PDF backend rasterizes on a canvas of the
        # whole page (9 MB at PDF_DPI for each bar, docs/benchmarks.md): its colours are
        # drawn as an image of one column instead, which the PDF embeds as it is
        cb.solids.set_visible(False)
        cb.solids.set_rasterized(False)   # hidden, and no page canvas made for it either
        lo, hi = cb.norm.vmin, cb.norm.vmax
        cax.imshow(np.linspace(lo, hi, im.cmap.N)[:, None], cmap=im.cmap, norm=im.norm,
                   aspect="auto", origin="lower", extent=(0.0, 1.0, lo, hi),
                   interpolation="nearest")
    if ticklabels is not None:
        cb.ax.set_yticklabels(ticklabels)
    cb.set_label(label, labelpad=5)
    cb.ax.tick_params(labelsize=7.5)
    if no_value is not None:
        pg.fig.add_artist(mpatches.Rectangle(
            ((x0 + iw + 0.08) / pg.W, (y0 - 0.34) / pg.H), 0.13 / pg.W, 0.13 / pg.H,
            facecolor=NO_VALUE, edgecolor="0.5", linewidth=0.5))
        pg.text(x0 + iw + 0.26, y0 - 0.275, f"no value\n{100.0 * no_value:.1f} %",
                fontsize=7, va="center", ha="left", color="0.25", linespacing=1.0)
    return cb


def map_panel(pg, cell, a, geom, *, title, label, cmap, limits=None, lo=1.0, hi=99.0,
              floor=None, no_value=None):
    """One H×W float map with a colour bar labelled ``label`` and a no-value swatch.

    The axes are those of the full map; its pixels are block-averaged to those the panel
    shows (:func:`shown`). Colour ``limits`` (vmin, vmax, extend) default to the
    ``lo``–``hi`` percentiles of ``a`` and ``no_value`` (the share of pixels without a
    value) to that of ``a``: a caller that already has them passes them
    (:class:`~microfacet.report.context.Context` computes them once).
    """
    ax, box = image_axes(pg, cell, a.shape, geom)
    small, _ = shown(a, box)
    if limits is None:
        limits = colour_limits(a, lo, hi, floor=floor)
    if no_value is None:
        no_value = 1.0 - np.count_nonzero(np.isfinite(a)) / max(a.size, 1)
    vmin, vmax, extend = limits
    im = ax.imshow(small, cmap=colour_map(cmap), vmin=vmin, vmax=vmax, aspect="auto",
                   extent=geom.extent(a.shape))
    colourbar(pg, im, box, label, extend=extend, no_value=float(no_value))
    ax.set_title(title)
    geom.scale_bar(ax, a.shape)
    return ax


def category_panel(pg, cell, codes, geom, *, colours, names, title, label, no_value,
                   to_codes=None):
    """A map of small integer categories ``codes`` (−1 = no value) with a colour bar.

    One pixel per block of :func:`shown` is drawn (nearest: averaging would mix
    categories). With ``to_codes``, ``codes`` is any H×W map and ``to_codes`` turns the
    pixels drawn into categories, so that they are computed for those pixels only.
    """
    ax, box = image_axes(pg, cell, codes.shape, geom)
    block = display_block(codes.shape, box[2:], dpi=PDF_DPI)
    small = codes[::block, ::block]
    if to_codes is not None:
        small = to_codes(small)
    k = len(colours)
    cm = mcolors.ListedColormap(list(colours)).with_extremes(bad=NO_VALUE)
    data = np.ma.masked_less(small.astype(np.float32), -0.5)
    im = ax.imshow(data, cmap=cm, vmin=-0.5, vmax=k - 0.5, aspect="auto",
                   extent=geom.extent(codes.shape))
    colourbar(pg, im, box, label, ticks=list(range(k)), ticklabels=list(names),
              no_value=no_value)
    ax.set_title(title)
    geom.scale_bar(ax, codes.shape)
    return ax


# --------------------------------------------------------------------------- tables
def draw_table(pg, x, y_top, w, rows, *, header=None, col_widths=None, fontsize=8.0,
               row_h=0.205, title=None):
    """A table of strings whose top-left corner is at ``(x, y_top)`` inches; returns the
    y of its bottom edge.

    Drawn as figure texts and one line collection: matplotlib's ``Axes.table`` takes
    several times longer to draw.
    """
    if title:
        pg.text(x, y_top - 0.02, title, fontsize=10, fontweight="bold", va="top")
        y_top -= 0.27
    all_rows = ([list(header)] if header is not None else []) + [list(r) for r in rows]
    n = len(all_rows)
    if n == 0:
        return y_top
    ncol = max(len(r) for r in all_rows)
    cw = np.asarray(col_widths if col_widths is not None else [1.0] * ncol, float)
    cx = x + np.concatenate([[0.0], np.cumsum(cw / cw.sum() * w)])
    W, H = pg.W, pg.H
    if header is not None:
        pg.fig.add_artist(mpatches.Rectangle((x / W, (y_top - row_h) / H), w / W, row_h / H,
                                             facecolor="#e8eef7", edgecolor="none", zorder=0))
    segs = [[(x / W, (y_top - i * row_h) / H), ((x + w) / W, (y_top - i * row_h) / H)]
            for i in range(n + 1)]
    segs += [[(c / W, y_top / H), (c / W, (y_top - n * row_h) / H)] for c in cx]
    pg.fig.add_artist(mcollections.LineCollection(segs, colors="0.8", linewidths=0.5,
                                                  zorder=1))
    pad = 0.07
    for i, row in enumerate(all_rows):
        yc = y_top - (i + 0.5) * row_h
        is_head = header is not None and i == 0
        for j, cell in enumerate(row):
            if cell == "":
                continue
            pg.text(cx[j] + pad, yc, str(cell), fontsize=fontsize, va="center_baseline",
                    ha="left", fontweight="bold" if is_head else "normal",
                    color="0.25" if (j == 0 and not is_head) else "k")
    return y_top - n * row_h
