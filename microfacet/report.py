"""The analysis report: a multi-page PDF (and PNGs) drawn from a results folder.

:func:`write_report` reads a results folder (``/work/shared/spec/results-format.md``) and
draws four A4-landscape pages:

1. **overview** — the all-in-focus image, the height map (µm), the mask and a short table
   of the inputs (pixel size, field of view);
2. **maps** — oxide thickness (nm) and the ΔE00 of the colour inversion; facet tilt from the
   colour (°), its 1-σ uncertainty (°) and, if present, the tilt from the height map (°) on
   the same colour scale;
3. **distributions** — the thickness histogram density with the fitted mixture and each
   Gaussian component drawn separately, the ROI thicknesses marked (seed Fig. 18a); the
   facet-tilt histogram with the NDF mixture and its lobes (seed Fig. 19);
4. **parameters** — a table of the fitted parameters (components, BIC, exposure, ΔE00,
   masked fraction, timings) and the predicted angular colour map if present.

Only ``summary.json`` is required. A missing map or CSV skips its panel (the histograms
fall back to the maps, then to the fitted mixture alone) and is listed on page 4; a
mixture with an empty component list (no fit) is shown as "no fit". Maps
larger than :data:`MAX_MAP_PX` are block-averaged down before drawing and images are
rasterised, so the PDF stays small. Grey in a map is a masked or unreliable (NaN) pixel.

Importing this module does not import matplotlib; :func:`write_report` does.
"""

from __future__ import annotations

import csv
import json
import math
import os
import re
import warnings
from pathlib import Path

import numpy as np

__all__ = ["MAX_MAP_PX", "PAGES", "write_report"]

#: Page names, in order (also the PNG file names ``report_<n>_<name>.png``).
PAGES = ("overview", "maps", "distributions", "parameters")
#: Maps are block-averaged so that neither side exceeds this many pixels.
MAX_MAP_PX = 1000

_A4_LANDSCAPE_IN = (11.69, 8.27)
_PDF_DPI = 150   # resolution at which images are rasterised into the PDF
_PNG_DPI = 110
_BAD = "#c4c4c4"  # colour of NaN / masked pixels
_RC = {
    "font.size": 10,
    "axes.titlesize": 11,
    "axes.labelsize": 10,
    "xtick.labelsize": 9,
    "ytick.labelsize": 9,
    "legend.fontsize": 8.5,
    "figure.titlesize": 14,
    "pdf.fonttype": 42,
    "axes.spines.top": False,
    "axes.spines.right": False,
}
_COMPONENT_COLOURS = ("C1", "C2", "C3", "C5", "C6", "C8", "C9")
_MARK = "C4"  # ROI thicknesses, tilt from the height map
_THICKNESS_CSV = ("thickness_nm", "density", "mixture_density")
_NDF_CSV = ("tilt_deg", "density", "mixture_density")
_ROI_CSV = ("row0", "col0", "size", "thickness_nm", "mean_delta_e", "n_pixels")


# --------------------------------------------------------------------------- reading
class _Folder:
    """The files of one results folder, loaded on demand; records what is missing."""

    def __init__(self, path: Path):
        self.path = path
        self.missing: list[str] = []
        f = path / "summary.json"
        if not f.is_file():
            raise FileNotFoundError(f"{f}: missing (required to write the report)")
        try:
            self.summary = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ValueError(f"{f}: cannot read ({exc})") from None
        if not isinstance(self.summary, dict):
            raise ValueError(f"{f}: must hold a JSON object")
        self._cache: dict = {}

    def _file(self, name):
        f = self.path / name
        if f.is_file():
            return f
        if name not in self.missing:
            self.missing.append(name)
        return None

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

    def image(self, name):
        """A PNG as float RGB (or grey) in [0, 1], or None if the file is absent."""
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
        return np.clip(img, 0.0, 1.0)

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
    from .distributions import NDFMixture, ThicknessMixture

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


# --------------------------------------------------------------------------- drawing helpers
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
    if not vmax > vmin:
        d = max(abs(vmin) * 1e-3, 1e-6)
        vmin, vmax = vmin - d, vmax + d
    below, above = v.min() < vmin, v.max() > vmax
    extend = {(True, True): "both", (True, False): "min", (False, True): "max"}.get(
        (bool(below), bool(above)), "neither")
    return float(vmin), float(vmax), extend


