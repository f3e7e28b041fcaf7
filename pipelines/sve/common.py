"""What the speed-vs-error sections share: the scene ranges, the run sizes, the library
defaults, the timer, the Pareto plot and the noisy ``nd`` scene of section 3.

Another ΔE formula is measured inside a search by giving the search a
:class:`~microfacet.colour.model.FilmColourModel` with that ``delta_e_method`` (the searches
take the model; the library is never patched).
"""

from __future__ import annotations

import functools
import inspect
import math

import numpy as np

from pipelines._shared import best_of, noisy_scene, pareto_front, pyplot, save_figure

NA = 0.8
MAX_TILT = math.degrees(math.asin(NA)) / 2.0   # 26.57°: the microscope's tilt range
THETA_RANGE = (0.0, MAX_TILT + 0.5)            # as microfacet.analysis.pipeline builds its table
RANGES = [(0.0, 200.0), (0.0, 400.0), (0.0, 800.0)]
SPECTRAL_STEPS = (1.0, 2.0, 5.0, 10.0, 20.0)
FORMULAS = ("CIE76", "CIE94", "CIEDE2000")


def config(quick, repeat=None):
    """Sample sizes and settings of a full run, or of a quick check (seconds, not a
    measurement: small samples, few settings, a cropped focus stack)."""
    if quick:
        return dict(repeat=repeat or 1, n_points=200, n_time=50, rounds=1, n_lookup=5_000,
                    d_steps=(0.5, 2.0), t_steps=(2.0, 4.0), scene_px=128,
                    n_tilt_px=1_000, tilt_steps=(0.5, 1.0, 2.0),
                    n_formula=20_000, focus_stacks=(1,), focus_px=(7,), focus_crop=80,
                    eq6_n=(50.0,), eq6_steps=(0.5, 1.0, 2.0), eq6_ref_step=0.25,
                    eq6_d_steps=("default", 3.0), eq6_grid_step=5.0,
                    ranges=[(0.0, 100.0), (0.0, 200.0), (0.0, 400.0)])
    return dict(repeat=repeat or 3, n_points=20_000, n_time=2000, n_lookup=200_000,
                d_steps=(0.25, 0.5, 1.0, 2.0, 4.0), t_steps=(0.5, 1.0, 2.0, 4.0, 8.0),
                scene_px=1024, n_tilt_px=100_000,
                tilt_steps=(0.05, 0.1, 0.25, 0.5, 1.0, 2.0, 4.0), n_formula=1_000_000,
                focus_stacks=(1, 2, 3), focus_px=(3, 5, 7, 9, 11, 15),
                eq6_n=(50.0, 500.0, 5000.0), eq6_steps=(0.1, 0.25, 0.5, 1.0, 2.0, 5.0),
                eq6_ref_step=0.05, eq6_d_steps=(0.25, 0.5, "default", 3.0, 6.0))


def timed(fn, repeat):
    """Best-of timer of these experiments: fast calls repeated for ≥ 0.25 s, slow ones ≤ 8 s
    (a quick run, ``repeat`` 1, times each call once)."""
    if repeat <= 1:
        return best_of(fn, 1)
    return best_of(fn, repeat, min_total_s=0.25, max_calls=30, max_total_s=8.0)


@functools.cache
def defaults():
    """The defaults as the installed library defines them (labels follow the code)."""
    from microfacet.analysis.options import JointOptions, RoiOptions, TiltOptions
    from microfacet.focus.options import FocusOptions
    from microfacet.forward.angular import simulate_map
    from microfacet.forward.brdf import thickness_nodes
    from pipelines.studies.accuracy_focus import focus_defaults

    def dflt(fn, name):
        return inspect.signature(fn).parameters[name].default

    roi = RoiOptions()
    return dict(
        roi_grid=float(roi.grid_step_nm),
        roi_sample=int(roi.sample_px),
        roi_refine=int(roi.refine_px),
        facet_step=float(JointOptions().thickness_step_nm),
        tilt_step=float(TiltOptions().step_deg),
        eq6_step=float(dflt(simulate_map, "theta_m_step_deg")),
        dnode_max=float(dflt(thickness_nodes, "max_step_nm")),
        focus=focus_defaults(FocusOptions()),
    )


def model_of(table, *, exposure=1.0, method="CIEDE2000"):
    """The film model of ``table`` at ``exposure`` with the ΔE formula ``method``."""
    from microfacet.colour.model import FilmColourModel

    return FilmColourModel(table, exposure=exposure, delta_e_method=method)


@functools.cache
def scene(size):
    """Section 3's scene: the `nd` preset with its sensor noise, the analysis' colour table."""
    from microfacet.colour.table import build_colour_table

    p, sc, lab, mask, noise = noisy_scene("nd", size=size, seed=11)
    table = build_colour_table(thickness_range_nm=(0.0, 400.0), theta_range_deg=THETA_RANGE)
    return dict(p=p, sc=sc, lab=lab, mask=mask, used=~mask, noise=noise, table=table,
                model=model_of(table))


