"""Page 1 of the report, **overview**: the all-in-focus image, the height map (µm), the colour
mask and two tables: the inputs (image size, pixel size, field of view, focal planes, NA) and
what the mask removed, by reason."""

from __future__ import annotations

import numpy as np

from .layout import (
    CMAPS,
    NO_VALUE,
    blank_panel,
    category_panel,
    draw_table,
    fmt,
    image_axes,
    map_panel,
    number,
    pct,
    shorten,
    shown,
)

__all__ = ["NAME", "TITLE", "draw"]

NAME = "overview"
TITLE = "overview"
#: Whether the page reads the folder's maps or images (after the last page that does, the
#: report lets them go).
READS_MAPS = True


def draw(pg, ctx):
    """Draw the overview page.

    Parameters
    ----------
    pg : microfacet.report.layout.Page
    ctx : microfacet.report.context.Context
    """
    res, geom = ctx.res, ctx.geom
    aif = res.image("all_in_focus")
    height = res.map("height_um")
    # the colour mask, else the pixels without a thickness; drawn pixels only as codes
    mask, mask_note, frac, to_codes = ctx.mask, "", None, _as_codes
    if mask is not None:
        frac = np.count_nonzero(mask) / max(mask.size, 1)
    else:
        mask = res.map("thickness_nm")
        if mask is not None:
            mask_note, frac, to_codes = " (no thickness)", ctx.no_value("thickness_nm"), \
                _no_value_codes
    # two large maps on top; the mask and two tables below
    bottom_h = 3.0
    top_cells = pg.grid(1, 2, bottom=pg.bottom + bottom_h)
    low = pg.grid(1, 3, top=pg.bottom + bottom_h, widths=[3.45, 3.9, 3.45], hgap=0.0)
    cells = [top_cells[0], top_cells[1], low[0]]
    # ---- maps
    if aif is not None:
        ax, box = image_axes(pg, cells[0], aif.shape, geom)
        small, _ = shown(aif, box)
        ax.imshow(small, cmap="gray" if small.ndim == 2 else None, vmin=0, vmax=1,
                  aspect="auto", extent=geom.extent(aif.shape), interpolation="antialiased")
        ax.set_title("all-in-focus image")
        geom.scale_bar(ax, aif.shape)
    else:
        blank_panel(pg, cells[0], "all_in_focus.png is not in the folder",
                    "all-in-focus image")
    source = ("microscope export" if ctx.inputs.get("height_source") == "microscope export"
              else "from focus")
    if height is not None:
        map_panel(pg, cells[1], height, geom, title=f"height ({source})",
                  label="height (µm)", cmap=CMAPS["height"], limits=ctx.limits("height_um"),
                  no_value=ctx.no_value("height_um"))
    else:
        blank_panel(pg, cells[1], "height_um.npy is not in the folder", f"height ({source})")
    if mask is not None:
        category_panel(pg, cells[2], mask, geom, to_codes=to_codes,
                       colours=("#f3f3f3", NO_VALUE), names=("used", "masked"), label="",
                       title=f"colour mask{mask_note}: {100 * frac:.1f} % masked",
                       no_value=None)
    else:
        blank_panel(pg, cells[2], "mask.npy is not in the folder", "colour mask")
    # ---- tables
    x, y, w, h = low[1]
    top = y + h - 0.25
    draw_table(pg, x, top, w - 0.2, _input_rows(ctx), col_widths=[0.36, 0.64],
               title="inputs", fontsize=8.0)
    x, y, w, h = low[2]
    draw_table(pg, x + 0.05, top, w - 0.05, _mask_rows(ctx), col_widths=[0.66, 0.34],
               title="masked pixels (reasons overlap)", fontsize=8.0)


def _input_rows(ctx):
    res, geom, inputs = ctx.res, ctx.geom, ctx.inputs
    shape = None
    for a in (res.map("height_um"), ctx.mask, res.map("thickness_nm")):
        if a is not None:
            shape = a.shape[:2]
            break
    if shape is None:
        s = inputs.get("shape")
        if isinstance(s, list) and len(s) >= 2 and all(number(v) for v in s[:2]):
            shape = (int(s[0]), int(s[1]))
    rows = []
    if ctx.stack:
        rows.append(["stack", shorten(ctx.stack, 38)])
    rows += [
        ["image size", f"{shape[1]} × {shape[0]} pixels" if shape else "—"],
        ["pixel size", geom.size_text()],
        ["field of view", geom.field_text(shape)],
    ]
    z = inputs.get("z_um_range")
    n = inputs.get("n_slices")
    if n is not None or z is not None:
        zs = (f", z {z[0]:.3g} to {z[1]:.3g} µm" if isinstance(z, list) and len(z) == 2
              and all(number(v) is not None for v in z) else "")
        rows.append(["focal planes", f"{fmt(n, '.0f')}{zs}"])
    na = number(inputs.get("numerical_aperture"))
    if na is not None:
        mt = ctx.max_tilt()
        rows.append(["numerical aperture", f"{na:.3g}" + (
            f" (tilt ≤ asin(NA)/2 = {mt:.1f}°)" if mt else "")])
    rows.append(["height, 1–99 %", _range_text(ctx, "height_um", "µm")])
    return rows


def _mask_rows(ctx):
    res = ctx.res
    rows = [["masked (any reason)", fmt(pct(res.get("masked_fraction")), ".1f", "%")]]
    m = res.get("mask")
    if isinstance(m, dict):
        for k, name in (("low_saturation", "low saturation"), ("dark", "dark"),
                        ("clipped", "clipped (over-exposed)"), ("shadow", "shadow"),
                        ("steep", "steep (past the acceptance)"),
                        ("dark_feature", "dark features (scratches, walls)"),
                        ("invalid", "invalid (NaN)")):
            if k in m:
                rows.append([f"   {name}", fmt(pct(m[k]), ".1f", "%")])
        for k, name in (("grey_film", "grey film analysed (S below it)"),
                        ("clipped_one", "one channel clipped, analysed")):
            if m.get(k):
                rows.append([name, fmt(pct(m[k]), ".1f", "%")])
    s_min, v_min = res.parameter("mask.saturation_min"), res.parameter("mask.value_min")
    if s_min is not None or v_min is not None:
        rows.append(["thresholds (0–255 HSV)", f"S ≥ {fmt(s_min, '.4g')}, V ≥ {fmt(v_min, '.4g')}"])
    uf = res.get("height", "unreliable_fraction")
    if uf is not None:
        rows.append(["height unreliable (no focus)", fmt(pct(uf), ".1f", "%")])
    return rows


def _as_codes(mask):
    return mask.astype(np.int8)


def _no_value_codes(a):
    return (~np.isfinite(a)).astype(np.int8)


def _range_text(ctx, name, unit):
    p = ctx.percentiles(name, (1.0, 99.0))
    if p is None:
        return "—"
    lo, hi = p[0]
    return f"{lo:.4g} to {hi:.4g} {unit}"
