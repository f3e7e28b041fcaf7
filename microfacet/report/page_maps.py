"""Page 2 of the report, **maps**: oxide thickness (nm), the thickness component of each pixel
(seed Fig. 18c), the ΔE00 of the colour inversion, facet tilt from colour (°), facet tilt from
the height map (°, same colour scale) and the tilt's 1-σ uncertainty (°)."""

from __future__ import annotations

import numpy as np

from .layout import (
    CMAPS,
    DE,
    blank_panel,
    category_panel,
    component_colour,
    map_panel,
)

__all__ = ["NAME", "TITLE", "draw"]

NAME = "maps"
TITLE = "thickness, tilt and colour-difference maps"
#: Whether the page reads the folder's maps or images (after the last page that does, the
#: report lets them go).
READS_MAPS = True


def component_codes(thickness, mix):
    """Index of the most probable component of ``mix`` for each pixel (−1 where NaN).

    Parameters
    ----------
    thickness : ndarray (H, W)
        Thickness, nm.
    mix : ThicknessMixture

    Returns
    -------
    ndarray (H, W) of int8

    Examples
    --------
    >>> from microfacet.core.distributions import ThicknessMixture
    >>> mix = ThicknessMixture([(0.5, 100.0, 2.0), (0.5, 120.0, 2.0)])
    >>> component_codes(np.array([[99.0, 121.0, np.nan]]), mix).tolist()
    [[0, 1, -1]]
    """
    codes = np.full(thickness.shape, -1, np.int8)
    ok = np.isfinite(thickness)
    if not ok.any():
        return codes
    d = thickness[ok].astype(np.float64)[:, None]
    w, m, s = mix.weights, mix.means_nm, mix.sds_nm
    logp = np.log(w) - np.log(s) - 0.5 * ((d - m) / s) ** 2
    codes[ok] = np.argmax(logp, axis=1)
    return codes


def draw(pg, ctx):
    """Draw the maps page (2 × 3 maps).

    Parameters
    ----------
    pg : microfacet.report.layout.Page
    ctx : microfacet.report.context.Context
    """
    res, geom = ctx.res, ctx.geom
    thick = res.map("thickness_nm")
    de = res.map("delta_e")
    tilt = res.map("tilt_deg")
    sig = res.map("tilt_sigma_deg")
    tilt_h = res.map("tilt_height_deg")
    cells = pg.grid(2, 3, vgap=0.15)
    shape = next((a.shape for a in (thick, de, tilt, sig, tilt_h) if a is not None), (1, 1))
    # one colour scale for both tilt maps, so they can be compared
    tilt_lim = ctx.limits(("tilt_deg", "tilt_height_deg"), 0.0, 99.0, floor=0.0)
    if thick is not None:
        map_panel(pg, cells[0], thick, geom, title="oxide thickness",
                  label="thickness (nm)", cmap=CMAPS["thickness"],
                  limits=ctx.limits("thickness_nm"), no_value=ctx.no_value("thickness_nm"))
    else:
        blank_panel(pg, cells[0], "thickness_nm.npy is not in the folder", "oxide thickness",
                    shape=shape)
    if thick is not None and ctx.thick is not None:
        k = len(ctx.thick.components)
        names = [f"{i + 1}: {c[1]:.0f} nm" for i, c in enumerate(ctx.thick.components)]
        # the component of the pixels drawn only; no value exactly where thickness has none
        category_panel(pg, cells[1], thick, geom, title="thickness component (seed Fig. 18c)",
                       to_codes=lambda t: component_codes(t, ctx.thick),
                       colours=[component_colour(i) for i in range(k)], names=names,
                       label="", no_value=ctx.no_value("thickness_nm"))
    else:
        blank_panel(pg, cells[1], "no fitted thickness mixture", "thickness component",
                    shape=shape)
    if de is not None:
        map_panel(pg, cells[2], de, geom, title="colour difference of the fit",
                  label=f"{DE} (CIEDE2000)", cmap=CMAPS["delta_e"],
                  limits=ctx.limits("delta_e", 0.0, 99.0, floor=0.0),
                  no_value=ctx.no_value("delta_e"))
    else:
        blank_panel(pg, cells[2], "delta_e.npy is not in the folder", "colour difference",
                    shape=shape)
    if tilt is not None:
        map_panel(pg, cells[3], tilt, geom, title="facet tilt from colour",
                  label="tilt from optical axis (°)", cmap=CMAPS["tilt"], limits=tilt_lim,
                  no_value=ctx.no_value("tilt_deg"))
    else:
        blank_panel(pg, cells[3], "tilt_deg.npy is not in the folder",
                    "facet tilt from colour", shape=shape)
    if tilt_h is not None:
        map_panel(pg, cells[4], tilt_h, geom, title="facet tilt from the height map",
                  label="tilt from optical axis (°)", cmap=CMAPS["tilt"], limits=tilt_lim,
                  no_value=ctx.no_value("tilt_height_deg"))
    else:
        blank_panel(pg, cells[4], "tilt_height_deg.npy is not in the folder",
                    "facet tilt from the height map", shape=shape)
    if sig is not None:
        map_panel(pg, cells[5], sig, geom, title="tilt uncertainty (1σ)",
                  label="tilt 1σ (°)", cmap=CMAPS["sigma"],
                  limits=ctx.limits("tilt_sigma_deg", 0.0, 99.0, floor=0.0),
                  no_value=ctx.no_value("tilt_sigma_deg"))
    else:
        blank_panel(pg, cells[5], "tilt_sigma_deg.npy is not in the folder",
                    "tilt uncertainty", shape=shape)
