"""Page 4 of the report, **parameters**: tables of the thickness components (weight, mean, SD),
the NDF lobes (weight, slope SD as an angle, tan, Beckmann α), the analysis (mode, exposure,
flat field, ΔE00, masking, optics, colour-table settings, ROIs), the height map's ISO 25178-2 areal
parameters (Sq, Sa, Sdq, Sdr, with SurfaceTopography's RMS height and gradient and the
analysis' own RMS slope beside them) and the run (timings, versions, the files missing from
the folder). :func:`parameter_tables` returns the same tables as strings."""

from __future__ import annotations

import math

from .context import Context
from .layout import DE, draw_table, fmt, number, pct, shorten, wrap

__all__ = ["NAME", "TITLE", "draw", "parameter_tables"]

NAME = "parameters"
TITLE = "fitted parameters"
#: Whether the page reads the folder's maps or images (after the last page that does, the
#: report lets them go).
READS_MAPS = False

_STEP_NAMES = {"height_from_focus": "height from focus", "colour_and_mask": "colour and mask",
               "thickness_roi": "thickness per ROI", "tilt_per_pixel": "tilt per pixel",
               "facet_fits": "facet fits", "mixtures": "mixture fits",
               "write": "writing the results"}


def parameter_tables(results_dir) -> dict:
    """The tables of the report's parameter page, as lists of rows of strings.

    Parameters
    ----------
    results_dir : path-like or Context
        A results folder, or one already opened for the report.

    Returns
    -------
    dict
        ``"thickness"`` (header ``component, weight, mean (nm), mean 1σ (nm), SD (nm)``:
        the mean's uncertainty with its white-balance part, summary.json
        ``thickness.mixture.mean_uncertainty``, "—" where unknown), ``"ndf"``
        (``lobe, weight, slope SD (°), tan(slope SD), Beckmann α``), ``"analysis"`` and
        ``"run"`` (``quantity, value`` pairs: versions, missing files), ``"iso25178"``
        (``parameter, value``: Sq, Sa, Sdq, Sdr by their ISO 25178-2 names, the reference
        plane, the RMS height and gradient of the map as measured, the normals' RMS slope;
        no rows without it), ``"timings"``
        (``step, time``), each ``{"header": [...], "rows": [[...]]}``; ``"thickness"`` and
        ``"ndf"`` also have a ``"note"`` on the fit. Numbers are formatted as printed:
        weights with 3 decimals, thickness mean with 1 and SD with 2 (nm), lobe SD with 2 (°).

    Raises
    ------
    InputError
        ``results_dir`` or its ``summary.json`` is missing or malformed.

    Examples
    --------
    >>> parameter_tables("results/sample1")["thickness"]["rows"][0]  # doctest: +SKIP
    ['1', '0.085', '108.0', '0.95', '1.28']
    """
    ctx = results_dir if isinstance(results_dir, Context) else Context.open(results_dir)
    out = {}
    rows = []
    if ctx.thick is not None:
        unc = ctx.res.get("thickness", "mixture", "mean_uncertainty") or []
        for i, (w, m, s) in enumerate(ctx.thick.components):
            u = unc[i] if i < len(unc) else {}
            rows.append([f"{i + 1}", f"{w:.3f}", f"{m:.1f}", fmt(u.get("sigma_nm"), ".2f"),
                         f"{s:.2f}"])
    out["thickness"] = {"header": ["component", "weight", "mean (nm)", "mean 1σ (nm)",
                                   "SD (nm)"],
                        "rows": rows, "note": _fit_note(ctx, "thickness", ctx.thick)}
    rows = []
    if ctx.ndf is not None:
        for i, (w, s) in enumerate(ctx.ndf.components):
            rows.append([f"{i + 1}", f"{w:.3f}", f"{s:.2f}",
                         f"{math.tan(math.radians(s)):.4f}",
                         f"{math.sqrt(2.0) * math.tan(math.radians(s)):.4f}"])
    out["ndf"] = {"header": ["lobe", "weight", "slope SD σ (°)", "tan σ", "Beckmann α"],
                  "rows": rows, "note": _fit_note(ctx, "ndf", ctx.ndf)}
    out["analysis"] = {"header": ["quantity", "value"], "rows": _analysis_rows(ctx)}
    out["iso25178"] = {"header": ["parameter", "value"], "rows": _iso25178_rows(ctx)}
    out["run"] = {"header": ["quantity", "value"], "rows": _run_rows(ctx)}
    out["timings"] = {"header": ["step", "time"], "rows": _timing_rows(ctx)}
    return out