def _cmap(name):
    import matplotlib

    return matplotlib.colormaps[name].with_extremes(bad=_BAD)


class _Geometry:
    """Axis units for the maps: µm if the pixel size is known, else pixels."""

    def __init__(self, pixel_size_um):
        self.px = pixel_size_um
        self.unit = "µm" if pixel_size_um else "pixel"

    def extent(self, shape, block=1):
        s = (self.px or 1.0) * block
        return (0.0, shape[1] * s, shape[0] * s, 0.0)

    def label(self, ax, *, y=True):
        ax.set_xlabel(f"x ({self.unit})")
        if y:
            ax.set_ylabel(f"y ({self.unit})")


def _map(fig, ax, a, geom, *, title, label, cmap, limits=None, lo=1.0, hi=99.0, floor=None):
    """Draw one H×W float map with a colour bar labelled ``label``."""
    small, block = _downsample(a)
    vmin, vmax, extend = limits if limits is not None else _limits(a, lo, hi, floor=floor)
    im = ax.imshow(small, cmap=_cmap(cmap), vmin=vmin, vmax=vmax,
                   extent=geom.extent(small.shape, block), rasterized=True)
    cb = _colorbar(fig, im, ax, extend=extend)
    cb.set_label(label)
    ax.set_title(title)
    geom.label(ax)
    return im


def _colorbar(fig, im, ax, **kw):
    """A colour bar exactly as tall as the (aspect-locked) image, right of it."""
    cax = ax.inset_axes([1.04, 0.0, 0.045, 1.0])
    return fig.colorbar(im, cax=cax, **kw)


def _blank(ax, text):
    ax.set_axis_off()
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, wrap=True,
            color="0.35")


def _fmt(v, spec=".3g", unit=""):
    v = _number(v)
    if v is None:
        return "—"
    return f"{v:{spec}}" + (f" {unit}" if unit else "")


def _edges(centres):
    """Bin edges for a grid of bin centres (midpoints; the ends mirrored)."""
    x = np.asarray(centres, dtype=np.float64)
    if x.size == 1:
        return np.array([x[0] - 0.5, x[0] + 0.5])
    mid = 0.5 * (x[1:] + x[:-1])
    return np.concatenate([[2 * x[0] - mid[0]], mid, [2 * x[-1] - mid[-1]]])


def _finite(a, mask=None):
    if a is None:
        return np.empty(0)
    v = a if mask is None or mask.shape != a.shape else np.where(mask, np.nan, a)
    v = np.asarray(v, dtype=np.float64).ravel()
    return v[np.isfinite(v)]


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


