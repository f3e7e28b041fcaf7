"""The analysis report: a multi-page PDF (and PNGs) drawn from a results folder.

:func:`write_report` reads a results folder (``docs/results-format.md``) and
draws five A4-landscape pages, each with a header (stack name, analysis mode, optics, date,
microfacet version) and a footer (results folder, page number):

1. **overview** — the all-in-focus image, the height map (µm), the colour mask and two
   tables: the inputs (image size, pixel size, field of view, focal planes, NA) and what
   the mask removed, by reason;
2. **maps** — oxide thickness (nm), the thickness component of each pixel (seed Fig.
   18c), the ΔE00 of the colour inversion, facet tilt from colour (°), facet tilt from the
   height map (°, same colour scale) and the tilt's 1-σ uncertainty (°);
3. **distributions** — the thickness histogram with the fitted Gaussian mixture and each
   component (seed Fig. 18a); the per-pixel tilt histogram with the NDF mixture and its
   lobes (seed Fig. 19); the same NDF as D(θ) per steradian (log scale); the ΔE00
   histogram;
4. **parameters** — tables of the thickness components (weight, mean, SD), the NDF lobes
   (weight, slope SD as an angle, tan, Beckmann α), the analysis (mode, exposure, ΔE00,
   masking, optics, colour-table settings, ROIs) and the run (timings, versions);
5. **angular colour** — the colour predicted over in-plane light × view zenith angles
   from the fitted distributions: the microfacet thin-film BRDF (:mod:`microfacet.forward.angular`)
   and the half-vector model (seed §2.3), computed here (≈0.2 s).

Colour maps are perceptually uniform and sequential (no quantity drawn is signed); a
pixel without a value (masked by the colour mask, or NaN) is drawn in :data:`NO_VALUE`
grey on every map, and each map states its share of such pixels next to a grey swatch.

Only ``summary.json`` is required. A missing map or CSV skips its panel (the histograms
fall back to the maps, then to the fitted mixture alone) and is listed on page 4; a
mixture with an empty component list (no fit) is shown as "no fit". Maps larger than
:data:`MAX_MAP_PX` are block-averaged before drawing, so the PDF stays small.

Importing this module does not import matplotlib; :func:`write_report` does.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import math
import os
import re
import warnings
from pathlib import Path

import numpy as np
from ..colour.colorimetry import white_xyz

__all__ = ["MAX_MAP_PX", "NO_VALUE", "PAGES", "parameter_tables", "write_report"]

#: Page names, in order (also the PNG file names ``report_<n>_<name>.png``).
PAGES = ("overview", "maps", "distributions", "parameters", "angular")
#: Maps are block-averaged so that neither side exceeds this many pixels (map panels are
#: 2.2–3.3 inches wide: 512 pixels is over 150 per inch; larger maps only fatten the PDF).
MAX_MAP_PX = 512
#: Colour of a pixel without a value (masked or NaN) on every map.
NO_VALUE = "#a3a3a3"

_PAGE_IN = (11.69, 8.27)  # A4 landscape
_PDF_DPI = 150   # resolution of the images the PDF resamples (all-in-focus, angular maps)
_PNG_DPI = 110   # 1286 × 910 pixel page PNGs
_MARGIN_X = 0.45
_HEADER_IN = 0.82     # title, sub-title and a rule
_FOOTER_IN = 0.40
_RC = {
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
}
#: Mixture components, sorted by mean thickness / lobe width (blue, green, red as the
#: seed's Fig. 18c for thin, middle and thick).
_COMPONENT_COLOURS = ("#1f77b4", "#2ca02c", "#d62728", "#ff7f0e", "#8c564b", "#e377c2",
                      "#bcbd22", "#17becf", "#7f7f7f", "#9467bd")
_HEIGHT_TILT = "#7b3294"   # tilt from the height map, overlaid on the tilt histogram
_HIST_FILL, _HIST_EDGE = "#dcdcdc", "#8a8a8a"
_CMAPS = {"height": "plasma", "thickness": "viridis", "delta_e": "inferno",
          "tilt": "magma", "sigma": "inferno"}
_THICKNESS_CSV = ("thickness_nm", "density", "mixture_density")
_NDF_CSV = ("tilt_deg", "density", "mixture_density")
_ROI_CSV = ("row0", "col0", "size", "thickness_nm", "mean_delta_e", "n_pixels")
_DE = "ΔE₀₀"
#: The files a panel is drawn from (all optional; a missing one is listed on page 4).
_FILES = ("all_in_focus.png", "height_um.npy", "mask.npy", "thickness_nm.npy", "tilt_deg.npy",
          "tilt_sigma_deg.npy", "delta_e.npy", "tilt_height_deg.npy", "thickness_pdf.csv",
          "ndf_pdf.csv", "thickness_roi.csv")


# --------------------------------------------------------------------------- reading
class _Folder:
    """The files of one results folder, loaded on demand (None if absent)."""

    def __init__(self, path: Path):
        self.path = path
        f = path / "summary.json"
        if not f.is_file():
            raise FileNotFoundError(f"{f}: missing (required to write the report)")
        try:
            self.summary = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{f}: cannot read ({exc})") from None
        if not isinstance(self.summary, dict):
            raise ValueError(f"{f}: must hold a JSON object")
        self.summary_mtime = f.stat().st_mtime
        self._cache: dict = {}

    def _file(self, name):
        f = self.path / name
        return f if f.is_file() else None

    def array(self, name, *, ndim=2):
        """A ``.npy`` array (float32 unless bool), or None if the file is absent."""
        if name in self._cache:
            return self._cache[name]
        f = self._file(name)
        a = None
        if f is not None:
            try:
                a = np.load(f, allow_pickle=False)
            except (OSError, ValueError) as exc:
                raise ValueError(f"{f}: cannot read ({exc})") from None
            if a.ndim != ndim or min(a.shape) < 1:
                raise ValueError(f"{f}: expected a {ndim}-D array, got shape {a.shape}")
            if a.dtype != bool:
                if not np.issubdtype(a.dtype, np.number):
                    raise ValueError(f"{f}: expected numbers, got dtype {a.dtype}")
                a = a.astype(np.float32, copy=False)
        self._cache[name] = a
        return a

    def mask(self):
        """mask.npy as bool (True = masked), or None."""
        m = self.array("mask.npy")
        if m is not None and m.dtype != bool:
            m = m != 0
        return m

    def image(self, name):
        """A PNG as float RGB (or grey) in [0, 1], or None if the file is absent."""
        if name in self._cache:
            return self._cache[name]
        f = self._file(name)
        if f is None:
            return None
        import cv2

        img = cv2.imdecode(np.fromfile(f, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            raise ValueError(f"{f}: cannot read as an image")
        scale = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
        img = img.astype(np.float32) / scale
        if img.ndim == 3:
            img = img[..., 2::-1] if img.shape[2] >= 3 else img[..., 0]
        self._cache[name] = img = np.clip(img, 0.0, 1.0)
        return img

    def table(self, name, required):
        """A CSV as a dict of float columns, or None if the file is absent."""
        if name in self._cache:
            return self._cache[name]
        self._cache[name] = self._read_table(name, required)
        return self._cache[name]

    def _read_table(self, name, required):
        f = self._file(name)
        if f is None:
            return None
        try:
            with open(f, newline="", encoding="utf-8") as fh:
                rows = list(csv.reader(fh))
        except (OSError, UnicodeDecodeError) as exc:
            raise ValueError(f"{f}: cannot read ({exc})") from None
        if not rows:
            raise ValueError(f"{f}: empty (expected the header {','.join(required)})")
        head = [h.strip() for h in rows[0]]
        absent = [c for c in required if c not in head]
        if absent:
            raise ValueError(f"{f}: missing column(s) {', '.join(absent)}")
        out = {}
        for c in required:
            j = head.index(c)
            try:
                out[c] = np.array([float(r[j]) if r[j].strip() else np.nan
                                   for r in rows[1:] if r], dtype=np.float64)
            except (ValueError, IndexError):
                raise ValueError(f"{f}: column {c} holds a value that is not a number") \
                    from None
        return out

    def get(self, *keys):
        """``summary[k0][k1]...`` or None."""
        v = self.summary
        for k in keys:
            if not isinstance(v, dict) or k not in v:
                return None
            v = v[k]
        return v


def _number(v):
    """``float(v)`` if v is a finite real number (not bool), else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _mixtures(res: _Folder):
    """The fitted (ThicknessMixture | None, NDFMixture | None) from summary.json."""
    from ..core.distributions import NDFMixture, ThicknessMixture

    out = []
    for key, cls in (("thickness", ThicknessMixture), ("ndf", NDFMixture)):
        data = res.get(key, "mixture")
        if data is None or (isinstance(data, dict) and data.get("components") == []):
            out.append(None)  # no fit (the analysis writes an empty component list)
            continue
        try:
            out.append(cls.from_json(data))
        except (ValueError, TypeError, AttributeError) as exc:
            raise ValueError(f"{res.path / 'summary.json'}: {key}.mixture: {exc}") from None
    return tuple(out)


