"""Page 3 of the report, **distributions**: the thickness histogram with the fitted Gaussian
mixture and each component (seed Fig. 18a); the per-pixel tilt histogram with the NDF mixture
and its lobes (seed Fig. 19); the same NDF as D(θ) per steradian (log scale); the ΔE00
histogram.

The histograms are those of ``thickness_pdf.csv`` and ``ndf_pdf.csv``; without them, the
histograms of the maps (densities of :func:`microfacet.core.densities.histogram_density`),
and without those the fitted mixture alone.
"""

from __future__ import annotations

import functools
import math
import re

import numpy as np

from ..core.densities import cell_edges, ndf_D_from_tilt_histogram
from ..core.distributions import NDFMixture, ThicknessMixture
from ..core.lazy import load
from .arrays import value_stats
from .layout import (
    DE,
    HEIGHT_TILT,
    HIST_EDGE,
    HIST_FILL,
    component_colour,
    finite,
    histogram,
    number,
    quantile_range,
    wrap,
)

mticker = load("matplotlib.ticker")

__all__ = ["NAME", "TITLE", "draw"]

NAME = "distributions"
TITLE = "thickness and facet-normal distributions"
#: Whether the page reads the folder's maps or images (after the last page that does, the
#: report lets them go).
READS_MAPS = True


def draw(pg, ctx):
    """Draw the distributions page (2 × 2 plots).

    Parameters
    ----------
    pg : microfacet.report.layout.Page
    ctx : microfacet.report.context.Context
    """
    cells = pg.grid(2, 2, hgap=0.25, vgap=0.10, heights=[1.25, 1.0])
    ax_t, ax_n, ax_d, ax_e = (_hist_axes(pg, c) for c in cells)
    _thickness_panel(ax_t, ctx)
    x, dens = _tilt_panel(ax_n, ctx)
    ndf_ok, ndf_why = ctx.identification("ndf")
    _ndf_panel(ax_d, x, dens, ctx.ndf if ndf_ok else None, hi=float(ax_n.get_xlim()[1]))
    _self_check_note(ax_d, ctx.res.get("ndf", "self_check"),
                     ctx.res.get("ndf", "mixture", "width_correction"))
    if not ndf_ok:
        _not_identified(ax_d, ndf_why)
    _delta_e_panel(ax_e, ctx)


def _se(check, key) -> str:
    """`` ± SE`` of a self-check's transfer (``key`` in ``ndf.self_check``), or nothing."""
    v = check.get(key)
    return "" if v is None else f" ± {v:.2f}"


def _self_check_note(ax, check, correction=None):
    """The NDF's self-check (``ndf.self_check``) in the panel's lower left corner: the
    recovered/injected slope gain, per injected width, the width the NDF would see and the
    injected domes' gain;
    where the lobes were corrected for that width (``ndf.mixture.width_correction``), so."""
    if not isinstance(check, dict) or check.get("transfer") is None:
        return
    per = ", ".join("–" if v is None else f"{v:.2f}" for v in check.get("ratio") or [])
    wt = check.get("width_transfer")
    width = ("" if wt is None else
             f"; width after noise removal {wt:.2f}{_se(check, 'width_transfer_se')}×")
    fixed = (f"\nlobes scaled ×{correction['scale']:.2f} to the planes' RMS slope over it "
             f"(ndf.mixture.width_correction)"
             if isinstance(correction, dict) and correction.get("scale") is not None else "")
    dome = check.get("dome_transfer")
    domes = "" if dome is None else (f"; domes {dome:.2f}"
                                     f"{_se(check, 'dome_transfer_se')}× (planar-facet check "
                                     f"over it)")
    ax.text(0.01, 0.02, f"self-check: injected slopes recovered at {check['transfer']:.2f}"
            f"{_se(check, 'transfer_se')}×"
            f"{width}{domes}\n({per} at 0.5, 1, 2× the width; ndf.self_check){fixed}",
            transform=ax.transAxes, ha="left", va="bottom", fontsize=6.5, color="0.25")


def _hist_axes(pg, cell):
    x, y, w, h = cell
    return pg.axes(x + 0.72, y + 0.48, w - 0.72 - 0.12, h - 0.48 - 0.30)


def _not_identified(ax, reason):
    """The plain statement, inside the panel, that its distribution was not identified (no
    components are drawn)."""
    text = "NOT IDENTIFIED: the fit is not a measurement\n" + "\n".join(wrap(reason, 60))
    ax.text(0.5, 0.55, text, ha="center", va="center", transform=ax.transAxes, fontsize=7.5,
            color="#a00000", bbox=dict(boxstyle="round", fc="white", ec="#a00000", lw=0.8),
            zorder=10)