# --------------------------------------------------------------------------- pages
def _page_overview(fig, res, geom):
    aif = res.image("all_in_focus.png")
    height = res.array("height_um.npy")
    mask = res.array("mask.npy")
    mask_note = ""
    if mask is None:
        th = res.array("thickness_nm.npy")
        if th is not None:
            mask, mask_note = ~np.isfinite(th), " (NaN thickness)"
    elif mask.dtype != bool:
        mask = mask != 0

    panels = [p for p in ("aif", "height", "mask")
              if {"aif": aif, "height": height, "mask": mask}[p] is not None]
    # 2 × 2: the maps first, then the facts table
    axes = fig.subplots(2, 2).ravel()
    for ax, p in zip(axes, panels):
        if p == "aif":
            small, block = _downsample(aif)
            ax.imshow(small, cmap="gray" if small.ndim == 2 else None, vmin=0, vmax=1,
                      extent=geom.extent(small.shape, block), rasterized=True)
            ax.set_title("all-in-focus image")
            geom.label(ax)
        elif p == "height":
            _map(fig, ax, height, geom, title="height from focus", label="height (µm)",
                 cmap="cividis")
        else:
            import matplotlib.colors as mcolors

            small, block = _downsample(mask)
            cm = mcolors.ListedColormap(["#f2f2f2", "#3b3b8f"])
            im = ax.imshow(small.astype(np.uint8), cmap=cm, vmin=-0.5, vmax=1.5,
                           extent=geom.extent(small.shape, block), interpolation="nearest",
                           rasterized=True)
            cb = _colorbar(fig, im, ax, ticks=[0, 1])
            cb.ax.set_yticklabels(["used", "masked"])
            cb.set_label("pixel status")
            ax.set_title(f"mask{mask_note}: {100.0 * float(np.mean(mask)):.1f} % masked")
            geom.label(ax)
    for ax in axes[len(panels):-1]:
        ax.set_axis_off()
    if not panels:
        _blank(axes[0], "no all_in_focus.png,\nheight_um.npy or mask.npy\nin the folder")
    # a few facts
    ax = axes[-1]
    ax.set_axis_off()
    ax.set_title("inputs")
    shape = next((a.shape[:2] for a in (height, aif, mask) if a is not None), None)
    inputs = res.get("inputs") if isinstance(res.get("inputs"), dict) else {}
    stack = inputs.get("stack") or inputs.get("stack_path") or inputs.get("path")
    cells = [
        ["image size", f"{shape[1]} × {shape[0]} pixels" if shape else "—"],
        ["pixel size", _fmt(geom.px, ".4g", "µm") if geom.px else "unknown (axes in pixels)"],
        ["field of view", (f"{shape[1] * geom.px:.4g} × {shape[0] * geom.px:.4g} µm"
                           if shape and geom.px else "—")],
        ["height range (1–99 %)", _range_text(height, "µm")],
        ["masked fraction", _fmt(_pct(res.get("masked_fraction")), ".1f", "%")],
    ]
    if stack:
        cells.insert(0, ["stack", _shorten(str(stack), 44)])
    t = ax.table(cellText=cells, colWidths=[0.4, 0.6], cellLoc="left",
                 bbox=[0.0, 1.0 - 0.1 * len(cells), 1.0, 0.1 * len(cells)])
    _style_table(t, fontsize=9.5)


def _page_maps(fig, res, geom):
    thick = res.array("thickness_nm.npy")
    de = res.array("delta_e.npy")
    tilt = res.array("tilt_deg.npy")
    sig = res.array("tilt_sigma_deg.npy")
    tilt_h = res.array("tilt_height_deg.npy")
    row1 = [p for p in (("thick", thick), ("de", de)) if p[1] is not None]
    row2 = [p for p in (("tilt", tilt), ("sig", sig), ("tilt_h", tilt_h)) if p[1] is not None]
    rows = [r for r in (row1, row2) if r]
    if not rows:
        _blank(fig.subplots(), "no thickness_nm.npy, delta_e.npy, tilt_deg.npy, "
                               "tilt_sigma_deg.npy or tilt_height_deg.npy in the folder")
        return
    # one colour scale for both tilt maps, so they can be compared
    tilt_lim = _limits(np.concatenate([_finite(tilt), _finite(tilt_h)]), 0.0, 99.0, floor=0.0)
    subs = np.atleast_1d(fig.subfigures(len(rows), 1))
    for sub, row in zip(subs, rows):
        axes = np.atleast_1d(sub.subplots(1, len(row)))
        for ax, (p, a) in zip(axes, row):
            if p == "thick":
                _map(sub, ax, a, geom, title="oxide thickness", label="thickness (nm)",
                     cmap="viridis")
            elif p == "de":
                _map(sub, ax, a, geom, title="colour difference of the fit",
                     label="ΔE00 (CIEDE2000, unitless)", cmap="inferno", lo=0.0, floor=0.0)
            elif p == "tilt":
                _map(sub, ax, a, geom, title="facet tilt from colour",
                     label="tilt from optical axis (°)", cmap="magma", limits=tilt_lim)
            elif p == "sig":
                _map(sub, ax, a, geom, title="tilt uncertainty (1σ)",
                     label="tilt 1σ (°)", cmap="plasma", lo=0.0, floor=0.0)
            else:
                _map(sub, ax, a, geom, title="tilt from height map",
                     label="tilt from optical axis (°)", cmap="magma", limits=tilt_lim)


