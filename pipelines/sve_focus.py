"""Speed against error, section 4: focus operator, window, window size and peak fit of
``microfacet.focus.height.height_from_focus``.

Height RMSE in slices on the ground-truth stacks of Cou & Guennebaud (2023) in
fixtures/focus-stacks, time as a ratio to the library's default.

Run:  python pipelines/sve_focus.py [--quick] [--repeat N] [--out DIR]
      (part of python pipelines/speed_vs_error.py, which writes docs/speed-vs-error.md)
"""

from __future__ import annotations

import numpy as np
from _shared import cou_rmse, cou_stack, md_table, verdict
from _sve import focus_defaults, pareto_plot, section_main, timed

from microfacet.focus.options import OPERATORS, WINDOWS, FocusOptions


def measure(cfg):
    from microfacet.focus.height import height_from_focus

    stacks = {}
    for s in cfg["focus_stacks"]:
        st, ref = cou_stack(s)
        order = np.argsort(st.z_um)
        imgs = [st.read_slice(int(i), np.float32) for i in order]
        stacks[s] = (imgs, np.asarray(st.z_um, float)[order], ref)
    z_step = float(np.median(np.diff(stacks[cfg["focus_stacks"][0]][1])))
    fop, fwin, fpx, finterp, fr = focus_defaults(FocusOptions())
    fit_r = fr if finterp == "lsq" else 2
    configs = [(op, win, px, "lsq", fit_r) for op in OPERATORS for win in WINDOWS
               for px in sorted(set(cfg["focus_px"]) | {fpx})]
    configs += [(fop, fwin, fpx, "none", None), (fop, fwin, fpx, "gauss3", None),
                (fop, fwin, fpx, "lsq", fit_r + 1)]
    if (fop, fwin, fpx, finterp, fr) not in configs:
        configs.append((fop, fwin, fpx, finterp, fr))
    res = []
    for op, win, px, interp, r in configs:
        tot_t, errs = 0.0, []
        for imgs, z, ref in stacks.values():
            opts = _options(op, win, px, interp, r)
            t, fres = timed(lambda: height_from_focus(imgs, opts, z_um=z, prefetch=False),
                            cfg["repeat"])
            tot_t += t
            errs.append(cou_rmse(fres.height_um, ref) / z_step)
        res.append(dict(op=op, win=win, px=px, interp=interp, r=r, time=tot_t,
                        err=float(np.mean(errs)), worst=float(np.max(errs)), errs=errs))
        print(f"  focus {op} {win} {px} {interp} {r}: {np.mean(errs):.3f} slices, {tot_t:.2f} s",
              flush=True)
    fkey = (fop, fwin, fpx, finterp, fr if finterp in ("lsq", "lorentz") else None)
    idef = next(i for i, c in enumerate(res) if (c["op"], c["win"], c["px"], c["interp"],
                                                  c["r"]) == fkey)
    first = stacks[cfg["focus_stacks"][0]][0]
    return res, idef, fit_r, (first[0].shape, len(first))


def _options(op, win, px, interp, r):
    """The focus options of one configuration, every pixel kept; the default radius where
    ``r`` is None (the fit does not use it)."""
    kw = dict(operator=op, window=win, window_px=px, interpolation=interp,
              min_reliability_db=-np.inf)
    return FocusOptions(**kw, **({} if r is None else {"fit_radius": r}))