def _sd_not_measured(ctx) -> dict:
    """Mean → why, for the thickness components whose spread is not measured: SD at the
    floor (summary.json's ``thickness.mixture.sd_at_floor``) or on one region
    (``sd_one_region``)."""
    comps = ctx.thick.components if ctx.thick is not None else ()
    out = {}
    for key, why in (("sd_one_region", "one region"), ("sd_at_floor", "at the floor")):
        for i in ctx.res.get("thickness", "mixture", key) or []:
            if i < len(comps):
                out[comps[i][1]] = why
    return out


def _candidate_lines(ax, ctx) -> int:
    """The reported candidate populations (``thickness.mixture.candidates``) as dashed
    lines: a population the field is too small to decide. Returns the legend entries."""
    cands = [c for c in ctx.res.get("thickness", "mixture", "candidates") or []
             if c.get("reported")]
    for i, c in enumerate(cands):
        ax.axvline(c["mean_nm"], color="#b05000", ls="--", lw=0.9, zorder=4,
                   label=None if i else "candidate population (field too small to decide)")
    return int(bool(cands))


def _thickness_panel(ax, ctx):
    """Seed Fig. 18a: thickness histogram, mixture components and the ROI thicknesses."""
    ok, why = ctx.identification("thickness")
    mix = ctx.thick if ok else None
    csv_t = ctx.density_table("thickness_pdf")
    if csv_t is not None:
        x, dens, mixd = csv_t["thickness_nm"], csv_t["density"], csv_t["mixture_density"]
        mixd = mixd if ok else None
        src = "thickness_pdf.csv"
    else:
        lo_hi = ctx.thick.support_nm() if ctx.thick is not None else (None, None)
        h = histogram(finite(ctx.res.map("thickness_nm"), ctx.mask), *lo_hi)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "thickness_nm.npy"
    rng = quantile_range(x, dens) if x is not None else None
    if ctx.thick is not None:
        s_lo, s_hi = ctx.thick.support_nm()
        rng = (min(rng[0], s_lo), max(rng[1], s_hi)) if rng else (s_lo, s_hi)
    if rng is not None:
        pad = max(0.06 * (rng[1] - rng[0]), 2.0)
        rng = (max(0.0, rng[0] - pad), rng[1] + pad)
    unmeasured = _sd_not_measured(ctx)
    n = _density_panel(
        ax, x, dens, mixd, mix, src=src, unit="nm", what="oxide thickness",
        comp_pdf=lambda m, g: m.pdf(g),
        comp_label=lambda c: f"weight {c[0]:.2f}, mean {c[1]:.1f} nm, " + (
            f"SD not measured ({unmeasured[c[1]]})" if c[1] in unmeasured
            else f"SD {c[2]:.2f} nm"),
        xrange=rng or (0.0, 1.0))
    roi = ctx.res.table("thickness_roi")
    roi_t = roi["thickness_nm"][np.isfinite(roi["thickness_nm"])] if roi is not None else None
    if roi_t is not None and roi_t.size:
        ax.plot(roi_t, np.full(roi_t.shape, 0.0), ls="none", marker="^", ms=6, mew=0.6,
                mfc="white", mec="k", transform=ax.get_xaxis_transform(), clip_on=False,
                zorder=5, label=f"ROI thickness ({roi_t.size} ROI{'s' * (roi_t.size > 1)})")
        n += 1
    n += _candidate_lines(ax, ctx)
    _legend_room(ax, n, top=_clip_top(ax, x, dens, _curves(ax, x)))
    _legend(ax, x, dens)
    if not ok:
        _not_identified(ax, why)
    ax.set_title("oxide thickness distribution (seed Fig. 18a)")