def _page_distributions(fig, res, geom, thick_mix, ndf_mix):
    ax_t, ax_n = fig.subplots(1, 2)
    mask = res.array("mask.npy")
    if mask is not None and mask.dtype != bool:
        mask = mask != 0

    # ---- thickness (seed Fig. 18a)
    csv_t = res.table("thickness_pdf.csv", _THICKNESS_CSV)
    if csv_t is not None and csv_t["thickness_nm"].size:
        x, dens, mixd = csv_t["thickness_nm"], csv_t["density"], csv_t["mixture_density"]
        src = "thickness_pdf.csv"
    else:
        lo_hi = thick_mix.support_nm() if thick_mix is not None else (None, None)
        h = _histogram(_finite(res.array("thickness_nm.npy"), mask), *lo_hi)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "thickness_nm.npy"
    roi = res.table("thickness_roi.csv", _ROI_CSV)
    roi_t = roi["thickness_nm"][np.isfinite(roi["thickness_nm"])] if roi is not None else None
    _density_panel(
        ax_t, x, dens, mixd, thick_mix, src=src, unit="nm", what="oxide thickness",
        comp_pdf=lambda m, g: m.pdf(g), comp_label=lambda w, c: (
            f"w {w:.2f}, μ {c[1]:.1f} nm, σ {c[2]:.1f} nm"),
        default_range=thick_mix.support_nm() if thick_mix is not None else (0.0, 1.0))
    ax_t.set_title("oxide thickness distribution")
    if roi_t is not None and roi_t.size:
        ax_t.plot(roi_t, np.full(roi_t.shape, 0.025), ls="none", marker="|", ms=16, mew=2,
                  color=_MARK, transform=ax_t.get_xaxis_transform(),
                  label=f"ROI thickness (n = {roi_t.size})")
        _legend(ax_t)

    # ---- facet tilt / NDF (seed Fig. 19)
    csv_n = res.table("ndf_pdf.csv", _NDF_CSV)
    tilt_h = _finite(res.array("tilt_height_deg.npy"), mask)
    hi = float(min(89.0, 4.0 * ndf_mix.sds_deg.max())) if ndf_mix is not None else None
    if csv_n is not None and csv_n["tilt_deg"].size:
        x, dens, mixd = csv_n["tilt_deg"], csv_n["density"], csv_n["mixture_density"]
        src = "ndf_pdf.csv"
    else:
        h = _histogram(_finite(res.array("tilt_deg.npy"), mask), 0.0, hi)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "tilt_deg.npy"
    _density_panel(
        ax_n, x, dens, mixd, ndf_mix, src=src, unit="°", what="facet tilt from optical axis",
        comp_pdf=lambda m, g: m.tilt_pdf(g), comp_label=lambda w, c: (
            f"w {w:.2f}, σ {c[1]:.1f}° (slope sd {math.tan(math.radians(c[1])):.3f})"),
        default_range=(0.0, hi or 30.0), lower=0.0)
    if tilt_h.size >= 2:
        lo, top = ax_n.get_xlim()
        d, e = np.histogram(tilt_h, bins=60, range=(max(0.0, lo), top), density=True)
        ax_n.stairs(d, e, color=_MARK, lw=1.2, label="tilt from height map (histogram)")
        _legend(ax_n)
    ax_n.set_title("facet normal distribution (per-pixel tilt)")


def _density_panel(ax, x, dens, mixd, mix, *, src, unit, what, comp_pdf, comp_label,
                   default_range, lower=None):
    """Histogram density, fitted mixture (bold) and each component (thin, dashed)."""
    drew = False
    if x is not None and np.size(x):
        e = _edges(x)
        if lower is not None:
            e[0] = max(e[0], lower)
        d = np.nan_to_num(np.asarray(dens, dtype=np.float64))
        ax.stairs(d, e, fill=True, color="#9ecae1", alpha=0.8, label=f"histogram ({src})")
        ax.stairs(d, e, color="#3182bd", lw=0.8)
        lo, hi = float(e[0]), float(e[-1])
        drew = True
    else:
        lo, hi = default_range
    grid = np.linspace(lo, hi, 800)
    if mix is not None:
        from .distributions import NDFMixture, ThicknessMixture

        single = ThicknessMixture if isinstance(mix, ThicknessMixture) else NDFMixture
        for i, c in enumerate(mix.components):
            w = c[0]
            g = w * comp_pdf(single([(1.0,) + tuple(c[1:])]), grid)
            colour = _COMPONENT_COLOURS[i % len(_COMPONENT_COLOURS)]
            ax.plot(grid, g, lw=1.4, ls="--", color=colour,
                    label=f"component {i + 1}: {comp_label(w, c)}")
    if mixd is not None and np.any(np.isfinite(mixd)):
        ax.plot(x, mixd, color="k", lw=2.0, label="fitted mixture")
        drew = True
    elif mix is not None:
        ax.plot(grid, comp_pdf(mix, grid), color="k", lw=2.0, label="fitted mixture")
        drew = True
    if not drew:
        ax.plot([], [], ls="none", label="(no histogram or fitted mixture in the folder)")
    ax.set_xlim(lo, hi)
    ax.set_xlabel(f"{what} ({unit})")
    ax.set_ylabel(f"probability density (1/{unit})")
    _legend(ax)