def run(cfg, doc, img):
    fop, fwin, fpx, finterp, fr = focus_defaults(FocusOptions())
    dname = f"{fop}, {fwin} {fpx} px, {finterp}" + (
        f" r = {fr}" if finterp in ("lsq", "lorentz") else "")
    res, idef, fit_r, (shape, n_slices) = measure(cfg)
    td = res[idef]["time"]
    doc("\n## 4. Focus operator and window\n")
    doc(f"`height_from_focus` on the Cou & Guennebaud (2023) stacks "
        f"{', '.join(map(str, cfg['focus_stacks']))} ({shape[1]}×{shape[0]} px, "
        f"{n_slices} slices; slices decoded beforehand, so the "
        f"time is the focus measure, peak fit and reliability only), RMSE in slices against "
        f"the ground truth (as `pipelines/focus_accuracy.py`: all pixels, no reliability "
        f"mask), mean over the stacks (worst stack in brackets); time summed over the stacks, "
        f"best of {cfg['repeat']}, as a ratio to the default ({dname}: {td:.2f} s). Operator × "
        f"window table with the lsq r = {fit_r} fit; each cell: RMSE (worst) / time ×.\n")
    pxs = sorted(set(cfg["focus_px"]) | {fpx})

    def get(op, win, px, interp="lsq", r=None):
        r = fit_r if r is None else r
        return next(c for c in res if (c["op"], c["win"], c["px"], c["interp"], c["r"]) ==
                    (op, win, px, interp, r if interp == "lsq" else None))
    rows = []
    for op in OPERATORS:
        for win in WINDOWS:
            cells = []
            for px in pxs:
                c = get(op, win, px)
                star = "**" if c is res[idef] else ""
                cells.append(f"{star}{c['err']:.3f} ({c['worst']:.3f}) / {c['time'] / td:.2f}×"
                             f"{star}")
            rows.append([op, win] + cells)
    doc(md_table(["operator", "window"] + [f"{px} px" for px in pxs], rows))
    doc(f"\nPeak interpolation ({fop}, {fwin} {fpx} px):\n")
    doc(md_table(["interpolation", "RMSE (slices)", "worst stack", "time × default"],
                 [[{"none": "arg-max", "gauss3": "Gauss 3-point", "lsq": f"lsq r = {c['r']}",
                   "lorentz": f"Lorentz r = {c['r']}"}[
                     c["interp"]] + (" (default)" if c is res[idef] else ""),
                   f"{c['err']:.3f}", f"{c['worst']:.3f}", f"{c['time'] / td:.2f}"]
                  for c in res if (c["op"], c["win"], c["px"]) == (fop, fwin, fpx)]))
    names = [f"{c['op']} {c['win'][:5]} {c['px']} {c['interp']}{c['r'] or ''}" for c in res]
    doc("\n" + verdict(names, [c["time"] for c in res], [c["err"] for c in res], idef,
                       target=res[idef]["err"] * 1.05, unit=" slices",
                       fmt=lambda x: f"{x:.3f}"))
    best = min(range(len(res)), key=lambda i: res[i]["err"])
    doc(f"The most accurate setting measured is {names[best]} ({res[best]['err']:.3f} slices, "
        f"{res[best]['time'] / td:.2f}×).")
    plot(img, res, idef, fit_r)
    doc("\n![focus: RMSE against time](img/sve-focus.png)\n")
    lsq2 = [c for c in res if c["interp"] == "lsq" and c["r"] == fit_r]
    t_rng = (min(c["time"] for c in lsq2) / td, max(c["time"] for c in lsq2) / td)
    gauss_better = all(get(op, "gaussian", px)["err"] <= get(op, "box", px)["err"] + 1e-9
                       for op in OPERATORS for px in pxs if px >= 5)
    best2 = min(lsq2, key=lambda c: c["err"])
    r1, g3, am = (get(fop, fwin, fpx, "lsq", fit_r + 1), get(fop, fwin, fpx, "gauss3"),
                  get(fop, fwin, fpx, "none"))
    doc(f"\n**Reading.** Operators and windows cost about the same "
        f"({t_rng[0]:.2f}–{t_rng[1]:.2f}× the default with the lsq r = {fit_r} fit; the shared "
        f"peak fit and reliability dominate, GLV's two window filters cost most), so the "
        f"choice is about accuracy. A Gaussian window beats a box of the same spread "
        + ("at every size ≥ 5 px" if gauss_better else "at most sizes")
        + "; 7–9 px is the optimum on these stacks (3 px is far too small, 15 px blurs the "
        f"relief). The default ({dname}) is "
        + ("the most accurate" if best2 is res[idef] else
           f"within {100 * (res[idef]['err'] / best2['err'] - 1):.0f} % of the most accurate")
        + f" of the lsq r = {fit_r} settings ({res[idef]['err']:.3f} slices); "
        f"r = {fit_r + 1} gains {res[idef]['err'] - r1['err']:.4f} slices "
        f"for {r1['time'] / td:.2f}× the time (and 4 "
        f"more image buffers), the 3-point Gaussian saves "
        f"{100 * (1 - g3['time'] / td):.0f} % for "
        f"{100 * (g3['err'] / res[idef]['err'] - 1):.0f} "
        f"% more error, the arg-max is {am['err'] / res[idef]['err']:.1f}× "
        f"worse. **The default is justified** (docs/height-from-focus.md has the same "
        f"ordering per stack).")
    return dict(res=res, idef=idef, name=dname)


def plot(img, res, idef, fit_r):
    fop, fwin, fpx = focus_defaults(FocusOptions())[:3]
    td = res[idef]["time"]
    panels = []
    for op in OPERATORS:
        series = []
        for win in WINDOWS:
            sel = [i for i, c in enumerate(res) if c["op"] == op and c["win"] == win
                   and c["interp"] == "lsq" and c["r"] == fit_r]
            series.append({"label": f"{win} window", "x": [res[i]["time"] / td for i in sel],
                           "y": [res[i]["err"] for i in sel],
                           "names": [str(res[i]["px"]) for i in sel],
                           "default": next((j for j, i in enumerate(sel) if i == idef), None)})
        panels.append({"title": f"{op} (labels: window px; lsq r={fit_r})", "series": series,
                       "ylim": (0.9 * min(c["err"] for c in res),
                                1.05 * max(c["err"] for c in res if c["interp"] == "lsq"))})
    sel = [i for i, c in enumerate(res) if (c["op"], c["win"], c["px"]) == (fop, fwin, fpx)]
    panels.append({"title": f"peak interpolation ({fop}, {fwin} {fpx})", "series": [
        {"label": "interpolation", "x": [res[i]["time"] / td for i in sel],
         "y": [res[i]["err"] for i in sel],
         "names": [f"{res[i]['interp']}{res[i]['r'] or ''}" for i in sel],
         "default": sel.index(idef), "line": False}]})
    pareto_plot(img / "sve-focus.png", panels, xlabel="time (× default)",
                ylabel="height RMSE (slices)", suptitle="Focus operator, window, interpolation",
                logx=False, logy=False)


def summary_rows(result):
    """Rows of the summary table (speed_vs_error.py)."""
    res, i = result["res"], result["idef"]
    best = min(range(len(res)), key=lambda k: res[k]["err"])
    return [["§4 focus (`FocusOptions`: `operator`, `window`, `window_px`, "
             "`interpolation`, `fit_radius`)",
             result["name"], f"{res[i]['err']:.3f} slices RMSE",
             f"best measured: {res[best]['op']} {res[best]['win']} {res[best]['px']} "
             f"{res[best]['interp']}{res[best]['r'] or ''} {res[best]['err']:.3f} at "
             f"{res[best]['time'] / res[i]['time']:.2f}×", "justified"]]


if __name__ == "__main__":
    section_main(run, "focus", __doc__)
