"""Speed against error: for each knob, time and error against a high-accuracy reference.

One run measures, on the same machine and in the same process (times are the minimum of
``--repeat`` runs and are given as ratios, because the 2-core machine is shared); each
section is its own script (runnable alone, see its docstring):

1. **Spectral step** (``sve_spectral.py``; 1, 2, 5, 10, 20 nm) for the thickness ranges
   users meet (0-200, 0-400, 0-800 nm; incidence 0 … asin(NA)/2 + 0.5° for NA 0.8): ΔE00
   against direct 1 nm spectral evaluation at random (θ, d), time per colour.
2. **Colour-table grid** (``sve_table.py``; thickness step × angle step) at the spectral
   step the library picks for the range: ΔE00 of the interpolated table against direct 1 nm
   evaluation, build time, lookup time.
3. **ΔE formula and inversion search** (``sve_inversion.py``) on a synthetic ``nd`` scene
   with known truth and sensor noise (8-bit sRGB, shot + read noise of the preset): raw
   formula speed (``colour.difference.delta_e(method=...)``); ROI thickness
   (``sve_roi.py``: ``analysis.roi.fit_roi_thickness`` grid step, pixel samples, refinement
   sample), per-facet thickness (``sve_facet.py``: ``analysis.facets.facet_thickness``
   search step), per-pixel tilt (``sve_tilt.py``: ``analysis.tilt.invert_tilt`` tilt grid
   step, with and without the facet-plane prior); CIE76 / CIE94 inside a search where it
   takes ``delta_e_method=``.
4. **Focus operator and window** (``sve_focus.py``; ``focus.height.height_from_focus``):
   height RMSE in slices on the ground-truth stacks of Cou & Guennebaud (2023) in
   fixtures/focus-stacks, time.
5. **Eq. 6 quadrature** (``sve_eq6.py``; ``theta_m_step_deg`` of
   ``forward.angular.simulate_map(model="eq6")``, and the thickness-node step): ΔE00 of the
   90 × 90 angular map against a very dense reference, time.

It prints every table and writes OUT/speed-vs-error.md with a table and a Pareto plot
(error against time, default marked) per knob, plots in OUT/img/sve-*.png.

Run:  python pipelines/speed_vs_error.py            (full run, writes docs/; ~6-10 min on 2 cores)
      python pipelines/speed_vs_error.py --quick    (a fast check, writes out/speed-vs-error-quick/)
      python pipelines/speed_vs_error.py --sections spectral table   (only some knobs)
"""

from __future__ import annotations

import os
import platform
import sys
import time

import sve_eq6
import sve_focus
import sve_inversion
import sve_spectral
import sve_table
from _shared import Doc, git_describe, md_table, output_folder, parser
from _sve import config, defaults

SECTIONS = ("spectral", "table", "inversion", "focus", "eq6")
MODULES = dict(spectral=sve_spectral, table=sve_table, inversion=sve_inversion, focus=sve_focus,
               eq6=sve_eq6)


def intro(doc, cmd, cfg, quick):
    doc("# Speed against error\n")
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
        "all: [conditioning.md](conditioning.md) (`python pipelines/conditioning.py`).\n")
    doc("Contents: [1. spectral step](#1-spectral-step) · [2. colour-table resolution]"
        "(#2-colour-table-resolution) · [3. ΔE formula and inversion search]"
        "(#3-δe-formula-and-inversion-search) · [4. focus operator and window]"
        "(#4-focus-operator-and-window) · [5. eq. 6 quadrature](#5-eq-6-quadrature) · "
        "[summary](#summary-where-the-defaults-sit)\n")


def summary(doc, results):
    """Where each default sits, in one table (filled from whatever sections ran)."""
    doc("\n## Summary: where the defaults sit\n")
    rows = [row for name in SECTIONS if name in results
            for row in MODULES[name].summary_rows(results[name])]
    doc(md_table(["knob (where)", "default", "error of the default", "alternatives",
                  "verdict"], rows))


def main(argv=None):
    ap = parser(__doc__, quick="small samples, fewer settings, 1 repeat", repeat=None,
                out="folder for speed-vs-error.md and img/ (default docs/, or "
                    "out/speed-vs-error-quick/ with --quick)")
    ap.add_argument("--sections", nargs="+", choices=SECTIONS, default=list(SECTIONS))
    args = ap.parse_args(argv)
    cfg = config(args.quick, args.repeat)
    out = output_folder(args.out, quick=args.quick, name="speed-vs-error")
    img = out / "img"
    cmd = "python pipelines/speed_vs_error.py" + (" --quick" if args.quick else "") + (
        f" --repeat {args.repeat}" if args.repeat else "") + (
        " --sections " + " ".join(args.sections) if args.sections != list(SECTIONS) else "")
    import numpy

    from microfacet import __version__

    t_all = time.perf_counter()
    load0 = os.getloadavg()[0]
    doc = Doc()
    intro(doc, cmd, cfg, args.quick)
    results = {}
    for name in SECTIONS:
        if name not in args.sections:
            continue
        if name == "table":
            results[name] = sve_table.run(cfg, doc, img, results.get("spectral"))
        else:
            results[name] = MODULES[name].run(cfg, doc, img)
    summary(doc, results)
    elapsed = time.perf_counter() - t_all
    doc(f"\n---\nMeasured {time.strftime('%Y-%m-%d')} in {elapsed / 60:.1f} min "
        f"(load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end; "
        f"{os.cpu_count()} CPUs), microfacet {__version__} ({git_describe()}), numpy "
        f"{numpy.__version__}, Python {platform.python_version()}. Library defaults read from "
        f"the code at run time: {defaults()}.")
    doc.write(out / "speed-vs-error.md")
    print(f"\nwrote {out / 'speed-vs-error.md'} and {img}/sve-*.png", file=sys.stderr)


if __name__ == "__main__":
    main()
