"""``microfacet analyze STACK --out OUT``: the whole pipeline on one stack."""

from __future__ import annotations

import logging
import sys
import time
from pathlib import Path

from .. import batch
from .options import (
    HelpFormatter,
    add_analysis_options,
    add_limit_options,
    analysis_options,
    example_epilog,
    limits_from_args,
)
from .progress import Progress


def register(sub):
    p = sub.add_parser(
        "analyze",
        help="thickness and normal distributions from a focus stack (the whole pipeline)",
        description=(
            "Height from focus, colour mask, exposure, oxide thickness per region of interest, "
            "per-pixel thickness and facet tilt, and the fitted thickness mixture and NDF "
            "(seed §3.3.3). Writes the results folder: summary.json, height_um.npy, "
            "normals.npy, all_in_focus.png, thickness_nm.npy, tilt_deg.npy, "
            "tilt_sigma_deg.npy, thickness_roi.csv, thickness_pdf.csv, ndf_pdf.csv, report.pdf."),
        epilog=example_epilog("microfacet analyze fixtures/stacks/nd-fixture --out out/nd",
                              "microfacet analyze my-stack --out res --mode seed "
                              "--roi-size-px 128"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("stack", metavar="STACK", help="stack folder (microfacet-stack/1)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="results folder (new, empty, or an earlier results folder with "
                        "--overwrite; never an input or a folder holding one)")
    add_analysis_options(p)
    add_limit_options(p)
    p.add_argument("--no-report", action="store_true", help="skip report.pdf")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT if it is an earlier microfacet results folder")
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    out = Path(args.out)
    opts = analysis_options(args)
    t0 = time.perf_counter()
    stages = ["height from focus", "colour", "colour table", "thickness per ROI",
              "tilt per pixel", "distributions", "write", "report"]
    with Progress("analyze", total=len(stages), unit="stages", quiet=args.quiet) as bar:
        def progress(name):
            bar.update(stages.index(name) if name in stages else 0)

        result = batch.analyse_to_folder(args.stack, out, options=opts,
                                         overwrite=args.overwrite, report=not args.no_report,
                                         limits=limits_from_args(args), progress=progress)
        bar.update(len(stages))
    if not args.quiet:
        fit = result.thickness_fit
        comps = ", ".join(f"{m:.1f} nm ({100 * w:.0f}%)" for w, m, _ in fit.mixture.components) \
            if fit else "none"
        lobes = ", ".join(f"{s:.1f}° ({100 * w:.0f}%)"
                          for w, s in result.ndf_fit.mixture.components) \
            if result.ndf_fit else "none"
        if fit is not None and not fit.identified:
            comps += " -- NOT IDENTIFIED"
        if result.ndf_fit is None or not result.ndf_fit.identified:
            lobes += " -- NOT IDENTIFIED, not a measurement"
        de = result.delta_e_stats
        print(f"wrote {out} in {time.perf_counter() - t0:.1f} s\n"
              f"  thickness: {comps}\n  NDF lobes (slope SD): {lobes}\n"
              f"  exposure {result.exposure:.3f} ({result.exposure_source}), "
              f"mean dE00 {de['mean'] if de['mean'] is None else round(de['mean'], 2)}, "
              f"masked {100 * result.mask.fraction:.1f}%", file=sys.stderr)
    for w in result.warnings:
        logging.getLogger(__name__).warning("%s: %s", out, w)
    return 0