def _legend(ax):
    """Legend in the top right, with head room above the data so it covers nothing."""
    ax.relim()
    ax.autoscale_view()
    top = ax.dataLim.y1 if np.isfinite(ax.dataLim.y1) and ax.dataLim.y1 > 0 else 1.0
    n = len(ax.get_legend_handles_labels()[1])
    ax.set_ylim(0.0, top * (1.08 + 0.055 * n))
    if n:
        ax.legend(loc="upper right", frameon=False, markerscale=0.6)


def _page_parameters(fig, res, thick_mix, ndf_mix):
    ang = res.image("angular_map.png")
    if ang is not None:
        ax_t, ax_a = fig.subplots(1, 2, width_ratios=[1.25, 1.0])
    else:
        ax_t, ax_a = fig.subplots(), None
    rows = _parameter_rows(res, thick_mix, ndf_mix)
    ax_t.set_axis_off()
    ax_t.set_title("fitted parameters (summary.json)")
    n = len(rows) + 1
    h = min(1.0, 0.034 * n)
    x0, w = (0.0, 1.0) if ax_a is not None else (0.15, 0.7)
    t = ax_t.table(cellText=rows, colLabels=["quantity", "value"], colWidths=[0.42, 0.58],
                   cellLoc="left", bbox=[x0, 1.0 - h, w, h])
    _style_table(t, fontsize=9.5 if n <= 28 else 8)
    if ax_a is not None:
        _angular_panel(ax_a, ang, res)


def _angular_panel(ax, img, res):
    spec = res.get("angular_map") or res.get("angular") or {}
    rng = {}
    for k in ("theta_light_deg", "theta_view_deg"):
        v = spec.get(k) if isinstance(spec, dict) else None
        try:
            v = np.asarray(v, dtype=np.float64).ravel()
        except (TypeError, ValueError):
            v = np.empty(0)
        if v.size >= 2 and np.all(np.isfinite(v)):
            rng[k] = (float(v.min()), float(v.max()))
    small, _ = _downsample(img)
    if len(rng) == 2:
        (l0, l1), (v0, v1) = rng["theta_light_deg"], rng["theta_view_deg"]
        hl = 0.5 * (l1 - l0) / max(small.shape[0] - 1, 1)
        hv = 0.5 * (v1 - v0) / max(small.shape[1] - 1, 1)
        ax.imshow(small, extent=(v0 - hv, v1 + hv, l1 + hl, l0 - hl), rasterized=True,
                  interpolation="nearest")
        ax.set_xlabel("view zenith θ_view (°, + = mirror side)")
        ax.set_ylabel("light zenith θ_light (°)")
    else:
        ax.imshow(small, rasterized=True, interpolation="nearest")
        ax.set_xlabel("view zenith angle → (range not in summary.json)")
        ax.set_ylabel("light zenith angle ↓")
        ax.set_xticks([])
        ax.set_yticks([])
    ax.set_title("predicted angular colour map")


