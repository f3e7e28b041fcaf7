"""Speed against error: for each knob, time and error against a high-accuracy reference.

One run measures, on the same machine and in the same process (times are the minimum of
``repeat`` runs and are given as ratios, because the 2-core machine is shared); each section
is a module of :mod:`pipelines.sve`:

1. **Spectral step** (1, 2, 5, 10, 20 nm) for the thickness ranges users meet (0-200, 0-400,
   0-800 nm; incidence 0 … asin(NA)/2 + 0.5° for NA 0.8): ΔE00 against direct 1 nm spectral
   evaluation at random (θ, d), time per colour.
2. **Colour-table grid** (thickness step × angle step) at the spectral step the library
   picks for the range: ΔE00 of the interpolated table against direct 1 nm evaluation,
   build time, lookup time.
3. **ΔE formula and inversion search** on a synthetic ``nd`` scene with known truth and
   sensor noise: raw formula speed; ROI thickness (``fit_roi_thickness``: grid step, pixel
   samples, refinement sample), per-facet thickness (``facet_thickness``: search step),
   per-pixel tilt (``invert_tilt``: tilt grid step, with and without the facet-plane
   prior); CIE76 / CIE94 inside each search.
4. **Focus operator and window** (``height_from_focus``; the measurement of the
   ``accuracy-focus`` study): height RMSE in slices on the ground-truth stacks of Cou &
   Guennebaud (2023), time.
5. **Eq. 6 quadrature** (``theta_m_step_deg`` of ``simulate_map(model="eq6")``, and the
   thickness-node step): ΔE00 of the 90 × 90 angular map against a very dense reference, time.

It returns the page (docs/speed-vs-error.md below its title: a table and a Pareto plot per
knob, the default marked, and a summary) and writes the plots to ``out/img/sve-*.png``
(``--docs`` copies them to docs/img/).
"""

from __future__ import annotations

import os
import platform
import time
from pathlib import Path

from pipelines import Study
from pipelines._shared import Doc, git_describe, md_table

SECTIONS = ("spectral", "table", "inversion", "focus", "eq6")

STUDY = Study(
    name="speed-vs-error",
    question="Where does each default that trades time for accuracy sit between its time and "
             "its error (spectral step, colour table, ΔE and searches, focus, eq. 6)?",
    doc=("docs/speed-vs-error.md", "speed-vs-error"),
    run_time="9 min",
    quick_time="20-30 s",
    options={"sections": (",".join(SECTIONS), "sections to run, comma-separated"),
             "repeat": (0, "timing repeats, best kept (0: 3, or 1 with --quick)")},
    doc_files={f"img/sve-{s}.png": f"docs/img/sve-{s}.png" for s in SECTIONS},
)


def _modules():
    from pipelines.studies import accuracy_focus
    from pipelines.sve import eq6, inversion, spectral, table

    return dict(spectral=spectral, table=table, inversion=inversion, focus=accuracy_focus,
                eq6=eq6)


def intro(doc, cmd, cfg, quick):
    doc(f"Reproduce: `{cmd}`" + (" (quick run: small samples, fewer settings)" if quick
                                 else "") + "\n")
    doc("For every knob that trades time for accuracy, this page gives the error against a "
        "high-accuracy reference and the time, both measured in one run on the project's "
        "2-core development machine (shared with other jobs: times are the minimum of "
        f"{cfg['repeat']} runs and are compared as ratios within the run, not across runs), "
        "a Pareto plot (error against time; red star = the library default, grey = the "
        "Pareto front), and where the default sits. The rule behind every default is *model "
        "only what a scene needs*: the cheapest setting whose error is below what matters "
        "(0.1 ΔE00 for colour, well below the image noise of ~0.5 ΔE00, and well below the "
        "truth error for thickness, tilt and height). Which films allow tilt from colour at "
        "all: [conditioning.md](conditioning.md) (`python -m pipelines run "
        "accuracy-conditioning`).\n")
    doc("Contents: [1. spectral step](#1-spectral-step) · [2. colour-table resolution]"
        "(#2-colour-table-resolution) · [3. ΔE formula and inversion search]"
        "(#3-δe-formula-and-inversion-search) · [4. focus operator and window]"
        "(#4-focus-operator-and-window) · [5. eq. 6 quadrature](#5-eq-6-quadrature) · "
        "[summary](#summary-where-the-defaults-sit)\n")


def run(*, quick: bool, out: Path, sections=",".join(SECTIONS), repeat=0) -> str:
    import numpy

    from microfacet import __version__
    from pipelines.sve.common import config, defaults, pareto_plot, timed

    chosen = [s for s in sections.split(",") if s]
    unknown = sorted(set(chosen) - set(SECTIONS))
    if unknown:
        raise ValueError(f"sections: unknown {', '.join(unknown)}; known: {', '.join(SECTIONS)}")
    cfg = config(quick, repeat or None)
    img = out / "img"
    cmd = "python -m pipelines run speed-vs-error" + (" --quick" if quick else "") + (
        f" --set repeat={repeat}" if repeat else "") + (
        f" --set sections={sections}" if chosen != list(SECTIONS) else "")
    modules = _modules()
    t_all = time.perf_counter()
    load0 = os.getloadavg()[0]
    doc = Doc()
    intro(doc, cmd, cfg, quick)
    results = {}
    for name in SECTIONS:
        if name not in chosen:
            continue
        if name == "table":
            results[name] = modules[name].run(cfg, doc, img, results.get("spectral"))
        elif name == "focus":
            results[name] = modules[name].section(cfg, doc, img, timer=timed,
                                                  pareto_plot=pareto_plot)
        else:
            results[name] = modules[name].run(cfg, doc, img)
    doc("\n## Summary: where the defaults sit\n")
    doc(md_table(["knob (where)", "default", "error of the default", "alternatives",
                  "verdict"], [row for name in SECTIONS if name in results
                               for row in modules[name].summary_rows(results[name])]))
    elapsed = time.perf_counter() - t_all
    doc(f"\n---\nMeasured {time.strftime('%Y-%m-%d')} in {elapsed / 60:.1f} min "
        f"(load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; "
        f"{os.cpu_count()} CPUs), microfacet {__version__} ({git_describe()}), numpy "
        f"{numpy.__version__}, Python {platform.python_version()}. Library defaults read from "
        f"the code at run time: {defaults()}.")
    return doc.text()
