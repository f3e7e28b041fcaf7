"""Speed against error, section 3a: the ROI thickness search (grid step, pixel samples,
refinement sample, ΔE formula) of ``microfacet.analysis.roi.fit_roi_thickness``.

On the noisy synthetic ``nd`` scene of section 3 (:func:`pipelines.sve.common.scene`): MAE
against the true ROI thickness and against a reference fit with the finest settings, time as
a ratio to the default.
"""

from __future__ import annotations

import numpy as np

from pipelines._shared import fmt, md_table, verdict
from pipelines.sve.common import defaults, model_of, roi_reference, scene, timed


def settings():
    """(name, keywords, formula) of every setting measured; the default first."""
    D = defaults()
    G, SP, RP = D["roi_grid"], D["roi_sample"], D["roi_refine"]
    out = [(f"default (grid {G:g} nm, sample {SP}, refine {RP} px)", {}, "CIEDE2000")]
    out += [(f"grid {g:g} nm", dict(grid_step_nm=g), "CIEDE2000")
            for g in (0.5, 1.0, 2.0, 5.0) if g != G]
    out += [(f"sample {n} px", dict(sample_px=n), "CIEDE2000")
            for n in (64, 128, 256, 1024) if n != SP]
    out += [(f"refine {n} px", dict(refine_px=n), "CIEDE2000")
            for n in (1000, 2000, 32000) if n != RP]
    return out + [("CIE76", {}, "CIE76"), ("CIE94", {}, "CIE94")]


def edge_shifts(s, rois, dfit, G):
    """For ROIs clamped at the refinement window's edge: how far out the all-pixel minimum is."""
    from microfacet.colour.colorimetry import xyz_to_lab
    from microfacet.colour.difference import delta_e

    sc, lab, table = s["sc"], s["lab"], s["table"]
    rows_, cols_, (rh, rw) = rois
    usable_t = s["used"] & np.isfinite(sc.tilt_deg)
    t_hi = float(table.theta_deg[-1])
    shifts, k = [], 0
    for r0 in rows_:
        for c0 in cols_:
            dk = dfit.thickness_nm[k]
            k += 1
            if not (np.isfinite(dk) and np.isclose(np.mod(dk + 1e-9, G), 0.0, atol=2e-6)):
                continue
            yy_, xx_ = np.nonzero(usable_t[r0:r0 + rh, c0:c0 + rw])
            yy_, xx_ = yy_ + r0, xx_ + c0
            fine = np.arange(dk - 5.0, dk + 5.0 + 1e-9, 0.05)
            xyz = table.xyz_at(np.clip(sc.tilt_deg[yy_, xx_].astype(np.float64), 0, t_hi)[:, None],
                               fine[None, :]) * dfit.exposure
            mlab = xyz_to_lab(xyz.astype(np.float32), white=table.white_xyz.astype(np.float32))
            curve = delta_e(mlab, lab[yy_, xx_][:, None, :]).mean(axis=0)
            shifts.append(abs(float(fine[int(np.argmin(curve))]) - dk))
    return shifts


def run(cfg, doc, img=None):
    from microfacet.analysis.options import RoiOptions
    from microfacet.analysis.roi import fit_roi_thickness

    rep = min(cfg["repeat"], 2)
    s = scene(cfg["scene_px"])
    p, sc, lab, mask, table = s["p"], s["sc"], s["lab"], s["mask"], s["table"]
    rois, truth_roi, ref_fit = roi_reference(cfg["scene_px"])
    rh = rois[2][0]
    G = defaults()["roi_grid"]
    res_roi = []
    for name, kw, f in settings():
        model = model_of(table, method=f)
        t, fit = timed(lambda kw=kw, model=model: fit_roi_thickness(
            lab, sc.tilt_deg, mask, model, RoiOptions(**kw), rois=rois), rep)
        step = kw.get("grid_step_nm", G)
        edge = np.isclose(np.mod(fit.thickness_nm + 1e-9, step), 0.0, atol=2e-6)
        dev = np.abs(fit.thickness_nm - ref_fit.thickness_nm)
        flip = dev > 1.0
        res_roi.append(dict(name=name, time=t, mae=float(np.nanmean(np.abs(
            fit.thickness_nm - truth_roi))), dev=float(np.nanmean(dev)),
            dev_kept=float(np.nanmean(dev[~flip])) if (~flip).any() else float("nan"),
            flips=int(np.sum(flip)), exp=fit.exposure, edge=int(np.sum(edge)),
            n=fit.thickness_nm.size))
    idef = 0
    doc(f"### 3a. Thickness per ROI (`analysis.roi.fit_roi_thickness`, {len(truth_roi)} ROIs "
        f"of {rh} px, exposure estimated; time best of {rep})\n")
    doc(f"Reference: grid 0.5 nm, 2048 sample pixels, every pixel in the refinement "
        f"(MAE against truth {fmt(np.nanmean(np.abs(ref_fit.thickness_nm - truth_roi)))} nm, "
        f"exposure {ref_fit.exposure:.3f}; true 1). \"at window edge\" counts ROIs whose "
        f"refined thickness sits exactly on the edge of the ±1 grid-step refinement window "
        f"(the minimum of the refinement sample lies outside it).\n")
    td = res_roi[idef]["time"]
    doc(md_table(["setting", "MAE vs truth (nm)", "MAE vs reference (nm)",
                  "ROIs > 1 nm off the reference", "MAE vs reference, other ROIs (nm)",
                  "exposure", "at window edge", "time (s)", "time × default"],
                 [[r["name"], fmt(r["mae"]), fmt(r["dev"]), f"{r['flips']}/{r['n']}",
                   fmt(r["dev_kept"]), f"{r['exp']:.3f}", f"{r['edge']}/{r['n']}",
                   f"{r['time']:.2f}", f"{r['time'] / td:.2f}"] for r in res_roi]))
    doc("\nAgainst the reference (the truth error is the estimator's, see below): "
        + verdict([r["name"] for r in res_roi], [r["time"] for r in res_roi],
                  [r["dev"] for r in res_roi], idef, unit=" nm (MAE vs reference)"))
    dfit = fit_roi_thickness(lab, sc.tilt_deg, mask, s["model"], RoiOptions(),
                             rois=rois)  # the defaults
    shifts = edge_shifts(s, rois, dfit, G)
    reading(doc, res_roi, shifts, rh, p)
    return dict(roi=res_roi, roi_edge_shift=shifts)