# --------------------------------------------------------------------------- small helpers
def _fmt(v, spec=".3g", unit=""):
    v = _number(v)
    if v is None:
        return "—"
    return f"{v:{spec}}" + ((unit if unit == "°" else f" {unit}") if unit else "")


def _pct(v):
    v = _number(v)
    return None if v is None else 100.0 * v


def _shorten(s, n):
    s = str(s)
    return s if len(s) <= n else "…" + s[-(n - 1):]


def _positive_or_none(v):
    v = _number(v)
    return v if v is not None and v > 0 else None


def _finite(a, mask=None):
    if a is None:
        return np.empty(0)
    v = a if mask is None or mask.shape != a.shape else np.where(mask, np.nan, a)
    v = np.asarray(v, dtype=np.float64).ravel()
    return v[np.isfinite(v)]


def _downsample(a, max_px=MAX_MAP_PX):
    """Block-average ``a`` (H×W or H×W×C; NaN-aware) so neither side exceeds ``max_px``.

    Returns the reduced array and the block size (1 if unchanged). A boolean array gives a
    boolean array (a block is True if at least half of it is).
    """
    h, w = a.shape[:2]
    f = math.ceil(max(h, w) / max_px)
    if f <= 1:
        return a, 1
    is_bool = a.dtype == bool
    x = a.astype(np.float32)
    H, W = math.ceil(h / f) * f, math.ceil(w / f) * f
    pad = [(0, H - h), (0, W - w)] + [(0, 0)] * (x.ndim - 2)
    x = np.pad(x, pad, constant_values=np.nan)
    x = x.reshape((H // f, f, W // f, f) + x.shape[2:])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN blocks stay NaN
        x = np.nanmean(x, axis=(1, 3))
    return (x >= 0.5 if is_bool else x), f


def _limits(values, lo=1.0, hi=99.0, *, floor=None):
    """Robust colour limits (percentiles of the finite values) and the colour-bar extend."""
    v = np.asarray(values, dtype=np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return 0.0, 1.0, "neither"
    vmin, vmax = np.percentile(v, [lo, hi])
    if floor is not None:
        vmin = max(floor, vmin) if lo > 0 else floor
    if not vmax > vmin:  # a constant map: a range of ±5 % (at least ±1) about it
        d = max(abs(vmin) * 0.05, 1.0)
        vmin, vmax = vmin - d, vmax + d
        if floor is not None and vmin < floor:
            vmin, vmax = floor, max(vmax, floor + d)
    below, above = v.min() < vmin, v.max() > vmax
    extend = {(True, True): "both", (True, False): "min", (False, True): "max"}.get(
        (bool(below), bool(above)), "neither")
    return float(vmin), float(vmax), extend


def _edges(centres):
    """Bin edges for a grid of bin centres (midpoints; the ends mirrored)."""
    x = np.asarray(centres, dtype=np.float64)
    if x.size == 1:
        return np.array([x[0] - 0.5, x[0] + 0.5])
    mid = 0.5 * (x[1:] + x[:-1])
    return np.concatenate([[2 * x[0] - mid[0]], mid, [2 * x[-1] - mid[-1]]])


def _histogram(values, lo=None, hi=None, *, bins=80):
    """(centres, density) of ``values`` or None if there are too few."""
    if values.size < 2:
        return None
    lo = float(np.min(values)) if lo is None else lo
    hi = float(np.max(values)) if hi is None else hi
    if not hi > lo:
        hi = lo + 1.0
    dens, e = np.histogram(values, bins=bins, range=(lo, hi), density=True)
    return 0.5 * (e[1:] + e[:-1]), dens


def _quantile_range(x, dens, q=(0.002, 0.998)):
    """The (low, high) quantiles of a density tabulated at bin centres ``x``."""
    d = np.nan_to_num(np.asarray(dens, dtype=np.float64)).clip(0)
    if x is None or d.sum() <= 0:
        return None
    c = np.cumsum(d) / d.sum()
    return float(x[min(np.searchsorted(c, q[0]), x.size - 1)]), \
        float(x[min(np.searchsorted(c, q[1]), x.size - 1)])


# --------------------------------------------------------------------------- layout
class _Page:
    """One A4-landscape figure laid out in inches (bottom-left origin), no layout engine.

    Fixed positions are an order of magnitude cheaper to draw than constrained layout
    and keep the pages of every report identical in structure.
    """

    def __init__(self, fig):
        self.fig = fig
        self.W, self.H = fig.get_size_inches()
        self.top = self.H - _HEADER_IN          # content area: [bottom, top] × [left, right]
        self.bottom = _FOOTER_IN
        self.left = _MARGIN_X
        self.right = self.W - _MARGIN_X

    def axes(self, x, y, w, h, **kw):
        return self.fig.add_axes((x / self.W, y / self.H, w / self.W, h / self.H), **kw)

    def text(self, x, y, s, **kw):
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


class _Geometry:
    """Axis units for the maps: µm if the pixel size is known, else pixels."""

    def __init__(self, pixel_size_um):
        self.px = pixel_size_um
        self.unit = "µm" if pixel_size_um else "pixel"

    def extent(self, shape, block=1):
        s = (self.px or 1.0) * block
        return (0.0, shape[1] * s, shape[0] * s, 0.0)

    def label(self, ax):
        ax.set_xlabel(f"x ({self.unit})", labelpad=2)
        ax.set_ylabel(f"y ({self.unit})", labelpad=2)


def _cmap(name):
    import matplotlib

    return matplotlib.colormaps[name].with_extremes(bad=NO_VALUE)


def _blank(pg, cell, text, title=None, shape=(1, 1)):
    """An empty panel saying why, where a map of ``shape`` would be."""
    ax, _ = _image_axes(pg, cell, shape)
    ax.set_axis_off()
    if title:
        ax.set_title(title)
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes,
            color="0.35", fontsize=9, wrap=True)
    return ax


_MAP_MARGINS = dict(left=0.55, right=0.86, top=0.30, bottom=0.50)


def _image_axes(pg, cell, shape):
    """Axes in ``cell`` whose box has exactly the image's aspect (so a colour bar beside it
    is as tall as the image), as large as the margins allow, centred."""
    x, y, w, h = cell
    m = _MAP_MARGINS
    aw, ah = w - m["left"] - m["right"], h - m["top"] - m["bottom"]
    r = shape[0] / shape[1]
    iw, ih = (aw, aw * r) if aw * r <= ah else (ah / r, ah)
    x0 = x + m["left"] + 0.5 * (aw - iw)
    y0 = y + m["bottom"] + 0.5 * (ah - ih)
    ax = pg.axes(x0, y0, iw, ih)
    for sp in ax.spines.values():
        sp.set_visible(True)
        sp.set_linewidth(0.6)
    return ax, (x0, y0, iw, ih)


def _colourbar(pg, im, box, label, *, extend="neither", ticks=None, ticklabels=None,
               no_value=None):
    """A colour bar right of the image ``box``; below it, if ``no_value`` is a fraction,
    a grey swatch saying what share of the map has no value."""
    x0, y0, iw, ih = box
    cax = pg.axes(x0 + iw + 0.08, y0, 0.13, ih)
    cb = pg.fig.colorbar(im, cax=cax, extend=extend, ticks=ticks)
    if ticklabels is not None:
        cb.ax.set_yticklabels(ticklabels)
    cb.set_label(label, labelpad=5)
    cb.ax.tick_params(labelsize=7.5)
    if no_value is not None:
        from matplotlib.patches import Rectangle

        pg.fig.add_artist(Rectangle(((x0 + iw + 0.08) / pg.W, (y0 - 0.34) / pg.H),
                                    0.13 / pg.W, 0.13 / pg.H, facecolor=NO_VALUE,
                                    edgecolor="0.5", linewidth=0.5))
        pg.text(x0 + iw + 0.26, y0 - 0.275, f"no value\n{100.0 * no_value:.1f} %",
                fontsize=7, va="center", ha="left", color="0.25", linespacing=1.0)
    return cb


def _map_panel(pg, cell, a, geom, *, title, label, cmap, limits=None, lo=1.0, hi=99.0,
               floor=None):
    """One H×W float map with a colour bar labelled ``label`` and a no-value swatch."""
    small, block = _downsample(a)
    vmin, vmax, extend = limits if limits is not None else _limits(a, lo, hi, floor=floor)
    ax, box = _image_axes(pg, cell, small.shape)
    im = ax.imshow(small, cmap=_cmap(cmap), vmin=vmin, vmax=vmax, aspect="auto",
                   extent=geom.extent(small.shape, block))
    _colourbar(pg, im, box, label, extend=extend,
               no_value=float(np.mean(~np.isfinite(a))))
    ax.set_title(title)
    geom.label(ax)
    return ax


def _category_panel(pg, cell, codes, geom, *, colours, names, title, label, no_value):
    """A map of small integer categories ``codes`` (−1 = no value) with a colour bar."""
    import matplotlib.colors as mcolors

    block = max(1, math.ceil(max(codes.shape) / MAX_MAP_PX))
    small = codes[::block, ::block]  # nearest: averaging would mix categories
    k = len(colours)
    cm = mcolors.ListedColormap(list(colours)).with_extremes(bad=NO_VALUE)
    ax, box = _image_axes(pg, cell, small.shape)
    data = np.ma.masked_less(small.astype(np.float32), -0.5)
    im = ax.imshow(data, cmap=cm, vmin=-0.5, vmax=k - 0.5, aspect="auto",
                   extent=geom.extent(small.shape, block))
    _colourbar(pg, im, box, label, ticks=list(range(k)), ticklabels=list(names),
               no_value=no_value)
    ax.set_title(title)
    geom.label(ax)
    return ax


def _legend_room(ax, n_entries, *, frac_per_entry=0.075, base=1.06, top=None):
    """Raise the y limit so a legend of ``n_entries`` in the upper right covers no data
    (``top``: the highest value to show, default the data's)."""
    if top is None:
        ax.relim()
        ax.autoscale_view()
        top = ax.dataLim.y1
    top = top if np.isfinite(top) and top > 0 else 1.0
    ax.set_ylim(0.0, top * (base + frac_per_entry * n_entries))


def _clip_top(ax, x, dens, curves=()):
    """The y to show: all of the curves, and the histogram unless a few bins are spikes
    (over 4× the 90th percentile of the bins), which are then cut and their height
    written next to them. Returns None for "all of the data"."""
    if x is None or not np.size(x):
        return None
    d = np.nan_to_num(np.asarray(dens, dtype=np.float64))
    pos = d[d > 0]
    if pos.size < 5:
        return None
    ref = max(4.0 * float(np.percentile(pos, 90)),
              max((float(np.nanmax(c)) for c in curves if np.size(c)), default=0.0) * 1.1)
    if d.max() <= ref * 1.05:
        return None
    for j in np.flatnonzero(d > ref)[:3]:
        ax.annotate(f"↑ {d[j]:.3g}", (x[j], ref), xytext=(4, -2), textcoords="offset points",
                    fontsize=7, color="0.25", va="top", ha="left")
    return ref


def _table(pg, x, y_top, w, rows, *, header=None, col_widths=None, fontsize=8.0,
           row_h=0.205, title=None):
    """A table of strings whose top-left corner is at ``(x, y_top)`` inches; returns the
    y of its bottom edge.

    Drawn as figure texts and one line collection: matplotlib's ``Axes.table`` takes
    several times longer to draw.
    """
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Rectangle

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
        pg.fig.add_artist(Rectangle((x / W, (y_top - row_h) / H), w / W, row_h / H,
                                    facecolor="#e8eef7", edgecolor="none", zorder=0))
    segs = [[(x / W, (y_top - i * row_h) / H), ((x + w) / W, (y_top - i * row_h) / H)]
            for i in range(n + 1)]
    segs += [[(c / W, y_top / H), (c / W, (y_top - n * row_h) / H)] for c in cx]
    pg.fig.add_artist(LineCollection(segs, colors="0.8", linewidths=0.5, zorder=1))
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


# --------------------------------------------------------------------------- context
class _Context:
    """What every page needs: the folder, the fits, the geometry, the page's style."""

    def __init__(self, res, thick_mix, ndf_mix):
        self.res = res
        self.thick = thick_mix
        self.ndf = ndf_mix
        self.geom = _Geometry(_positive_or_none(res.get("inputs", "pixel_size_um")))
        self.mask = res.mask()

    def max_tilt(self):
        """The largest measurable tilt (asin(NA)/2), degrees, or None."""
        v = _positive_or_none(self.res.get("ndf", "max_tilt_deg"))
        if v is None:
            na = _positive_or_none(self.res.get("inputs", "numerical_aperture"))
            if na is not None and na <= 1:
                v = math.degrees(math.asin(na)) / 2.0
        return v


# --------------------------------------------------------------------------- page 1
def _page_overview(pg, ctx):
    res, geom = ctx.res, ctx.geom
    aif = res.image("all_in_focus.png")
    height = res.array("height_um.npy")
    mask, mask_note = ctx.mask, ""
    if mask is None:
        th = res.array("thickness_nm.npy")
        if th is not None:
            mask, mask_note = ~np.isfinite(th), " (no thickness)"
    # two large maps on top; the mask and two tables below
    bottom_h = 3.0
    top_cells = pg.grid(1, 2, bottom=pg.bottom + bottom_h)
    low = pg.grid(1, 3, top=pg.bottom + bottom_h, widths=[3.45, 3.9, 3.45], hgap=0.0)
    cells = [top_cells[0], top_cells[1], low[0]]
    # ---- maps
    if aif is not None:
        small, block = _downsample(aif)
        ax, box = _image_axes(pg, cells[0], small.shape)
        ax.imshow(small, cmap="gray" if small.ndim == 2 else None, vmin=0, vmax=1,
                  aspect="auto", extent=geom.extent(small.shape, block),
                  interpolation="antialiased")
        ax.set_title("all-in-focus image")
        geom.label(ax)
    else:
        _blank(pg, cells[0], "all_in_focus.png is not in the folder", "all-in-focus image")
    if height is not None:
        _map_panel(pg, cells[1], height, geom, title="height from focus",
                   label="height (µm)", cmap=_CMAPS["height"])
    else:
        _blank(pg, cells[1], "height_um.npy is not in the folder", "height from focus")
    if mask is not None:
        frac = float(np.mean(mask))
        _category_panel(pg, cells[2], mask.astype(np.int8), geom, colours=("#f3f3f3",
                        NO_VALUE), names=("used", "masked"), label="",
                        title=f"colour mask{mask_note}: {100 * frac:.1f} % masked",
                        no_value=None)
    else:
        _blank(pg, cells[2], "mask.npy is not in the folder", "colour mask")
    # ---- tables
    x, y, w, h = low[1]
    top = y + h - 0.25
    _table(pg, x, top, w - 0.2, _input_rows(ctx), col_widths=[0.36, 0.64],
           title="inputs", fontsize=8.0)
    x, y, w, h = low[2]
    _table(pg, x + 0.05, top, w - 0.05, _mask_rows(ctx), col_widths=[0.66, 0.34],
           title="masked pixels (reasons overlap)", fontsize=8.0)


def _input_rows(ctx):
    res, geom = ctx.res, ctx.geom
    shape = None
    for a in (res.array("height_um.npy"), ctx.mask, res.array("thickness_nm.npy")):
        if a is not None:
            shape = a.shape[:2]
            break
    if shape is None:
        s = res.get("inputs", "shape")
        if isinstance(s, list) and len(s) >= 2 and all(_number(v) for v in s[:2]):
            shape = (int(s[0]), int(s[1]))
    inputs = res.get("inputs") if isinstance(res.get("inputs"), dict) else {}
    stack = inputs.get("stack") or inputs.get("stack_path") or inputs.get("path")
    rows = []
    if stack:
        rows.append(["stack", _shorten(stack, 38)])
    rows += [
        ["image size", f"{shape[1]} × {shape[0]} pixels" if shape else "—"],
        ["pixel size", _fmt(geom.px, ".4g", "µm") if geom.px else "unknown (axes in pixels)"],
        ["field of view", (f"{shape[1] * geom.px:.4g} × {shape[0] * geom.px:.4g} µm"
                           if shape and geom.px else "—")],
    ]
    z = inputs.get("z_um_range")
    n = inputs.get("n_slices")
    if n is not None or z is not None:
        zs = (f", z {z[0]:.3g} to {z[1]:.3g} µm" if isinstance(z, list) and len(z) == 2
              and all(_number(v) is not None for v in z) else "")
        rows.append(["focal planes", f"{_fmt(n, '.0f')}{zs}"])
    na = _number(inputs.get("numerical_aperture"))
    if na is not None:
        mt = ctx.max_tilt()
        rows.append(["numerical aperture", f"{na:.3g}" + (
            f" (tilt ≤ asin(NA)/2 = {mt:.1f}°)" if mt else "")])
    rows.append(["height, 1–99 %", _range_text(res.array("height_um.npy"), "µm")])
    return rows


def _mask_rows(ctx):
    res = ctx.res
    rows = [["masked (any reason)", _fmt(_pct(res.get("masked_fraction")), ".1f", "%")]]
    m = res.get("mask")
    if isinstance(m, dict):
        for k, name in (("low_saturation", "low saturation"), ("dark", "dark"),
                        ("clipped", "clipped (over-exposed)"), ("shadow", "shadow"),
                        ("invalid", "invalid (NaN)")):
            if k in m:
                rows.append([f"   {name}", _fmt(_pct(m[k]), ".1f", "%")])
    p = res.get("parameters")
    if isinstance(p, dict) and ("saturation_min" in p or "value_min" in p):
        rows.append(["thresholds (0–255 HSV)", f"S ≥ {_fmt(p.get('saturation_min'), '.4g')}, "
                                               f"V ≥ {_fmt(p.get('value_min'), '.4g')}"])
    uf = res.get("height", "unreliable_fraction")
    if uf is not None:
        rows.append(["height unreliable (no focus)", _fmt(_pct(uf), ".1f", "%")])
    return rows


def _range_text(a, unit):
    v = _finite(a)
    if v.size == 0:
        return "—"
    lo, hi = np.percentile(v, [1, 99])
    return f"{lo:.4g} to {hi:.4g} {unit}"


# --------------------------------------------------------------------------- page 2
def _component_codes(thickness, mix):
    """Index of the most probable mixture component of each pixel (−1 where NaN)."""
    codes = np.full(thickness.shape, -1, np.int8)
    ok = np.isfinite(thickness)
    if not ok.any():
        return codes
    d = thickness[ok].astype(np.float64)[:, None]
    w, m, s = mix.weights, mix.means_nm, mix.sds_nm
    logp = np.log(w) - np.log(s) - 0.5 * ((d - m) / s) ** 2
    codes[ok] = np.argmax(logp, axis=1)
    return codes


def _page_maps(pg, ctx):
    res, geom = ctx.res, ctx.geom
    thick = res.array("thickness_nm.npy")
    de = res.array("delta_e.npy")
    tilt = res.array("tilt_deg.npy")
    sig = res.array("tilt_sigma_deg.npy")
    tilt_h = res.array("tilt_height_deg.npy")
    cells = pg.grid(2, 3, vgap=0.15)
    shape = next((a.shape for a in (thick, de, tilt, sig, tilt_h) if a is not None), (1, 1))
    # one colour scale for both tilt maps, so they can be compared
    tilt_lim = _limits(np.concatenate([_finite(tilt), _finite(tilt_h)]), 0.0, 99.0, floor=0.0)
    if thick is not None:
        _map_panel(pg, cells[0], thick, geom, title="oxide thickness",
                   label="thickness (nm)", cmap=_CMAPS["thickness"])
    else:
        _blank(pg, cells[0], "thickness_nm.npy is not in the folder", "oxide thickness",
               shape=shape)
    if thick is not None and ctx.thick is not None:
        k = len(ctx.thick.components)
        codes = _component_codes(thick, ctx.thick)
        names = [f"{i + 1}: {c[1]:.0f} nm" for i, c in enumerate(ctx.thick.components)]
        _category_panel(pg, cells[1], codes, geom,
                        title="thickness component (seed Fig. 18c)",
                        colours=[_COMPONENT_COLOURS[i % len(_COMPONENT_COLOURS)]
                                 for i in range(k)], names=names,
                        label="",
                        no_value=float(np.mean(codes < 0)))
    else:
        _blank(pg, cells[1], "no fitted thickness mixture", "thickness component", shape=shape)
    if de is not None:
        _map_panel(pg, cells[2], de, geom, title="colour difference of the fit",
                   label=f"{_DE} (CIEDE2000)", cmap=_CMAPS["delta_e"], lo=0.0, floor=0.0)
    else:
        _blank(pg, cells[2], "delta_e.npy is not in the folder", "colour difference", shape=shape)
    if tilt is not None:
        _map_panel(pg, cells[3], tilt, geom, title="facet tilt from colour",
                   label="tilt from optical axis (°)", cmap=_CMAPS["tilt"], limits=tilt_lim)
    else:
        _blank(pg, cells[3], "tilt_deg.npy is not in the folder", "facet tilt from colour",
               shape=shape)
    if tilt_h is not None:
        _map_panel(pg, cells[4], tilt_h, geom, title="facet tilt from the height map",
                   label="tilt from optical axis (°)", cmap=_CMAPS["tilt"], limits=tilt_lim)
    else:
        _blank(pg, cells[4], "tilt_height_deg.npy is not in the folder",
               "facet tilt from the height map", shape=shape)
    if sig is not None:
        _map_panel(pg, cells[5], sig, geom, title="tilt uncertainty (1σ)",
                   label="tilt 1σ (°)", cmap=_CMAPS["sigma"], lo=0.0, floor=0.0)
    else:
        _blank(pg, cells[5], "tilt_sigma_deg.npy is not in the folder", "tilt uncertainty",
               shape=shape)


# --------------------------------------------------------------------------- page 3
def _hist_axes(pg, cell):
    x, y, w, h = cell
    return pg.axes(x + 0.72, y + 0.48, w - 0.72 - 0.12, h - 0.48 - 0.30)


def _page_distributions(pg, ctx):
    res, mask = ctx.res, ctx.mask
    cells = pg.grid(2, 2, hgap=0.25, vgap=0.10, heights=[1.25, 1.0])
    ax_t, ax_n, ax_d, ax_e = (_hist_axes(pg, c) for c in cells)

    # ---- thickness (seed Fig. 18a)
    csv_t = res.table("thickness_pdf.csv", _THICKNESS_CSV)
    if csv_t is not None and csv_t["thickness_nm"].size:
        x, dens, mixd = csv_t["thickness_nm"], csv_t["density"], csv_t["mixture_density"]
        src = "thickness_pdf.csv"
    else:
        lo_hi = ctx.thick.support_nm() if ctx.thick is not None else (None, None)
        h = _histogram(_finite(res.array("thickness_nm.npy"), mask), *lo_hi)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "thickness_nm.npy"
    rng = _quantile_range(x, dens) if x is not None else None
    if ctx.thick is not None:
        s_lo, s_hi = ctx.thick.support_nm()
        rng = (min(rng[0], s_lo), max(rng[1], s_hi)) if rng else (s_lo, s_hi)
    if rng is not None:
        pad = max(0.06 * (rng[1] - rng[0]), 2.0)
        rng = (max(0.0, rng[0] - pad), rng[1] + pad)
    n = _density_panel(
        ax_t, x, dens, mixd, ctx.thick, src=src, unit="nm", what="oxide thickness",
        comp_pdf=lambda m, g: m.pdf(g),
        comp_label=lambda c: f"weight {c[0]:.2f}, mean {c[1]:.1f} nm, SD {c[2]:.2f} nm",
        xrange=rng or (0.0, 1.0))
    roi = res.table("thickness_roi.csv", _ROI_CSV)
    roi_t = roi["thickness_nm"][np.isfinite(roi["thickness_nm"])] if roi is not None else None
    if roi_t is not None and roi_t.size:
        ax_t.plot(roi_t, np.full(roi_t.shape, 0.0), ls="none", marker="^", ms=6, mew=0.6,
                  mfc="white", mec="k", transform=ax_t.get_xaxis_transform(), clip_on=False,
                  zorder=5, label=f"ROI thickness ({roi_t.size} ROI{'s' * (roi_t.size > 1)})")
        n += 1
    _legend_room(ax_t, n, top=_clip_top(ax_t, x, dens, _curves(ax_t, x)))
    _legend(ax_t, x, dens)
    ax_t.set_title("oxide thickness distribution (seed Fig. 18a)")

    # ---- facet tilt / NDF (seed Fig. 19)
    csv_n = res.table("ndf_pdf.csv", _NDF_CSV)
    tilt_h = _finite(res.array("tilt_height_deg.npy"), mask)
    mt = ctx.max_tilt()
    hi = mt or (float(min(89.0, 4.0 * ctx.ndf.sds_deg.max())) if ctx.ndf is not None
                else 30.0)
    if csv_n is not None and csv_n["tilt_deg"].size:
        x, dens, mixd = csv_n["tilt_deg"], csv_n["density"], csv_n["mixture_density"]
        src = "ndf_pdf.csv"
    else:
        h = _histogram(_finite(res.array("tilt_deg.npy"), mask), 0.0, hi, bins=60)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "tilt_deg.npy"
    top = float(_edges(x)[-1]) if x is not None and np.size(x) else hi
    n = _density_panel(
        ax_n, x, dens, mixd, ctx.ndf, src=src, unit="°", what="facet tilt from optical axis",
        comp_pdf=lambda m, g: m.tilt_pdf(g),
        comp_label=lambda c: (f"weight {c[0]:.2f}, slope SD {c[1]:.2f}° "
                              f"(tan {math.tan(math.radians(c[1])):.3f})"),
        xrange=(0.0, max(top, hi if x is None else top)))
    if tilt_h.size >= 2:
        lo, top = ax_n.get_xlim()
        d, e = np.histogram(tilt_h, bins=60, range=(max(0.0, lo), top), density=True)
        ax_n.stairs(d, e, color=_HEIGHT_TILT, lw=1.0,
                    label="tilt from the height map (histogram)")
        n += 1
    if mt:
        ax_n.axvline(mt, color="0.3", lw=0.8, ls=":",
                     label=f"measurable limit asin(NA)/2 = {mt:.1f}°")
        n += 1
    _legend_room(ax_n, n, top=_clip_top(ax_n, x, dens, _curves(ax_n, x)))
    _legend(ax_n, x, dens)
    ax_n.set_title("facet tilt distribution, per pixel (seed Fig. 19)")

    # ---- NDF D(θ) per steradian, log scale
    _ndf_panel(ax_d, x, dens, ctx.ndf, hi=float(ax_n.get_xlim()[1]))

    # ---- ΔE00
    _delta_e_panel(ax_e, res, mask)


def _curves(ax, x):
    """The y data of the lines drawn in ``ax`` (mixture and components) beyond the second
    histogram bin ``x[1]``: a lobe narrower than a bin is a spike like the bin's."""
    out = []
    if x is None or np.size(x) < 2:
        return out
    for ln in ax.get_lines():
        xd = np.asarray(ln.get_xdata(), dtype=np.float64)
        y = np.asarray(ln.get_ydata(), dtype=np.float64)
        if xd.shape != y.shape:
            continue
        y = y[(xd > x[1]) & np.isfinite(y)]
        if y.size:
            out.append(y)
    return out


def _density_panel(ax, x, dens, mixd, mix, *, src, unit, what, comp_pdf, comp_label,
                   xrange):
    """Histogram density (grey), each component (coloured, filled lightly) and the fitted
    mixture (black); returns the number of legend entries."""
    n = 0
    lo, hi = xrange
    if x is not None and np.size(x):
        e = _edges(x)
        if e[0] < 0 <= x[0]:
            e[0] = 0.0
        d = np.nan_to_num(np.asarray(dens, dtype=np.float64))
        ax.stairs(d, e, fill=True, color=_HIST_FILL, label=f"histogram ({src})")
        ax.stairs(d, e, color=_HIST_EDGE, lw=0.6)
        n += 1
    grid = np.linspace(lo, hi, 600)
    if mix is not None:
        from ..core.distributions import NDFMixture, ThicknessMixture

        single = ThicknessMixture if isinstance(mix, ThicknessMixture) else NDFMixture
        for i, c in enumerate(mix.components):
            g = c[0] * comp_pdf(single([(1.0,) + tuple(c[1:])]), grid)
            colour = _COMPONENT_COLOURS[i % len(_COMPONENT_COLOURS)]
            ax.fill_between(grid, g, color=colour, alpha=0.12, lw=0)
            ax.plot(grid, g, lw=1.5, color=colour, label=f"{i + 1}: {comp_label(c)}")
            n += 1
    if mixd is not None and np.any(np.isfinite(mixd)):
        ax.plot(x, mixd, color="k", lw=1.3, ls=(0, (4, 1.5)), label="fitted mixture (sum)")
        n += 1
    elif mix is not None:
        ax.plot(grid, comp_pdf(mix, grid), color="k", lw=1.3, ls=(0, (4, 1.5)),
                label="fitted mixture (sum)")
        n += 1
    if n == 0:
        ax.text(0.5, 0.5, "no histogram and no fitted mixture", ha="center", va="center",
                transform=ax.transAxes, color="0.35")
    elif mix is None:
        ax.plot([], [], ls="none", label="no mixture fitted")
        n += 1
    ax.set_xlim(lo, hi)
    ax.set_xlabel(f"{what} ({unit})")
    ax.set_ylabel(f"probability density (1/{unit})")
    return n


def _legend(ax, x=None, dens=None):
    """Legend in the upper corner above less of the histogram ``(x, dens)`` (right if
    none), on a white ground so lines under it do not cross its text."""
    if not ax.get_legend_handles_labels()[1]:
        return
    loc = "upper right"
    if x is not None and np.size(x) > 4:
        lo, hi = ax.get_xlim()
        d = np.nan_to_num(np.asarray(dens, dtype=np.float64))
        xs = np.asarray(x, dtype=np.float64)
        left = d[(xs >= lo) & (xs < lo + 0.45 * (hi - lo))]
        right = d[(xs <= hi) & (xs > hi - 0.45 * (hi - lo))]
        if left.size and right.size and left.max() < 0.7 * right.max():
            loc = "upper left"
    leg = ax.legend(loc=loc, frameon=True, handlelength=1.8, borderaxespad=0.3,
                    labelspacing=0.35, fancybox=False, framealpha=0.85, borderpad=0.3)
    leg.get_frame().set_linewidth(0)


def _ndf_panel(ax, x, dens, mix, *, hi):
    """D(θ) per steradian (∫ D cos θ dω = 1) on a log scale: the NDF as the seed's Fig. 19
    draws it (mode at 0°); the histogram is divided by 2π sin θ cos θ."""
    ax.set_title("facet normal distribution D(θ)")
    n = 0
    top, bottoms = [], []
    if x is not None and np.size(x):
        e = _edges(x)
        e[0] = max(e[0], 0.0)
        th = np.radians(np.asarray(x, dtype=np.float64))
        with np.errstate(divide="ignore", invalid="ignore"):
            Dh = np.asarray(dens, np.float64) * (180.0 / math.pi) / (
                2 * math.pi * np.sin(th) * np.cos(th))
        Dh = np.where(np.isfinite(Dh) & (Dh > 0), Dh, np.nan)
        if np.isfinite(Dh).any():
            ax.stairs(Dh, e, color=_HIST_EDGE, lw=0.9, label="from the tilt histogram")
            top.append(np.nanmax(Dh))
            bottoms.append(np.nanpercentile(Dh, 5))
            n += 1
    grid = np.linspace(0.0, hi, 400)
    if mix is not None:
        from ..core.distributions import NDFMixture

        for i, c in enumerate(mix.components):
            colour = _COMPONENT_COLOURS[i % len(_COMPONENT_COLOURS)]
            ax.plot(grid, c[0] * NDFMixture([(1.0, c[1])]).D(grid), color=colour, lw=1.5,
                    label=f"lobe {i + 1}: Beckmann α {mix.beckmann_alpha[i]:.3f}")
            n += 1
        Dm = mix.D(grid)
        ax.plot(grid, Dm, color="k", lw=1.3, ls=(0, (4, 1.5)), label="fitted NDF (sum)")
        top.append(float(Dm.max()))
        bottoms.append(float(Dm.min()))
        n += 1
    ax.set_xlim(0.0, hi)
    ax.set_xlabel("facet tilt θ from optical axis (°)")
    ax.set_ylabel("D(θ) (1/sr)")
    if top:
        # from below the smallest value of the fitted NDF (or the histogram) in range, to
        # above the largest, at most 10 decades
        t = max(top)
        lows = [v for v in bottoms if np.isfinite(v) and v > 0]
        b = max(min(lows) / 3.0 if lows else t * 1e-4, t * 1e-10)
        ax.set_yscale("log")
        ax.set_ylim(b, t * 10 ** (0.12 * n + 0.3) if n else t * 3)
        _legend(ax)
    else:
        ax.text(0.5, 0.5, "no tilt histogram and no fitted NDF", ha="center", va="center",
                transform=ax.transAxes, color="0.35")


def _delta_e_panel(ax, res, mask):
    ax.set_title("colour difference of the fit, per pixel")
    v = _finite(res.array("delta_e.npy"), mask)
    ax.set_xlabel(f"{_DE} (CIEDE2000) between pixel and model colour")
    ax.set_ylabel(f"fraction of pixels per unit {_DE}")
    if v.size < 2:
        ax.text(0.5, 0.5, "no ΔE₀₀ values (delta_e.npy absent or all masked)",
                ha="center", va="center", transform=ax.transAxes, color="0.35")
        return
    hi = max(float(np.percentile(v, 99.0)), 1.0)
    d, e = np.histogram(v, bins=80, range=(0.0, hi), density=True)
    ax.stairs(d, e, fill=True, color=_HIST_FILL, label="histogram (delta_e.npy, 0–99 %)")
    ax.stairs(d, e, color=_HIST_EDGE, lw=0.6)
    mean = _number(res.get("delta_e", "mean"))
    med = _number(res.get("delta_e", "median"))
    mean = float(v.mean()) if mean is None else mean
    med = float(np.median(v)) if med is None else med
    ax.axvline(mean, color="#d62728", lw=1.2, label=f"mean {mean:.2f}")
    ax.axvline(med, color="#1f77b4", lw=1.2, ls="--", label=f"median {med:.2f}")
    p95 = _number(res.get("delta_e", "p95"))
    if p95 is not None and p95 <= hi:
        ax.axvline(p95, color="0.3", lw=1.0, ls=":", label=f"95th percentile {p95:.2f}")
    ax.set_xlim(0.0, hi)
    _legend_room(ax, 4)
    _legend(ax, 0.5 * (e[1:] + e[:-1]), d)


# --------------------------------------------------------------------------- page 4
def parameter_tables(results_dir) -> dict:
    """The tables of the report's parameter page, as lists of rows of strings.

    Returns
    -------
    dict
        ``"thickness"`` (header ``component, weight, mean (nm), SD (nm)``), ``"ndf"``
        (``lobe, weight, slope SD (°), tan(slope SD), Beckmann α``), ``"analysis"`` and
        ``"run"`` (``quantity, value`` pairs: versions, missing files), ``"timings"``
        (``step, time``), each ``{"header": [...], "rows": [[...]]}``.
        Numbers are formatted as printed: weights with 3 decimals, thickness mean with
        1 and SD with 2 (nm), lobe SD with 2 (°).

    Examples
    --------
    >>> parameter_tables("results/sample1")["thickness"]["rows"][0]  # doctest: +SKIP
    ['1', '0.085', '108.0', '1.28']
    """
    res = _Folder(Path(results_dir))
    thick, ndf = _mixtures(res)
    return _tables(_Context(res, thick, ndf))


def _tables(ctx) -> dict:
    res = ctx.res
    out = {}
    rows = []
    if ctx.thick is not None:
        for i, (w, m, s) in enumerate(ctx.thick.components):
            rows.append([f"{i + 1}", f"{w:.3f}", f"{m:.1f}", f"{s:.2f}"])
    out["thickness"] = {"header": ["component", "weight", "mean (nm)", "SD (nm)"],
                        "rows": rows, "note": _fit_note(res, "thickness", ctx.thick)}
    rows = []
    if ctx.ndf is not None:
        for i, (w, s) in enumerate(ctx.ndf.components):
            rows.append([f"{i + 1}", f"{w:.3f}", f"{s:.2f}",
                         f"{math.tan(math.radians(s)):.4f}",
                         f"{math.sqrt(2.0) * math.tan(math.radians(s)):.4f}"])
    out["ndf"] = {"header": ["lobe", "weight", "slope SD σ (°)", "tan σ", "Beckmann α"],
                  "rows": rows, "note": _fit_note(res, "ndf", ctx.ndf)}
    out["analysis"] = {"header": ["quantity", "value"], "rows": _analysis_rows(ctx)}
    out["run"] = {"header": ["quantity", "value"], "rows": _run_rows(ctx)}
    out["timings"] = {"header": ["step", "time"], "rows": _timing_rows(ctx)}
    return out


def _fit_note(res, key, mix):
    m = res.get(key, "mixture")
    if mix is None:
        return ("no fit (no usable pixels)" if isinstance(m, dict) else
                "no mixture in summary.json")
    parts = []
    bic = _number(res.get(key, "mixture", "bic"))
    k = len(mix.components)
    by_k = res.get(key, "mixture", "bic_by_k")
    if bic is not None:
        tried = ""
        if isinstance(by_k, dict) and by_k:
            tried = (f"; k = 1–{len(by_k)} tried" if len(by_k) > 1 else "; only k = 1 tried")
        parts.append(f"{k} component{'s' * (k > 1)} by BIC ({bic:.6g}{tried})")
    ne, ns = _number(res.get(key, "mixture", "n_effective")), \
        _number(res.get(key, "mixture", "n_samples"))
    if ns is not None:
        parts.append(f"{ns:.0f} pixels" + (f", {ne:.0f} effective samples"
                                           if ne is not None else ""))
    d = res.get(key, "mixture", "degenerate")
    if d is True:
        parts.append("degenerate fit")
    elif isinstance(d, str) and d:
        parts.append(d)
    return "; ".join(parts)


def _analysis_rows(ctx):
    res = ctx.res
    s = res.summary
    p = res.get("parameters") if isinstance(res.get("parameters"), dict) else {}
    inputs = res.get("inputs") if isinstance(res.get("inputs"), dict) else {}
    rows = []
    mode = s.get("mode") or p.get("mode")
    if mode:
        rows.append(["mode", str(mode) + {"joint": " (facet planes + colour)",
                                          "seed": " (the paper's ROI method)"}.get(mode, "")])
    for key in ("film", "substrate", "illuminant"):
        v = s.get(key) or inputs.get(key)
        if v:
            rows.append([key, _shorten(v, 40)])
    src = s.get("exposure_source")
    rows.append(["exposure", _fmt(s.get("exposure"), ".4g") + (f" ({src})" if src else "")])
    rows.append([f"{_DE} mean / median / p95",
                 " / ".join(_fmt(res.get("delta_e", k), ".2f")
                            for k in ("mean", "median", "p95"))])
    if "colour_noise_de" in s:
        rows.append([f"image colour noise ({_DE})", _fmt(s.get("colour_noise_de"), ".2f")])
    rows.append(["masked fraction", _fmt(_pct(s.get("masked_fraction")), ".1f", "%")])
    mt = ctx.max_tilt()
    if mt:
        rows.append(["largest measurable tilt", f"{mt:.1f}°"])
    ti = res.get("tilt_information")
    if isinstance(ti, dict):
        rows.append(["tilt 1σ, median", _fmt(ti.get("tilt_sigma_deg_median"), ".2f", "°")])
        cd = _pct(ti.get("colour_dominated_fraction"))
        if cd is not None:
            rows.append(["pixels whose tilt is set by colour", f"{cd:.1f} %"])
    roi = res.get("thickness", "roi")
    if isinstance(roi, dict):
        rows.append(["ROIs fitted / total",
                     f"{_fmt(roi.get('fitted'), '.0f')} / {_fmt(roi.get('count'), '.0f')}"
                     + (f", mean {_fmt(roi.get('thickness_nm_mean'), '.1f', 'nm')}"
                        if _number(roi.get("thickness_nm_mean")) is not None else "")
                     + (f", {roi['ambiguous_count']} ambiguous"
                        if _number(roi.get("ambiguous_count")) else "")])
    if p:
        if "roi_size_px" in p:
            rows.append(["ROI size", f"{_fmt(p.get('roi_size_px'), '.0f')} px"])
        tr = p.get("thickness_range_nm")
        if isinstance(tr, list) and len(tr) == 2:
            rows.append(["thickness search range", f"{_fmt(tr[0], 'g')}–{_fmt(tr[1], 'g')} nm"])
        if mode == "joint" and "facet_size_um" in p:
            rows.append(["facet size (segmentation)", _fmt(p.get("facet_size_um"), ".3g",
                                                           "µm")])
        if "tilt_step_deg" in p:
            rows.append(["tilt search step", _fmt(p.get("tilt_step_deg"), ".3g", "°")])
        if "max_components" in p:
            rows.append(["largest k tried (BIC)", _fmt(p.get("max_components"), ".0f")])
    ct = res.get("colour_table")
    if isinstance(ct, dict):
        rows.append(["colour table: steps",
                     f"{_fmt(ct.get('thickness_step_nm'), '.3g', 'nm')} thickness, "
                     f"{_fmt(ct.get('theta_step_deg'), '.3g', '°')} tilt, "
                     f"{_fmt(ct.get('spectral_step_nm'), '.3g', 'nm')} wavelength"])
        rows.append([f"colour table: error ({_DE})",
                     f"{_fmt(ct.get('interp_error_de00'), '.3f')} interpolation, "
                     f"{_fmt(ct.get('spectral_error_de00'), '.3f')} spectral"])
    return rows


_STEP_NAMES = {"height_from_focus": "height from focus", "colour_and_mask": "colour and mask",
               "thickness_roi": "thickness per ROI", "tilt_per_pixel": "tilt per pixel",
               "facet_fits": "facet fits", "mixtures": "mixture fits",
               "write": "writing the results"}


def _timing_rows(ctx):
    """[[step, "x.xx s"]] from summary.json's timings_s, the total last."""
    timings = ctx.res.get("timings_s")
    if not isinstance(timings, dict):
        return []
    rows = [[_STEP_NAMES.get(k, k.replace("_", " ")), f"{_number(v):.3g} s"]
            for k, v in timings.items()
            if k not in ("total", "report") and _number(v) is not None]
    if _number(timings.get("total")) is not None:
        rows.append(["total analysis", f"{_number(timings['total']):.3g} s"])
    if _number(timings.get("report")) is not None:
        rows.append(["report (previous)", f"{_number(timings['report']):.3g} s"])
    return rows


def _run_rows(ctx):
    res = ctx.res
    rows = []
    vers = res.get("versions")
    if isinstance(vers, dict):
        mv = vers.get("microfacet")
        others = ", ".join(f"{k} {v}" for k, v in vers.items() if k != "microfacet")
        rows.append(["versions", f"microfacet {mv}" + (f"; {others}" if others else "")])
    elif res.get("version"):
        rows.append(["versions", f"microfacet {res.get('version')}"])
    missing = [m for m in _FILES if not (res.path / m).is_file()]
    if missing:
        rows.append(["not in the folder", ", ".join(missing)])
    return rows


def _wrap(text, width):
    """Greedy wrap on ", " and spaces (a table cell holds one line per row)."""
    import textwrap

    return textwrap.wrap(text, width=width, break_long_words=True) or [""]


def _page_parameters(pg, ctx):
    tables = _tables(ctx)
    colw = 0.5 * (pg.right - pg.left - 0.4)
    xl, xr = pg.left, pg.left + colw + 0.4
    y = pg.top - 0.05
    for key, title, widths in (
            ("thickness", "oxide thickness: Gaussian mixture components",
             [0.2, 0.2, 0.3, 0.3]),
            ("ndf", "facet normals: zero-mean Gaussian-slope (Beckmann) lobes",
             [0.12, 0.17, 0.27, 0.2, 0.24])):
        t = tables[key]
        rows = t["rows"] or [["—"] + ["no fit"] + [""] * (len(t["header"]) - 2)]
        y = _table(pg, xl, y, colw, rows, header=t["header"], col_widths=widths,
                   title=title, fontsize=8.5)
        if t["note"]:
            lines = _wrap(t["note"], 92)
            for j, line in enumerate(lines):
                pg.text(xl, y - 0.17 - 0.15 * j, line, fontsize=7.5, color="0.3", va="center")
            y -= 0.15 * len(lines)
        y -= 0.42
    # timings in two column pairs, then versions (long values wrapped over several rows)
    tr = tables["timings"]["rows"]
    if tr:
        half = (len(tr) + 1) // 2
        rows = [a + (tr[half + j] if half + j < len(tr) else ["", ""])
                for j, a in enumerate(tr[:half])]
        y = _table(pg, xl, y, colw, rows, col_widths=[0.32, 0.18, 0.32, 0.18],
                   title="run time", fontsize=7.5, row_h=0.18) - 0.42
    rows = []
    for k, v in tables["run"]["rows"]:
        for j, line in enumerate(_wrap(v, 70)):
            rows.append([k if j == 0 else "", line])
    if rows:
        _table(pg, xl, y, colw, rows, col_widths=[0.22, 0.78], title="software",
               fontsize=7.5, row_h=0.18)
    rows = []
    for k, v in tables["analysis"]["rows"]:
        for j, line in enumerate(_wrap(v, 50)):
            rows.append([k if j == 0 else "", line])
    _table(pg, xr, pg.top - 0.05, pg.right - xr, rows, col_widths=[0.40, 0.60],
           title="analysis (summary.json)", fontsize=8.0)


# --------------------------------------------------------------------------- page 5
_ANGLES = np.arange(0.0, 85.0 + 1e-9, 1.0)
_CORE = 60  # degrees: the display scale of the microfacet map is set below this angle


def _predicted_maps(ctx):
    """[(title, AngularMap, note)] of the fitted distributions; [] if there is no fit."""
    if ctx.thick is None:
        return []
    from ..forward.angular import colours_from_spectra, simulate_map
    from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, load_set

    res = ctx.res
    inputs = res.get("inputs") if isinstance(res.get("inputs"), dict) else {}
    film = res.get("film") or inputs.get("film") or DEFAULT_FILM
    substrate = res.get("substrate") or inputs.get("substrate") or DEFAULT_SUBSTRATE
    illuminant = res.get("illuminant") or inputs.get("illuminant") or "D65"
    try:
        load_set(film)
        load_set(substrate)
        white_xyz(illuminant=illuminant)
    except (ValueError, KeyError, OSError):
        film, substrate, illuminant = DEFAULT_FILM, DEFAULT_SUBSTRATE, "D65"
    wl = np.arange(380.0, 781.0, 10.0)
    kw = dict(thickness=ctx.thick, theta_light_deg=_ANGLES, theta_view_deg=_ANGLES,
              wavelength_nm=wl, film=film, substrate=substrate, illuminant=illuminant)
    out = []
    if ctx.ndf is not None:
        m = simulate_map(model="microfacet", ndf=ctx.ndf, **kw)
        # Display scale: the 98th percentile of Y over light and view ≤ 60° at 0.9 of
        # white. The BRDF's specular peak, and its rise toward grazing angles, are far above
        # 1: scaled by the whole map (as `microfacet simulate` does) the map is nearly black.
        y = m.xyz[: _CORE + 1, : _CORE + 1, 1]
        y = y[np.isfinite(y)]
        p98 = float(np.percentile(y, 98)) if y.size else 0.0
        e = 0.9 / p98 if p98 > 0 else 1.0
        m.xyz, m.lab, m.srgb, _ = colours_from_spectra(m.spectra, wl, exposure=e,
                                                       illuminant=illuminant)
        out.append(("microfacet thin-film BRDF (fitted thickness mixture and NDF)", m,
                    f"reflectance factor π·f_r × {e:.3g}: the 98th percentile of Y over "
                    f"angles ≤ {_CORE}° shown at 0.9 of white;\nbrighter cells (specular, "
                    f"grazing) clip to white"))
    m = simulate_map(model="half-vector", **kw)
    out.append(("half-vector model (fitted thickness mixture; seed §2.3, Fig. 10)", m,
                "reflectance of the film at the half angle θ_d averaged over the thickness "
                "mixture,\nexposure 1 (a white diffuser is white)"))
    return out, dict(film=film, substrate=substrate, illuminant=illuminant)


def _page_angular(pg, ctx):
    try:
        got = _predicted_maps(ctx)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        _blank(pg, (pg.left, pg.bottom, pg.right - pg.left, pg.top - pg.bottom),
               f"the angular colour could not be predicted from the fitted distributions:\n"
               f"{_shorten(exc, 200)}")
        return
    maps, optics = got if got else ([], {})
    cells = pg.grid(1, 2, hgap=0.4, top=pg.top - 0.05, bottom=pg.bottom + 0.55)
    if not maps:
        img = ctx.res.image("angular_map.png")
        if img is not None:
            x, y, w, h = cells[0]
            ax = pg.axes(x + 0.7, y + 0.5, min(w, h) - 0.9, min(w, h) - 0.9)
            ax.imshow(_downsample(img)[0])
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_xlabel("view zenith angle → (range unknown)")
            ax.set_ylabel("light zenith angle ↓")
            ax.set_title("angular_map.png (from the folder)")
            _blank(pg, cells[1], "no fitted thickness mixture in summary.json:\n"
                                 "the map shown is the folder's angular_map.png")
        else:
            _blank(pg, (pg.left, pg.bottom, pg.right - pg.left, pg.top - pg.bottom),
                   "no fitted thickness mixture in summary.json: no colour to predict")
        return
    if len(maps) == 1:
        cells = [(cells[0][0] + 0.5 * (cells[1][0] - cells[0][0]),) + cells[0][1:]]
    for cell, (title, m, note) in zip(cells, maps):
        x, y, w, h = cell
        side = min(w - 0.8, h - 0.75)
        x0 = x + 0.65 + 0.5 * (w - 0.8 - side)
        ax = pg.axes(x0, y + h - 0.35 - side, side, side)
        tl, tv = m.theta_light_deg, m.theta_view_deg
        hl, hv = 0.5 * (tl[1] - tl[0]), 0.5 * (tv[1] - tv[0])
        ax.imshow(m.srgb, extent=(tv[0] - hv, tv[-1] + hv, tl[-1] + hl, tl[0] - hl),
                  aspect="auto", interpolation="nearest")
        ax.plot([tv[0], tv[-1]], [tv[0], tv[-1]], color="white", lw=0.8, ls=(0, (5, 4)),
                alpha=0.9)
        ax.text(0.2 * tv[-1], 0.17 * tv[-1], "specular (θ_view = θ_light)", color="white",
                fontsize=7.5, rotation=-45, rotation_mode="anchor", ha="left",
                va="bottom")
        ax.set_xlabel("view zenith θ_view (°), + = mirror side")
        ax.set_ylabel("light zenith θ_light (°)")
        ax.set_title(title, fontsize=10)
        pg.text(x0 + 0.5 * side, y + h - 0.35 - side - 0.48, note, fontsize=7.5,
                color="0.3", ha="center", va="top", linespacing=1.3)
    pg.text(0.5 * pg.W, pg.bottom + 0.25,
            f"In-plane light and view directions (rows: light zenith, columns: view zenith, "
            f"0–85° in 1° steps); {optics.get('film', '')} on "
            f"{optics.get('substrate', '')}, illuminant {optics.get('illuminant', '')}, "
            f"sRGB display.\nOther grids and models (seed eq. 6), and comparison with a "
            f"measured map: microfacet simulate --results <this folder>.",
            fontsize=7.5, color="0.3", ha="center", va="center", linespacing=1.3)


# --------------------------------------------------------------------------- header/footer
_TITLES = {"overview": "overview", "maps": "thickness, tilt and colour-difference maps",
           "distributions": "thickness and facet-normal distributions",
           "parameters": "fitted parameters", "angular": "predicted angular colour"}


def _header(pg, ctx, shown, page, i, written):
    res = ctx.res
    inputs = res.get("inputs") if isinstance(res.get("inputs"), dict) else {}
    stack = inputs.get("stack") or inputs.get("stack_path") or inputs.get("path")
    name = Path(str(stack)).name if stack else shown.name
    y1 = pg.H - 0.36
    pg.text(pg.left, y1, f"microfacet report — {_shorten(name, 40)}", fontsize=14,
            fontweight="bold", va="baseline")
    pg.text(pg.right, y1, f"{i}. {_TITLES[page]}", fontsize=12, fontweight="bold",
            ha="right", va="baseline", color="0.2")
    from .. import __version__

    mode = res.get("mode") or res.get("parameters", "mode")
    bits = []
    if mode:
        bits.append(f"{mode} mode")
    film, sub = res.get("film") or inputs.get("film"), res.get("substrate") or \
        inputs.get("substrate")
    if film and sub:
        ill = res.get("illuminant") or inputs.get("illuminant") or "D65"
        bits.append(f"{film} on {sub}, {ill}")
    when = res.get("created") or res.get("date")
    analysed = str(when) if when else _dt.datetime.fromtimestamp(
        res.summary_mtime).strftime("%Y-%m-%d %H:%M")
    bits.append(f"analysed {analysed}")
    av = res.get("versions", "microfacet") or res.get("version")
    if av:
        bits.append(f"microfacet {av}" + (f" (report: {__version__})"
                                          if str(av) != __version__ else ""))
    else:
        bits.append(f"report: microfacet {__version__} (analysis version not recorded)")
    sub_line = "   ·   ".join(bits)
    pg.text(pg.left, pg.H - 0.60, _shorten(sub_line, 150), fontsize=8.5, color="0.3",
            va="baseline")
    pg.text(pg.right, pg.H - 0.60, f"report written {written}", fontsize=8.5, color="0.3",
            ha="right", va="baseline")
    import matplotlib.lines as mlines

    pg.fig.add_artist(mlines.Line2D([pg.left / pg.W, pg.right / pg.W],
                                    [(pg.H - 0.71) / pg.H] * 2, color="0.75", lw=0.6))
    pg.text(pg.left, 0.17, _shorten(str(shown), 80), fontsize=7, color="0.45", va="center")
    pg.text(0.5 * pg.W, 0.17, "grey pixels on maps: masked or no value (NaN)", fontsize=7,
            color="0.45", ha="center", va="center")
    pg.text(pg.right, 0.17, f"page {i} of {len(PAGES)}", fontsize=7, color="0.45",
            ha="right", va="center")


# --------------------------------------------------------------------------- entry point
def write_report(results_dir, *, out_pdf=None, png_dir=None) -> Path:
    """Write the multi-page PDF report (and optional PNGs) of an analysis results folder.

    Parameters
    ----------
    results_dir : path-like
        A results folder (``docs/results-format.md``). ``summary.json`` is
        required; every other file is optional and a missing one skips its panel:
        ``all_in_focus.png``, ``height_um.npy``, ``thickness_nm.npy``, ``tilt_deg.npy``,
        ``tilt_sigma_deg.npy``, ``thickness_pdf.csv``, ``ndf_pdf.csv``,
        ``thickness_roi.csv``, ``mask.npy`` (bool, True = masked), ``delta_e.npy``
        (ΔE00 per pixel), ``tilt_height_deg.npy`` (tilt from the height map) and
        ``angular_map.png`` (shown on page 5 only when there is no fitted thickness
        mixture to predict the angular colour from).
    out_pdf : path-like, optional, keyword-only
        Where to write the PDF; default ``results_dir / "report.pdf"``. It is written under
        a temporary name and renamed when complete.
    png_dir : path-like, optional, keyword-only
        If given, each page is also written there as ``report_<n>_<name>.png``
        (names in :data:`PAGES`; 1286 × 910 pixels); the folder is created if needed.

    Returns
    -------
    pathlib.Path
        The PDF written.

    Raises
    ------
    FileNotFoundError
        ``results_dir`` is not a folder or has no ``summary.json`` (the message names it).
    ValueError
        A file that is present cannot be read or is malformed (the message names it), e.g.
        invalid JSON, a mixture ``from_json`` rejects, a CSV without its required columns.

    Notes
    -----
    Pages (A4 landscape): 1 overview (all-in-focus image, height map, mask, inputs,
    masking); 2 maps (thickness, thickness component, ΔE00, tilt from colour, tilt from
    height, tilt 1σ); 3 thickness and facet-tilt histograms with the fitted mixtures and
    their components (seed Figs. 18a, 19), D(θ), ΔE00 histogram; 4 tables of fitted
    parameters, analysis settings and run; 5 the predicted angular colour maps. Map axes
    are in µm when ``summary["inputs"]["pixel_size_um"]`` is given, else in pixels. Maps
    are block-averaged to at most :data:`MAX_MAP_PX` pixels a side and colour limits are
    the 1st–99th percentiles (arrows on the colour bar mark values beyond them).

    Examples
    --------
    >>> write_report("results/sample1")                                # doctest: +SKIP
    PosixPath('results/sample1/report.pdf')
    """
    results_dir = Path(results_dir)
    if not results_dir.is_dir():
        raise FileNotFoundError(f"{results_dir}: results folder not found")
    res = _Folder(results_dir)
    thick_mix, ndf_mix = _mixtures(res)
    for name, cols in (("thickness_pdf.csv", _THICKNESS_CSV), ("ndf_pdf.csv", _NDF_CSV),
                       ("thickness_roi.csv", _ROI_CSV)):
        res.table(name, cols)  # a malformed CSV fails here, before anything is drawn
    out_pdf = Path(out_pdf) if out_pdf is not None else results_dir / "report.pdf"
    ctx = _Context(res, thick_mix, ndf_mix)

    # Figure objects render through their own canvas: no global backend switch, so a
    # Jupyter session calling this keeps its inline backend.
    import matplotlib
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    from .. import __version__

    shown = _display_path(results_dir)
    title = f"microfacet report — {shown.name}"
    written = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    draw = {"overview": _page_overview, "maps": _page_maps,
            "distributions": _page_distributions, "parameters": _page_parameters,
            "angular": _page_angular}
    tmp = out_pdf.with_name(f".{out_pdf.name}.partial-{os.getpid()}")
    out_pdf.parent.mkdir(parents=True, exist_ok=True)
    if png_dir is not None:
        png_dir = Path(png_dir)
        png_dir.mkdir(parents=True, exist_ok=True)
    try:
        with matplotlib.rc_context(_RC), warnings.catch_warnings(), PdfPages(
                tmp, metadata={"Title": title, "Creator": f"microfacet {__version__}"}
        ) as pdf:
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN slices and the like
            for i, page in enumerate(PAGES, start=1):
                fig = Figure(figsize=_PAGE_IN)
                pg = _Page(fig)
                _header(pg, ctx, shown, page, i, written)
                draw[page](pg, ctx)
                pdf.savefig(fig, dpi=_PDF_DPI)
                if png_dir is not None:
                    fig.savefig(png_dir / f"report_{i}_{page}.png", dpi=_PNG_DPI,
                                pil_kwargs={"compress_level": 3})
        os.replace(tmp, out_pdf)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out_pdf


def _display_path(results_dir: Path) -> Path:
    """The folder's final name: ``.OUT.partial-xyz`` (being written) is shown as ``OUT``;
    relative to the working directory if it is inside it."""
    p = results_dir.resolve()
    m = re.fullmatch(r"\.(.+)\.partial-[^/]*", p.name)
    p = p.with_name(m.group(1)) if m else p
    try:
        return p.relative_to(Path.cwd().resolve())
    except (ValueError, OSError):
        return p