def _parameter_rows(res, thick_mix, ndf_mix):
    rows = []
    if thick_mix is not None:
        for i, (w, m, s) in enumerate(thick_mix.components):
            rows.append([f"thickness component {i + 1}",
                         f"w {w:.3f}   μ {m:.1f} nm   σ {s:.2f} nm"])
    elif res.get("thickness", "mixture") is not None:
        rows.append(["thickness mixture", "no fit"])
    rows.append(["thickness mixture BIC", _fmt(res.get("thickness", "mixture", "bic"), ".6g")])
    _degenerate_row(rows, res, "thickness")
    if ndf_mix is not None:
        for i, (w, s) in enumerate(ndf_mix.components):
            a = math.sqrt(2.0) * math.tan(math.radians(s))
            rows.append([f"NDF lobe {i + 1} (gaussian-slope)",
                         f"w {w:.3f}   σ {s:.2f}°   Beckmann α {a:.3f}"])
    elif res.get("ndf", "mixture") is not None:
        rows.append(["NDF mixture", "no fit"])
    rows.append(["NDF mixture BIC", _fmt(res.get("ndf", "mixture", "bic"), ".6g")])
    _degenerate_row(rows, res, "ndf")
    rows.append(["exposure", _fmt(res.get("exposure"), ".4g")])
    rows.append(["ΔE00 mean / median",
                 f"{_fmt(res.get('delta_e', 'mean'), '.2f')} / "
                 f"{_fmt(res.get('delta_e', 'median'), '.2f')}"])
    rows.append(["masked fraction", _fmt(_pct(res.get("masked_fraction")), ".1f", "%")])
    roi = res.table("thickness_roi.csv", _ROI_CSV)
    if roi is not None:
        t = roi["thickness_nm"][np.isfinite(roi["thickness_nm"])]
        rows.append(["ROIs (thickness)",
                     f"{t.size}: {t.min():.1f}–{t.max():.1f} nm" if t.size else "0"])
    timings = res.get("timings_s")
    if isinstance(timings, dict):
        rows.append(["time, total", _fmt(timings.get("total"), ".3g", "s")])
        other = [(k, _number(v)) for k, v in timings.items() if k != "total"]
        other = [(k, v) for k, v in other if v is not None]
        for k, v in other[:8]:
            rows.append([f"time, {k}", f"{v:.3g} s"])
        if len(other) > 8:
            rows.append(["time, other steps", f"{sum(v for _, v in other[8:]):.3g} s"])
    version = res.get("versions", "microfacet") or res.get("version")
    if version:
        rows.append(["microfacet version", _shorten(str(version), 40)])
    lines = []
    for name in (m for m in res.missing if m != "summary.json"):
        if lines and len(lines[-1]) + len(name) < 44:
            lines[-1] += f", {name}"
        else:
            lines.append(name)
    rows += [["not in folder" if j == 0 else "", ln] for j, ln in enumerate(lines)]
    return rows


def _degenerate_row(rows, res, key):
    d = res.get(key, "mixture", "degenerate")
    if d and d is not True:
        rows.append([f"{'NDF' if key == 'ndf' else 'thickness'} fit note",
                     _shorten(str(d), 46)])
    elif d is True:
        rows.append([f"{'NDF' if key == 'ndf' else 'thickness'} fit note", "degenerate"])


def _pct(v):
    v = _number(v)
    return None if v is None else 100.0 * v


def _range_text(a, unit):
    v = _finite(a)
    if v.size == 0:
        return "—"
    lo, hi = np.percentile(v, [1, 99])
    return f"{lo:.4g} to {hi:.4g} {unit}"


def _shorten(s, n):
    return s if len(s) <= n else "…" + s[-(n - 1):]


def _style_table(t, *, fontsize):
    t.auto_set_font_size(False)
    t.set_fontsize(fontsize)
    for (r, c), cell in t.get_celld().items():
        cell.set_edgecolor("0.8")
        cell.PAD = 0.03
        if r == 0 and cell.get_text().get_text() in ("quantity", "value"):
            cell.set_facecolor("#e8eef7")
            cell.get_text().set_fontweight("bold")
        elif c == 0:
            cell.get_text().set_color("0.25")