def reading(doc, res_roi, shifts, rh, p):
    D = defaults()
    r = {x["name"]: x for x in res_roi}
    dflt = res_roi[0]
    r.setdefault(f"sample {D['roi_sample']} px", dflt)
    r.setdefault(f"grid {D['roi_grid']:g} nm", dflt)
    r.setdefault(f"refine {D['roi_refine']} px", dflt)
    doc(f"\n**Reading.** The truth error (~{fmt(dflt['mae'])} nm) belongs to the ROI estimator, "
        f"not to the search: a {rh}-px ROI ({rh * p.pixel_size_um:.0f} µm) spans several "
        f"thickness regions ({p.region_size_um:g} µm), the thickness of least mean ΔE00 is "
        f"near the dominant population's rather than the ROI mean, and the mean-ΔE curve "
        f"has nearly equal minima, one per population — a different pixel sample can pick "
        f"another (sample 128 / 1024 px: {r['sample 128 px']['flips']} / "
        f"{r['sample 1024 px']['flips']} ROIs more than 1 nm off the 2048-px reference). No "
        f"search knob removes that; the joint mode only uses the ROI value as the centre of "
        f"its ±30 nm per-facet search. What the knobs do: (1) **the refinement, not the "
        f"scan, sets the time** — it evaluates `refine_px` pixels on a 0.05 nm grid over "
        f"±1 grid step around the two best minima, so a coarser scan is *slower* (2 nm "
        f"{r['grid 2 nm']['time'] / dflt['time']:.2f}×, 5 nm "
        f"{r['grid 5 nm']['time'] / dflt['time']:.2f}×) and `refine_px=2000` cuts the time "
        f"to {r['refine 2000 px']['time'] / dflt['time']:.2f}× at "
        f"{fmt(r['refine 2000 px']['dev_kept'])} nm from the reference (default "
        f"{fmt(dflt['dev_kept'])} nm), far below the estimator's own error; (2) 64 sample "
        f"pixels are too few ({r['sample 64 px']['flips']}/{dflt['n']} ROIs jump to another "
        f"minimum, MAE {fmt(r['sample 64 px']['mae'])} nm), while 1024 cost "
        f"{r['sample 1024 px']['time'] / dflt['time']:.2f}× — the scan is cheap; (3) the "
        f"refinement only looks within ±1 grid step of the scan's minimum: when the larger "
        f"refinement sample has its minimum outside that window, the result is clamped at the "
        f"window's edge (\"at window edge\": {dflt['edge']}/{dflt['n']} ROIs with the "
        f"default, up to {max(x['edge'] for x in res_roi)}/{dflt['n']} with other settings"
        + (f"; with all pixels the default's clamped minima lie "
           f"{', '.join(f'{x:.2f}' for x in shifts)} nm further out" if shifts else "")
        + "). **The default does more work than the ROI estimate needs**: "
        f"`refine_px=2000` ({r['refine 2000 px']['time'] / dflt['time']:.2f}×) stays within "
        f"{fmt(r['refine 2000 px']['dev'])} nm of the reference, far below "
        "the estimator's own error.")


def summary_rows(result):
    """Rows of the summary table (speed_vs_error.py)."""
    D = defaults()
    G, SP, RP = D["roi_grid"], D["roi_sample"], D["roi_refine"]
    roi = {x["name"]: x for x in result["roi"]}
    d = result["roi"][0]
    alt = []
    if "refine 2000 px" in roi:
        alt.append(f"refine_px 2000: {roi['refine 2000 px']['time'] / d['time']:.2f}× time, "
                   f"{fmt(roi['refine 2000 px']['dev_kept'])} nm")
    if "grid 2 nm" in roi:
        alt.append(f"grid 2 nm: {roi['grid 2 nm']['time'] / d['time']:.2f}× time")
    cheaper = [x for x in result["roi"][1:] if x["time"] < 0.8 * d["time"]
               and x["flips"] == 0 and x["dev_kept"] <= 0.5]
    return [[f"§3a ROI thickness search (`RoiOptions(grid_step_nm={G:g}, sample_px={SP}, "
             f"refine_px={RP})`)", f"{G:g} nm / {SP} / {RP}",
             f"MAE {fmt(d['mae'])} nm vs truth (the estimator's), "
             f"{fmt(d['dev_kept'])} nm vs reference", "; ".join(alt),
             (f"more than needed: {min(cheaper, key=lambda x: x['time'])['name']} stays "
              f"within 0.5 nm of the reference" if cheaper else "justified")
             + f"; refinement window edge hit in {d['edge']}/{d['n']} ROIs"]]