@functools.cache
def roi_reference(size):
    """The ROI grid, the true ROI thickness and the reference fit (the finest settings)."""
    from microfacet.analysis.options import RoiOptions
    from microfacet.analysis.roi import fit_roi_thickness, roi_grid

    s = scene(size)
    sc, used = s["sc"], s["used"]
    rois = roi_grid(s["lab"].shape[:2], size_px=RoiOptions().size_px)
    rows_, cols_, (rh, rw) = rois
    truth = np.array([float(sc.thickness_nm[r0:r0 + rh, c0:c0 + rw][
        used[r0:r0 + rh, c0:c0 + rw]].mean()) for r0 in rows_ for c0 in cols_])
    ref_options = RoiOptions(grid_step_nm=0.5, sample_px=2048, refine_px=10 ** 7)
    ref = fit_roi_thickness(s["lab"], sc.tilt_deg, s["mask"], s["model"], ref_options,
                            rois=rois)
    return rois, truth, ref


@functools.cache
def facet_truth(size):
    """True facets: interior pixels, usable pixels, mean tilt per facet (clipped)."""
    from scipy import ndimage

    s = scene(size)
    sc = s["sc"]
    facets = sc.facet_id
    H, W = facets.shape
    S = int(facets.max()) + 1
    edge_px = np.zeros((H, W), bool)
    edge_px[:, 1:] |= facets[:, 1:] != facets[:, :-1]
    edge_px[1:, :] |= facets[1:, :] != facets[:-1, :]
    interior = ndimage.distance_transform_edt(~edge_px) >= 1.5
    usable = s["used"] & sc.visible
    tilt_f = np.clip(np.bincount(facets.ravel(), weights=sc.tilt_deg.ravel(), minlength=S)
                     / np.maximum(np.bincount(facets.ravel(), minlength=S), 1), 0, MAX_TILT)
    return dict(facets=facets, S=S, interior=interior, usable=usable, tilt_f=tilt_f)


def pareto_plot(path, panels, *, xlabel, ylabel, suptitle=None, logx=True, logy=True):
    """One PNG, one panel per entry of ``panels``.

    panel: {"title", "series": [{"label", "x", "y", "names", "default" (index or None)}],
            "hlines": [(y, label)]}
    """
    plt = pyplot()
    import matplotlib.ticker as ticker

    fig, axes = plt.subplots(1, len(panels), figsize=(3.9 * len(panels), 3.5), squeeze=False)
    for ax, pnl in zip(axes[0], panels):
        allx, ally = [], []
        plogx, plogy = pnl.get("logx", logx), pnl.get("logy", logy)
        for k, s in enumerate(pnl["series"]):
            x = np.asarray(s["x"], float)
            y = np.asarray(s["y"], float)
            keep = y > 0 if plogy else np.isfinite(y)  # a zero error is the reference itself
            names = [nm for nm, kp in zip(s.get("names", [""] * len(x)), keep) if kp]
            dflt = s.get("default")
            dflt = (int(np.sum(keep[:dflt])) if dflt is not None and keep[dflt] else None)
            x, y = x[keep], y[keep]
            ax.plot(x, y, "o-" if s.get("line", True) else "o", ms=4, lw=0.8,
                    color=f"C{k}", label=s["label"])
            for xi, yi, nm in zip(x, y, names):
                ax.annotate(nm, (xi, yi), fontsize=6, xytext=(3, 2), textcoords="offset points",
                            color=f"C{k}")
            if dflt is not None:
                ax.plot([x[dflt]], [y[dflt]], marker="*", ms=13, mfc="none", mec="red", mew=1.4,
                        zorder=5)
            allx += list(x)
            ally += list(y)
        groups = ([(allx, ally, "0.6")] if pnl.get("front", "all") == "all" else
                  [([xi for xi, yi in zip(s["x"], s["y"]) if yi > 0],
                    [yi for yi in s["y"] if yi > 0], f"C{k}")
                   for k, s in enumerate(pnl["series"])])
        for gx, gy, col in groups:
            front = pareto_front(gx, gy)
            if len(front) > 1:
                ax.step([gx[i] for i in front], [gy[i] for i in front], where="post", color=col,
                        lw=2.5, alpha=0.3, zorder=0)
        for yv, lab in pnl.get("hlines", []):
            ax.axhline(yv, color="0.4", ls="--", lw=0.8)
            ax.annotate(lab, (0.02, yv), xycoords=("axes fraction", "data"),
                        fontsize=6, color="0.3", xytext=(0, 2), textcoords="offset points")
        if "ylim" in pnl:
            ax.set_ylim(*pnl["ylim"])
        for on, axis, setter in ((plogx, ax.xaxis, ax.set_xscale),
                                 (plogy, ax.yaxis, ax.set_yscale)):
            if on:
                setter("log")
                if axis is ax.xaxis:
                    axis.set_major_locator(ticker.LogLocator(base=10, subs=(1, 2, 5)))
                axis.set_minor_formatter(ticker.NullFormatter())
                axis.set_major_formatter(ticker.FuncFormatter(lambda v, _: f"{v:g}"))
        ax.set_title(pnl["title"], fontsize=8)
        ax.set_xlabel(xlabel, fontsize=7)
        ax.set_ylabel(pnl.get("ylabel", ylabel), fontsize=7)
        ax.tick_params(labelsize=6)
        ax.grid(True, which="major", lw=0.3, alpha=0.5)
        ax.legend(fontsize=6, loc="best")
    if suptitle:
        fig.suptitle(suptitle + "   (red star = default; grey = Pareto front)", fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
