"""Page 5 of the report, **angular colour**: the colour predicted over in-plane light × view
zenith angles from the fitted distributions — the microfacet thin-film BRDF and the
half-vector model (seed §2.3) of :func:`microfacet.forward.angular.simulate_map`, sharing one
film average (:func:`~microfacet.forward.angular.film_average_inplane`),
each shown at its :func:`~microfacet.forward.angular.display_exposure`, the one display rule
of every picture of an angular map (``microfacet simulate`` uses it too).

Without a fitted thickness mixture there is nothing to predict, and the page says so.
"""

from __future__ import annotations

import numpy as np

from ..colour.colorimetry import illuminant_key
from ..core.defaults import DEFAULT_ILLUMINANT
from ..forward.angular import (
    DISPLAY_CORE_DEG,
    display_exposure,
    film_average_inplane,
    simulate_map,
    with_exposure,
)
from ..optics.constants import DEFAULT_FILM, DEFAULT_SUBSTRATE, known_sets
from .layout import blank_panel, shorten

__all__ = ["NAME", "TITLE", "draw", "prepare"]

NAME = "angular"
TITLE = "predicted angular colour"
#: Whether the page reads the folder's maps or images (after the last page that does, the
#: report lets them go).
READS_MAPS = False
#: Light and view zenith angles of the maps, degrees.
ANGLES_DEG = np.arange(0.0, 85.0 + 1e-9, 1.0)
#: Wavelengths of the spectra, nm.
WAVELENGTH_NM = np.arange(380.0, 781.0, 10.0)
_TITLES = {"microfacet": "microfacet thin-film BRDF (fitted thickness mixture and NDF)",
           "half-vector": "half-vector model (fitted thickness mixture; seed §2.3, Fig. 10)"}


def optics(ctx) -> dict:
    """``film``, ``substrate`` and ``illuminant`` as recorded in the results folder, or all
    three defaults if one of them is not known here.

    Parameters
    ----------
    ctx : microfacet.report.context.Context

    Returns
    -------
    dict
    """
    out = dict(film=ctx.optics("film") or DEFAULT_FILM,
               substrate=ctx.optics("substrate") or DEFAULT_SUBSTRATE,
               illuminant=ctx.optics("illuminant") or DEFAULT_ILLUMINANT)
    try:
        illuminant_key(out["illuminant"])
        ok = out["film"] in known_sets() and out["substrate"] in known_sets()
    except (ValueError, TypeError):
        ok = False
    return out if ok else dict(film=DEFAULT_FILM, substrate=DEFAULT_SUBSTRATE,
                               illuminant=DEFAULT_ILLUMINANT)


def predicted_maps(ctx) -> list:
    """The angular maps of the fitted distributions, at their display exposure.

    Parameters
    ----------
    ctx : microfacet.report.context.Context

    Returns
    -------
    list of (str, AngularMap, str)
        (title, map, note saying how it is shown): the microfacet BRDF if there is an NDF,
        then the half-vector model; empty if there is no thickness mixture. Each map is
        :func:`~microfacet.forward.angular.with_exposure` of the simulated map at its
        :func:`~microfacet.forward.angular.display_exposure` (``meta["exposure"]``).
    """
    if ctx.thick is None:
        return []
    opt = optics(ctx)
    kw = dict(thickness=ctx.thick, theta_light_deg=ANGLES_DEG, theta_view_deg=ANGLES_DEG,
              wavelength_nm=WAVELENGTH_NM, **opt)
    # the film's reflectance at the grid's half angles, built once for both maps
    fa = film_average_inplane(ANGLES_DEG, ANGLES_DEG, thickness=ctx.thick,
                              wavelength_nm=WAVELENGTH_NM, film=opt["film"],
                              substrate=opt["substrate"])
    out = []
    for model in ("microfacet", "half-vector") if ctx.ndf is not None else ("half-vector",):
        m = simulate_map(model=model, ndf=ctx.ndf, film_average=fa, **kw)
        e = display_exposure(m)
        m = with_exposure(m, e) if e != 1.0 else m
        if model == "microfacet":
            note = (f"reflectance factor π·f_r × {e:.3g}: the 98th percentile of Y over "
                    f"angles ≤ {DISPLAY_CORE_DEG:g}° shown at 0.9 of white;\nbrighter cells "
                    f"(specular, grazing) clip to white")
        else:
            note = ("reflectance of the film at the half angle θ_d averaged over the "
                    f"thickness mixture,\nexposure {e:.3g} (a white diffuser is white)")
        out.append((_TITLES[model], m, note))
    return out


def prepare(ctx) -> None:
    """Compute the page's maps now, once for the folder (``ctx``'s cache): the report calls
    it before its PNG child forks, so that the PDF and the PNG pages draw the same maps
    without each computing them (0.2-0.4 s of thin-film optics; docs/benchmarks.md)."""
    _maps(ctx)


def _maps(ctx):
    """``(maps, None)`` of :func:`predicted_maps`, or ``(None, exception)`` if they cannot
    be predicted; computed once per context."""
    def compute():
        try:
            return predicted_maps(ctx), None
        except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
            return None, exc
    return ctx.cached(("angular", "predicted_maps"), compute)


def draw(pg, ctx):
    """Draw the angular-colour page: one or two maps side by side, with their notes.

    Parameters
    ----------
    pg : microfacet.report.layout.Page
    ctx : microfacet.report.context.Context
    """
    maps, exc = _maps(ctx)
    if exc is not None:
        blank_panel(pg, pg.content(),
                    f"the angular colour could not be predicted from the fitted "
                    f"distributions:\n{shorten(exc, 200)}")
        return
    if not maps:
        blank_panel(pg, pg.content(),
                    "no fitted thickness mixture in summary.json: no colour to predict")
        return
    cells = pg.grid(1, 2, hgap=0.4, top=pg.top - 0.05, bottom=pg.bottom + 0.55)
    if len(maps) == 1:
        cells = [(cells[0][0] + 0.5 * (cells[1][0] - cells[0][0]),) + cells[0][1:]]
    for cell, (title, m, note) in zip(cells, maps):
        _map(pg, cell, title, m, note)
    opt = optics(ctx)
    pg.text(0.5 * pg.W, pg.bottom + 0.25,
            f"In-plane light and view directions (rows: light zenith, columns: view zenith, "
            f"{ANGLES_DEG[0]:g}–{ANGLES_DEG[-1]:g}° in {ANGLES_DEG[1] - ANGLES_DEG[0]:g}° "
            f"steps); {opt['film']} on {opt['substrate']}, illuminant {opt['illuminant']}, "
            f"sRGB display.\nOther grids and models (seed eq. 6), and comparison with a "
            f"measured map: microfacet simulate --results <this folder>.",
            fontsize=7.5, color="0.3", ha="center", va="center", linespacing=1.3)


def _map(pg, cell, title, m, note):
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
            fontsize=7.5, rotation=-45, rotation_mode="anchor", ha="left", va="bottom")
    ax.set_xlabel("view zenith θ_view (°), + = mirror side")
    ax.set_ylabel("light zenith θ_light (°)")
    ax.set_title(title, fontsize=10)
    pg.text(x0 + 0.5 * side, y + h - 0.35 - side - 0.48, note, fontsize=7.5,
            color="0.3", ha="center", va="top", linespacing=1.3)
