"""Speed against error, section 3c: the per-pixel tilt search (tilt grid step, facet-plane
prior, ΔE formula) of ``microfacet.analysis.tilt.invert_tilt``.

On the noisy synthetic ``nd`` scene of section 3 (:func:`pipelines.sve.common.scene`): random
visible unmasked pixels at their true facet's mean thickness, without prior (the seed mode)
and with a simulated facet-plane prior (the joint mode); median error against the truth and
against a 0.05° grid (:func:`~microfacet.analysis.tilt.tilt_grid`), time as a ratio to the
default step.
"""

from __future__ import annotations

import numpy as np

from pipelines._shared import fmt, md_table, verdict
from pipelines.sve.common import MAX_TILT, defaults, facet_truth, model_of, scene, timed


def _row(name, f, t, inv, t_true, ref=None):
    return dict(name=name, f=f, time=t, err=float(np.median(np.abs(inv.tilt_deg - t_true))),
                dev=float("nan") if ref is None else float(np.median(np.abs(inv.tilt_deg - ref))),
                p90=float("nan") if ref is None else
                float(np.percentile(np.abs(inv.tilt_deg - ref), 90)),
                sig=float(np.median(inv.tilt_sigma_deg)))


def measure(cfg):
    """Every setting with and without the prior; the 'exact d' rows; the baselines."""
    from microfacet.analysis.options import TiltOptions
    from microfacet.analysis.tilt import TiltRows, invert_tilt, model_lab_rows, tilt_grid

    rep = cfg["repeat"]
    s = scene(cfg["scene_px"])
    sc, lab, table, noise = s["sc"], s["lab"], s["table"], s["noise"]
    ft = facet_truth(cfg["scene_px"])
    facets, S, usable, tilt_f = ft["facets"], ft["S"], ft["usable"], ft["tilt_f"]
    yy, xx = np.nonzero(usable)
    rng = np.random.default_rng(4)
    pick = rng.choice(yy.size, min(cfg["n_tilt_px"], yy.size), replace=False)
    yy, xx = yy[pick], xx[pick]
    fid = facets[yy, xx]
    cnt_u = np.bincount(facets[usable], minlength=S)
    d_rows = np.bincount(facets[usable], weights=sc.thickness_nm[usable], minlength=S) \
        / np.maximum(cnt_u, 1)
    d_rows = np.where(cnt_u > 0, d_rows, 130.0)
    t_true = sc.tilt_deg[yy, xx].astype(np.float64)
    prior_f = np.clip(tilt_f + rng.normal(0.0, 2.0, S), 0, MAX_TILT)   # per facet
    prior = prior_f[fid]
    lab_px = lab[yy, xx]
    d_px = sc.thickness_nm[yy, xx].astype(np.float64)
    options = TiltOptions()

    def run(step, with_prior, *, exact=False, method="CIEDE2000"):
        g = tilt_grid(MAX_TILT, step)
        model = model_of(table, method=method)
        if exact:   # every pixel its own row, at its own thickness
            d, ri, pr = d_px, np.arange(d_px.size), prior
        else:       # one row per facet, at the facet's mean thickness
            d, ri, pr = d_rows, fid, prior_f
        rows = TiltRows(model_lab_rows(model, d, g), d, noise,
                        *((pr, np.full(d.size, 2.0)) if with_prior else ()))
        return invert_tilt(lab_px, ri, rows, g, model, options)

    TS = defaults()["tilt_step"]
    TN = f"{TS:g}°"
    res_tilt, exact_rows = {}, {}
    for with_prior in (False, True):
        ref = run(0.05, with_prior).tilt_deg
        out = []
        for st in sorted(set(cfg["tilt_steps"]) | {TS}):
            t, inv = timed(lambda st=st: run(st, with_prior), rep)
            out.append(_row(f"{st:g}°", "CIEDE2000", t, inv, t_true, ref))
        for f in ("CIE76", "CIE94"):
            t, inv = timed(lambda f=f: run(TS, with_prior, method=f), rep)
            out.append(_row(f"{TN} {f}", f, t, inv, t_true, ref))
        t, inv = timed(lambda: run(TS, with_prior, exact=True), 1)
        exact_rows[with_prior] = dict(_row(f"{TN} exact d", "CIEDE2000", t, inv, t_true),
                                      weight=float(np.median(inv.colour_weight)))
        res_tilt[with_prior] = out
    const = float(np.median(np.abs(t_true - np.median(t_true))))
    prior_err = float(np.median(np.abs(prior - t_true)))
    return dict(tilt=res_tilt, tilt_name=TN, tilt_exact=exact_rows,
                tilt_baselines=(const, prior_err), n_px=yy.size)