def _tilt_panel(ax, ctx):
    """Seed Fig. 19: per-pixel tilt histogram, NDF lobes, tilt from the height map; returns
    the tilt histogram ``(centres, density)`` (None, None if there is none)."""
    mt = ctx.max_tilt()
    hi = mt or (float(min(89.0, 4.0 * ctx.ndf.sds_deg.max())) if ctx.ndf is not None
                else 30.0)
    ok, why = ctx.identification("ndf")
    mix = ctx.ndf if ok else None
    csv_n = ctx.density_table("ndf_pdf")
    if csv_n is not None:
        x, dens, mixd = csv_n["tilt_deg"], csv_n["density"], csv_n["mixture_density"]
        mixd = mixd if ok else None
        src = "ndf_pdf.csv"
    else:
        h = histogram(finite(ctx.res.map("tilt_deg"), ctx.mask), 0.0, hi, bins=60)
        x, dens = h if h is not None else (None, None)
        mixd, src = None, "tilt_deg.npy"
    top = float(cell_edges(x)[1][-1]) if x is not None else hi
    n = _density_panel(
        ax, x, dens, mixd, mix, src=src, unit="°", what="facet tilt from optical axis",
        comp_pdf=lambda m, g: m.tilt_pdf(g),
        comp_label=lambda c: (f"weight {c[0]:.2f}, slope SD {c[1]:.2f}° "
                              f"(tan {math.tan(math.radians(c[1])):.3f})"),
        xrange=(0.0, max(top, hi if x is None else top)))
    lo, top = ax.get_xlim()
    h = histogram(finite(ctx.res.map("tilt_height_deg"), ctx.mask), max(0.0, lo), top,
                  bins=60)
    if h is not None:
        _stairs(ax, h[1], cell_edges(h[0])[1], color=HEIGHT_TILT, lw=1.0,
                label="tilt from the height map (histogram)")
        n += 1
    if mt:
        ax.axvline(mt, color="0.3", lw=0.8, ls=":",
                   label=f"measurable limit asin(NA)/2 = {mt:.1f}°")
        n += 1
    _legend_room(ax, n, top=_clip_top(ax, x, dens, _curves(ax, x)))
    _legend(ax, x, dens)
    if not ok:
        _not_identified(ax, why)
    ax.set_title("facet tilt distribution, per pixel (seed Fig. 19)")
    return x, dens


def _density_panel(ax, x, dens, mixd, mix, *, src, unit, what, comp_pdf, comp_label,
                   xrange):
    """Histogram density (grey), each component (coloured, filled lightly) and the fitted
    mixture (black); returns the number of legend entries."""
    n = 0
    lo, hi = xrange
    if x is not None:
        e = cell_edges(x)[1]
        if e[0] < 0 <= x[0]:
            e[0] = 0.0
        d = np.nan_to_num(np.asarray(dens, dtype=np.float64))
        _stairs(ax, d, e, fill=True, color=HIST_FILL, label=f"histogram ({src})")
        _stairs(ax, d, e, color=HIST_EDGE, lw=0.6)
        n += 1
    grid = np.linspace(lo, hi, 600)
    if mix is not None:
        single = ThicknessMixture if isinstance(mix, ThicknessMixture) else NDFMixture
        for i, c in enumerate(mix.components):
            g = c[0] * comp_pdf(single([(1.0,) + tuple(c[1:])]), grid)
            ax.fill_between(grid, g, color=component_colour(i), alpha=0.12, lw=0)
            ax.plot(grid, g, lw=1.5, color=component_colour(i),
                    label=f"{i + 1}: {comp_label(c)}")
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


def _ndf_panel(ax, x, dens, mix, *, hi):
    """D(θ) per steradian (∫ D cos θ dω = 1) on a log scale: the NDF as the seed's Fig. 19
    draws it (mode at 0°); the histogram by :func:`ndf_D_from_tilt_histogram`."""
    ax.set_title("facet normal distribution D(θ)")
    n = 0
    top, bottoms = [], []
    if x is not None:
        e = cell_edges(x)[1]
        e[0] = max(e[0], 0.0)
        Dh = ndf_D_from_tilt_histogram(x, dens)
        Dh = np.where(np.isfinite(Dh) & (Dh > 0), Dh, np.nan)
        if np.isfinite(Dh).any():
            ax.stairs(Dh, e, color=HIST_EDGE, lw=0.9, label="from the tilt histogram")
            top.append(np.nanmax(Dh))
            bottoms.append(np.nanpercentile(Dh, 5))
            n += 1
    grid = np.linspace(0.0, hi, 400)
    if mix is not None:
        for i, c in enumerate(mix.components):
            ax.plot(grid, c[0] * NDFMixture([(1.0, c[1])]).D(grid), color=component_colour(i),
                    lw=1.5, label=f"lobe {i + 1}: Beckmann α {mix.beckmann_alpha[i]:.3f}")
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
        _plain_log_labels(ax.yaxis)
        ax.set_ylim(b, t * 10 ** (0.12 * n + 0.3) if n else t * 3)
        _legend(ax)
    else:
        ax.text(0.5, 0.5, "no tilt histogram and no fitted NDF", ha="center", va="center",
                transform=ax.transAxes, color="0.35")