# --------------------------------------------------------------------------- entry point
def write_report(results_dir, *, out_pdf=None, png_dir=None) -> Path:
    """Write the multi-page PDF report (and optional PNGs) of an analysis results folder.

    Parameters
    ----------
    results_dir : path-like
        A results folder (``/work/shared/spec/results-format.md``). ``summary.json`` is
        required; every other file is optional and a missing one skips its panel:
        ``all_in_focus.png``, ``height_um.npy``, ``thickness_nm.npy``, ``tilt_deg.npy``,
        ``tilt_sigma_deg.npy``, ``thickness_pdf.csv``, ``ndf_pdf.csv``,
        ``thickness_roi.csv``, ``mask.npy`` (bool, True = masked), ``delta_e.npy``
        (ΔE00 per pixel), ``tilt_height_deg.npy`` (tilt from the height map) and
        ``angular_map.png`` (a predicted angular colour map, light angle down, view angle
        across; its axes are labelled in degrees if ``summary.json`` has
        ``angular_map.theta_light_deg`` and ``.theta_view_deg``).
    out_pdf : path-like, optional, keyword-only
        Where to write the PDF; default ``results_dir / "report.pdf"``. It is written under
        a temporary name and renamed when complete.
    png_dir : path-like, optional, keyword-only
        If given, each page is also written there as ``report_<n>_<name>.png``
        (names in :data:`PAGES`); the folder is created if needed.

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
    Pages (A4 landscape): 1 overview (all-in-focus image, height map, mask, inputs);
    2 maps (thickness, ΔE00, tilt from colour, tilt 1σ, tilt from height); 3 thickness and
    facet-tilt histograms with the fitted mixtures and their components (seed Figs. 18a, 19);
    4 table of fitted parameters and the predicted angular map. Map axes are in µm when
    ``summary["inputs"]["pixel_size_um"]`` is given, else in pixels. Maps are
    block-averaged to at most :data:`MAX_MAP_PX` pixels a side and colour limits are the
    1st–99th percentiles (arrows on the colour bar mark values beyond them).

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
    geom = _Geometry(_positive_or_none(res.get("inputs", "pixel_size_um")))

    # Figure objects render through their own Agg canvas: no global backend switch, so
    # a Jupyter session calling this keeps its inline backend.
    import matplotlib
    from matplotlib.backends.backend_pdf import PdfPages
    from matplotlib.figure import Figure

    from . import __version__

    shown = _display_path(results_dir)
    title = f"microfacet report — {shown.name}"
    names = {"overview": "overview", "maps": "thickness, tilt and colour-difference maps",
             "distributions": "thickness and facet-normal distributions",
             "parameters": "fitted parameters"}
    tmp = out_pdf.with_name(f".{out_pdf.name}.partial-{os.getpid()}")
    out_pdf.parent.mkdir(parents=True, exist_ok=True)
    if png_dir is not None:
        png_dir = Path(png_dir)
        png_dir.mkdir(parents=True, exist_ok=True)
    try:
        with matplotlib.rc_context(_RC), PdfPages(tmp, metadata={
                "Title": title, "Creator": f"microfacet {__version__}"}) as pdf:
            for i, page in enumerate(PAGES, start=1):
                fig = Figure(figsize=_A4_LANDSCAPE_IN, layout="constrained")
                fig.get_layout_engine().set(h_pad=0.08, w_pad=0.08, hspace=0.06, wspace=0.04)
                fig.suptitle(f"{title}: {names[page]}", fontweight="bold")
                if page == "overview":
                    _page_overview(fig, res, geom)
                elif page == "maps":
                    _page_maps(fig, res, geom)
                elif page == "distributions":
                    _page_distributions(fig, res, geom, thick_mix, ndf_mix)
                else:
                    _page_parameters(fig, res, thick_mix, ndf_mix)
                fig.supxlabel(f"{_shorten(str(shown), 90)}   ·   grey pixels: masked or "
                              f"not available (NaN)   ·   page {i} of {len(PAGES)}",
                              fontsize=8, color="0.4")
                pdf.savefig(fig, dpi=_PDF_DPI)
                if png_dir is not None:
                    fig.savefig(png_dir / f"report_{i}_{page}.png", dpi=_PNG_DPI)
        os.replace(tmp, out_pdf)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return out_pdf


def _display_path(results_dir: Path) -> Path:
    """The folder's final name: ``.OUT.partial-xyz`` (being written) is shown as ``OUT``."""
    p = results_dir.resolve()
    m = re.fullmatch(r"\.(.+)\.partial-[^/]*", p.name)
    return p.with_name(m.group(1)) if m else p


def _positive_or_none(v):
    v = _number(v)
    return v if v is not None and v > 0 else None