def draw(pg, ctx):
    """Draw the parameters page: fits and run on the left, the analysis on the right.

    Parameters
    ----------
    pg : microfacet.report.layout.Page
    ctx : microfacet.report.context.Context
    """
    tables = parameter_tables(ctx)
    colw = 0.5 * (pg.right - pg.left - 0.4)
    xl, xr = pg.left, pg.left + colw + 0.4
    y = pg.top - 0.05
    for key, title, widths in (
            ("thickness", "oxide thickness: Gaussian mixture components",
             [0.17, 0.16, 0.22, 0.25, 0.2]),
            ("ndf", "facet normals: zero-mean Gaussian-slope (Beckmann) lobes",
             [0.12, 0.17, 0.27, 0.2, 0.24])):
        t = tables[key]
        rows = t["rows"] or [["—"] + ["no fit"] + [""] * (len(t["header"]) - 2)]
        y = draw_table(pg, xl, y, colw, rows, header=t["header"], col_widths=widths,
                       title=title, fontsize=8.5)
        if t["note"]:
            lines = wrap(t["note"], 92)
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
        y = draw_table(pg, xl, y, colw, rows, col_widths=[0.32, 0.18, 0.32, 0.18],
                       title="run time", fontsize=7.5, row_h=0.18) - 0.42
    rows = [[k if j == 0 else "", line] for k, v in tables["run"]["rows"]
            for j, line in enumerate(wrap(v, 70))]
    if rows:
        draw_table(pg, xl, y, colw, rows, col_widths=[0.22, 0.78], title="software",
                   fontsize=7.5, row_h=0.18)
    rows = [[k if j == 0 else "", line] for k, v in tables["analysis"]["rows"]
            for j, line in enumerate(wrap(v, 50))]
    y = draw_table(pg, xr, pg.top - 0.05, pg.right - xr, rows, col_widths=[0.40, 0.60],
                   title="analysis (summary.json)", fontsize=8.0) - 0.42
    rows = tables["iso25178"]["rows"]
    if rows:
        draw_table(pg, xr, y, pg.right - xr, rows, col_widths=[0.52, 0.48],
                   title="height map: ISO 25178-2 areal parameters", fontsize=7.5,
                   row_h=0.18)


def _fit_note(ctx, key, mix):
    res = ctx.res
    m = res.get(key, "mixture")
    if mix is None:
        return ("no fit (no usable pixels)" if isinstance(m, dict) else
                "no mixture in summary.json")
    parts = []
    bic = number(res.get(key, "mixture", "bic"))
    k = len(mix.components)
    by_k = res.get(key, "mixture", "bic_by_k")
    if bic is not None:
        tried = ""
        if isinstance(by_k, dict) and by_k:
            tried = (f"; k = 1–{len(by_k)} tried" if len(by_k) > 1 else "; only k = 1 tried")
        parts.append(f"{k} component{'s' * (k > 1)} by BIC ({bic:.6g}{tried})")
    ne, ns = number(res.get(key, "mixture", "n_effective")), \
        number(res.get(key, "mixture", "n_samples"))
    if ns is not None:
        parts.append(f"{ns:.0f} pixels" + (f", {ne:.0f} effective samples"
                                           if ne is not None else ""))
    margin = number(res.get(key, "mixture", "bic_margin"))
    if margin is not None:
        parts.append(f"BIC margin {margin:.1f}")
    d = res.get(key, "mixture", "degenerate")
    if d is True:
        parts.append("degenerate fit")
    elif isinstance(d, str) and d:
        parts.append(d)
    ident, reason = ctx.identification(key)
    if not ident:
        parts.insert(0, "NOT IDENTIFIED, not a measurement: " + reason)
    return "; ".join(parts)