def _delta_e_panel(ax, ctx):
    ax.set_title("colour difference of the fit, per pixel")
    res = ctx.res
    v = finite(res.map("delta_e"), ctx.mask)
    ax.set_xlabel(f"{DE} (CIEDE2000) between pixel and model colour")
    ax.set_ylabel(f"fraction of pixels per unit {DE}")
    hi = max(value_stats(v, [99.0])[0][0], 1.0) if v.size else 1.0
    h = histogram(v, 0.0, hi, bins=80)
    if h is None:
        ax.text(0.5, 0.5, "no ΔE₀₀ values (delta_e.npy absent or all masked)",
                ha="center", va="center", transform=ax.transAxes, color="0.35")
        return
    c, d = h
    e = cell_edges(c)[1]
    _stairs(ax, d, e, fill=True, color=HIST_FILL, label="histogram (delta_e.npy, 0–99 %)")
    _stairs(ax, d, e, color=HIST_EDGE, lw=0.6)
    mean = number(res.get("delta_e", "mean"))
    med = number(res.get("delta_e", "median"))
    mean = float(v.mean(dtype=np.float64)) if mean is None else mean
    med = float(np.median(v)) if med is None else med
    ax.axvline(mean, color="#d62728", lw=1.2, label=f"mean {mean:.2f}")
    ax.axvline(med, color="#1f77b4", lw=1.2, ls="--", label=f"median {med:.2f}")
    p95 = number(res.get("delta_e", "p95"))
    if p95 is not None and p95 <= hi:
        ax.axvline(p95, color="0.3", lw=1.0, ls=":", label=f"95th percentile {p95:.2f}")
    ax.set_xlim(0.0, hi)
    _legend_room(ax, 4)
    _legend(ax, c, d)


def _stairs(ax, values, edges, **kw):
    """``ax.stairs(values, edges, baseline=0, **kw)``, its data limits set from a stand-in
    of two bins spanning the same box: for the real path matplotlib evaluates every
    segment in Python (slow for the hundreds of bins of a density table)."""
    v = np.asarray(values, dtype=np.float64)
    ok = v[np.isfinite(v)]
    lo, hi = (float(ok.min()), float(ok.max())) if ok.size else (0.0, 0.0)
    patch = ax.stairs([hi, lo], [edges[0], 0.5 * (edges[0] + edges[-1]), edges[-1]], **kw)
    patch.set_data(v, edges)
    return patch


_SUPERSCRIPTS = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def plain_math(s):
    r"""A tick label of matplotlib's log formatter in plain text: mathtext is parsed again
    for every renderer (the PDF and each PNG), which costs more than the rest of the axis.

    >>> plain_math(r"$\mathdefault{10^{-3}}$"), plain_math(r"$\mathdefault{2\times10^{1}}$")
    ('10⁻³', '2×10¹')
    >>> plain_math("")
    ''
    """
    m = re.fullmatch(r"\$\\mathdefault\{(.*)\}\$", s)
    if not m:
        return s
    body = re.sub(r"\^\{(-?\d+)\}", lambda e: e.group(1).translate(_SUPERSCRIPTS),
                  m.group(1).replace(r"\times", "×"))
    return s if any(c in body for c in "\\{}^$") else body.replace("-", "−")


@functools.cache
def _plain_log_formatter():
    class PlainLogFormatter(mticker.LogFormatterSciNotation):
        """matplotlib's log-axis labels (10⁻³, 2×10⁻³) as plain text (:func:`plain_math`)."""

        def __call__(self, x, pos=None):
            return plain_math(super().__call__(x, pos))
    return PlainLogFormatter


def _plain_log_labels(axis):
    """The log scale's own major and minor formatters, in plain text, and minor ticks at 2
    and 5 times each power of ten (matplotlib's eight a decade made 48 ticks over this
    panel's six decades, each of them five artists drawn for the PDF and again for the
    PNG: ~0.05 s a rendering)."""
    cls = _plain_log_formatter()
    axis.set_major_formatter(cls(10.0))
    axis.set_minor_formatter(cls(10.0, labelOnlyBase=True))
    axis.set_minor_locator(mticker.LogLocator(10.0, subs=(2.0, 5.0)))


# --------------------------------------------------------------------------- legends
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


def _legend_room(ax, n_entries, *, frac_per_entry=0.075, base=1.06, top=None):
    """Raise the y limit so a legend of ``n_entries`` in the upper right covers no data
    (``top``: the highest value to show, default the data's)."""
    if top is None:  # every artist updated the data limits when added (collections too)
        top = ax.dataLim.y1
    top = top if np.isfinite(top) and top > 0 else 1.0
    ax.set_ylim(0.0, top * (base + frac_per_entry * n_entries))


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