def run(cfg, doc, img=None):
    m = measure(cfg)
    res_tilt, TN, exact_rows = m["tilt"], m["tilt_name"], m["tilt_exact"]
    const, prior_err = m["tilt_baselines"]
    p = scene(cfg["scene_px"])["p"]
    doc(f"\n### 3c. Tilt per pixel (`analysis.tilt.invert_tilt`, {m['n_px']} random visible "
        f"unmasked pixels, each at its true facet's mean thickness)\n")
    doc(f"Without prior = the seed mode's search; with prior = the joint mode's MAP with a "
        f"facet-plane prior, simulated as the true facet tilt + N(0, 2°) with σ_p = 2°. "
        f"Reference: the same search on a 0.05° grid. For scale: a constant tilt (the median) "
        f"has a median error of {const:.2f}°, the prior alone {prior_err:.2f}°. Time per "
        f"{m['n_px']} pixels including the model rows. \"exact d\": each pixel at its own "
        f"true thickness instead of its facet's mean (the facet's thickness varies by "
        f"~{p.thickness_fine_sd_nm:g} nm inside, the preset's fine variation).\n")
    tab_rows = []
    for with_prior in (False, True):
        out = res_tilt[with_prior]
        idf = [r["name"] for r in out].index(TN)
        for r in out + [exact_rows[with_prior]]:
            tab_rows.append(["with prior" if with_prior else "no prior",
                             r["name"] + (" (default)" if r["name"] == TN else ""),
                             fmt(r["err"]), fmt(r["dev"]), fmt(r["p90"]), fmt(r["sig"]),
                             f"{r['time']:.3f}", f"{r['time'] / out[idf]['time']:.2f}"])
    doc(md_table(["search", "grid step / formula", "median |error| vs truth (°)",
                  "median |Δ| vs 0.05° (°)", "p90 |Δ| vs 0.05° (°)", "median reported σ (°)",
                  "time (s)", "time × default"], tab_rows))
    for with_prior in (False, True):
        out = res_tilt[with_prior]
        idf = [r["name"] for r in out].index(TN)
        doc("\n* " + ("with prior" if with_prior else "no prior") + ": " + verdict(
            [r["name"] for r in out], [r["time"] for r in out], [r["err"] for r in out], idf,
            unit="° (vs truth)"))
    reading(doc, m, p)
    return m


def reading(doc, m, p):
    res_tilt, TN, exact_rows = m["tilt"], m["tilt_name"], m["tilt_exact"]
    const, prior_err = m["tilt_baselines"]
    tn = {x["name"]: x for x in res_tilt[False]}
    tw = {x["name"]: x for x in res_tilt[True]}
    sig_np = [x["sig"] for x in res_tilt[False] if x["f"] == "CIEDE2000"]
    formula = (f"Formula: the noise σ_n is measured in ΔE00, so with CIE76 the colour term is "
               f"over-weighted against the prior ({fmt(tw[TN + ' CIE76']['err'])}°); CIE94 is "
               f"{tw[TN + ' CIE94']['time'] / tw[TN]['time']:.2f}× the time and slightly worse "
               f"({fmt(tw[TN + ' CIE94']['err'])}°)." if TN + " CIE94" in tw else
               "Formula: not measured (see above).")
    doc(f"\n**Reading.** **The grid step does not matter for accuracy**: the parabola through "
        f"the three grid values around the minimum lands a 2° grid within "
        f"{fmt(tw['2°']['p90'])}° (p90, with prior) of the 0.05° search, a tenth of the "
        f"reported σ ({fmt(tw[TN]['sig'])}°), and the truth error does not move "
        f"({fmt(tw[TN]['err'])}° → {fmt(tw['2°']['err'])}°), while the time falls to "
        f"{tw['2°']['time'] / tw[TN]['time']:.2f}×. **A 1° or 2° grid is enough**: "
        f"`tilt.step_deg=1` ({tw['1°']['time'] / tw['0.5°']['time']:.2f}× the time of 0.5°, "
        f"p90 {fmt(tw['1°']['p90'])}°) or 2 ({tw['2°']['time'] / tw['0.5°']['time']:.2f}×, "
        f"p90 {fmt(tw['2°']['p90'])}°); the default is {TN} (0.5° until 2026-11-29, when the "
        f"generalization sweep confirmed 1°: docs/benchmarks.md, \"Second round, eighth "
        f"part\"). What limits the tilt is the conditioning ([conditioning.md]"
        f"(conditioning.md)), not the search: without the prior the colour's answer "
        f"({fmt(tn[TN]['err'])}°) is worse than a constant guess ({const:.2f}°), and its "
        f"reported σ ({fmt(min(sig_np))}–{fmt(max(sig_np))}° depending on the grid step, "
        f"because J is taken by finite differences at the grid node) says as much. With the "
        f"prior, the colour term makes the tilt *worse* than the prior alone "
        f"({fmt(tw[TN]['err'])}° against {prior_err:.2f}°): the likelihood treats the "
        f"facet's thickness as exact, but a {p.thickness_fine_sd_nm:g} nm variation inside "
        f"a facet looks like degrees of tilt (conditioning.md), and σ_n does not include it; "
        f"with each pixel at its true thickness the MAP gives "
        f"{fmt(exact_rows[True]['err'])}° (median colour weight "
        f"{fmt(exact_rows[True]['weight'])}), as good as the prior. " + formula)


def summary_rows(result):
    """Rows of the summary table (speed_vs_error.py)."""
    TN, step = result["tilt_name"], defaults()["tilt_step"]
    rows = []
    for wp in (False, True):
        out = {x["name"]: x for x in result["tilt"][wp]}
        d = out[TN]
        rows.append([f"§3c tilt grid, {'with' if wp else 'no'} prior "
                     f"(`TiltOptions(step_deg={step:g})`)", TN,
                     f"median {fmt(d['err'])}° vs truth, p90 {fmt(d['p90'])}° vs 0.05°",
                     f"2°: {out['2°']['time'] / d['time']:.2f}× time, "
                     f"{fmt(out['2°']['err'])}° vs truth, p90 {fmt(out['2°']['p90'])}°",
                     "over-fine: 1–2°" if step < 1 else "justified"])
    return rows