def _analysis_rows(ctx):
    res = ctx.res
    s = res.summary
    p = res.parameters
    rows = []
    mode = s.get("mode") or p.get("mode")
    if mode:
        rows.append(["mode", str(mode) + {"joint": " (facet planes + colour)",
                                          "seed": " (the paper's ROI method)"}.get(mode, "")])
    for key in ("film", "substrate", "illuminant"):
        v = ctx.optics(key)
        if v:
            rows.append([key, shorten(v, 40)])
    src = s.get("exposure_source")
    rows.append(["exposure", fmt(s.get("exposure"), ".4g") + (f" ({src})" if src else "")])
    ff = s.get("flat_field")
    if isinstance(ff, dict):
        rows.append(["flat field (vignetting)",
                     f"{fmt(pct(ff.get('corner_loss')), '.0f', '%')} lost at the corners "
                     f"({ff.get('source')})" if ff.get("applied")
                     else f"none: {ff.get('reason')}"])
    rows += _order_rows(res)
    rows.append([f"{DE} mean / median / p95",
                 " / ".join(fmt(res.get("delta_e", k), ".2f")
                            for k in ("mean", "median", "p95"))])
    if "colour_noise_de" in s:
        rows.append([f"image colour noise ({DE})", fmt(s.get("colour_noise_de"), ".2f")])
    rows.append(["masked fraction", fmt(pct(s.get("masked_fraction")), ".1f", "%")])
    mt = ctx.max_tilt()
    if mt:
        rows.append(["largest measurable tilt", f"{mt:.1f}°"])
    ti = res.get("tilt_information")
    if isinstance(ti, dict):
        rows.append(["tilt 1σ, median", fmt(ti.get("tilt_sigma_deg_median"), ".2f", "°")])
        cd = pct(ti.get("colour_dominated_fraction"))
        if cd is not None:
            rows.append(["pixels whose tilt is set by colour", f"{cd:.1f} %"])
    roi = res.get("thickness", "roi")
    if isinstance(roi, dict):
        rows.append(["ROIs fitted / total",
                     f"{fmt(roi.get('fitted'), '.0f')} / {fmt(roi.get('count'), '.0f')}"
                     + (f", mean {fmt(roi.get('thickness_nm_mean'), '.1f', 'nm')}"
                        if number(roi.get("thickness_nm_mean")) is not None else "")
                     + (f", {roi['ambiguous_count']} ambiguous"
                        if number(roi.get("ambiguous_count")) else "")])
    rows += _parameter_rows(res, mode)
    ct = res.get("colour_table")
    if isinstance(ct, dict):
        rows.append(["colour table: steps",
                     f"{fmt(ct.get('thickness_step_nm'), '.3g', 'nm')} thickness, "
                     f"{fmt(ct.get('theta_step_deg'), '.3g', '°')} tilt, "
                     f"{fmt(ct.get('spectral_step_nm'), '.3g', 'nm')} wavelength"])
        rows.append([f"colour table: error ({DE})",
                     f"{fmt(ct.get('interp_error_de00'), '.3f')} interpolation, "
                     f"{fmt(ct.get('spectral_error_de00'), '.3f')} spectral"])
    return rows


def _order_rows(res):
    """The thicknesses' interference order (``thickness.order``: established, or the first
    reason and how many more), each component read in another's order
    (``thickness.mixture.order_moves``), the facets the order cut read in their runner-up
    order (``thickness.mixture.order_cut``) and each component set aside as misread facets
    (``thickness.mixture.misread_components``)."""
    rows = []
    order = res.get("thickness", "order")
    if isinstance(order, dict) and "established" in order:
        why = order.get("reasons") or []
        more = f" (+{len(why) - 1} more)" if len(why) > 1 else ""
        rows.append(["interference order", "established" if order["established"] else
                     "not established: " + (why[0] if why else "") + more])
    for m in res.get("thickness", "mixture", "order_moves") or []:
        rows.append(["order move", f"{fmt(m.get('from_nm'), '.1f')} → "
                     f"{fmt(m.get('to_nm'), '.1f', 'nm')} "
                     f"({fmt(pct(m.get('area_share')), '.0f', '%')} of a component)"])
    cut = res.get("thickness", "mixture", "order_cut")
    if isinstance(cut, dict) and cut.get("facets"):
        rows.append(["order cut", f"{fmt(cut['facets'], '.0f')} facets to their runner-up "
                     f"order ({fmt(pct(cut.get('area_fraction')), '.1f', '%')} of the area)"])
    for m in res.get("thickness", "mixture", "misread_components") or []:
        why = (f"scattered, {fmt(m.get('facets_per_region'), '.1f')} facets per region"
               if m.get("why") == "scattered" else
               f"{DE} {fmt(m.get('delta_e'), '.1f')} vs "
               f"{fmt(m.get('delta_e_populations'), '.1f')}")
        rows.append(["set aside (misread)", f"{fmt(m.get('mean_nm'), '.1f', 'nm')} "
                     f"({fmt(pct(m.get('weight')), '.0f', '%')}; {why})"])
    return rows


def _parameter_rows(res, mode):
    """The analysis options the report shows (those recorded)."""
    rows = []
    size, tr = res.parameter("roi.size_px"), res.parameter("optics.thickness_range_nm")
    facet, step = res.parameter("joint.facet_size_um"), res.parameter("tilt.step_deg")
    k = res.parameter("fits.max_components")
    if size is not None:
        rows.append(["ROI size", f"{fmt(size, '.0f')} px"])
    if isinstance(tr, list) and len(tr) == 2:
        rows.append(["thickness search range", f"{fmt(tr[0], 'g')}–{fmt(tr[1], 'g')} nm"])
    if mode == "joint" and facet is not None:
        rows.append(["facet size (segmentation)", fmt(facet, ".3g", "µm")])
    if step is not None:
        rows.append(["tilt search step", fmt(step, ".3g", "°")])
    if k is not None:
        rows.append(["largest k tried (BIC)", fmt(k, ".0f")])
    return rows


def _iso25178_rows(ctx):
    """[[name, value]] of summary.json's ``iso25178`` (empty without it)."""
    iso = ctx.res.get("iso25178")
    if not isinstance(iso, dict):
        return []
    n = number(iso.get("n_points"))
    return [
        ["Sq, root mean square height", fmt(iso.get("Sq_um"), ".4g", "µm")],
        ["Sa, arithmetic mean height", fmt(iso.get("Sa_um"), ".4g", "µm")],
        ["Sdq, root mean square gradient", fmt(iso.get("Sdq"), ".4g")],
        ["Sdr, developed interfacial area ratio", fmt(iso.get("Sdr_percent"), ".4g", "%")],
        ["reference (S-F surface)", f"{iso.get('reference') or '—'}, tilt "
         f"{fmt(iso.get('plane_tilt_deg'), '.3g', '°')}"
         + (f", {n:.0f} pixels" if n is not None else "")],
        ["as measured: RMS height / gradient", f"{fmt(iso.get('rms_height_um'), '.4g', 'µm')}"
         f" / {fmt(iso.get('rms_gradient'), '.4g')} (SurfaceTopography)"],
        ["RMS slope of the normals (microfacet)", fmt(iso.get("rms_slope_normals"), ".4g")
         + " (central differences)"],
    ]


def _timing_rows(ctx):
    """[[step, "x.xx s"]] from summary.json's timings_s, the total last."""
    timings = ctx.res.get("timings_s")
    if not isinstance(timings, dict):
        return []
    rows = [[_STEP_NAMES.get(k, k.replace("_", " ")), f"{number(v):.3g} s"]
            for k, v in timings.items()
            if k not in ("total", "report") and number(v) is not None]
    if number(timings.get("total")) is not None:
        rows.append(["total analysis", f"{number(timings['total']):.3g} s"])
    if number(timings.get("report")) is not None:
        rows.append(["report (previous)", f"{number(timings['report']):.3g} s"])
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
    missing = ctx.missing_files()
    if missing:
        rows.append(["not in the folder", ", ".join(missing)])
    return rows
