"""``microfacet export-brdf RESULTS --out FILE``: the fitted material as one file a renderer
reads (:mod:`microfacet.io.material_file`; docs/rendering.md)."""

from __future__ import annotations

import sys

from .. import workflow
from .options import HelpFormatter, example_epilog

_EXAMPLES = ("microfacet export-brdf nd-analysis --out nd-material",
             "microfacet export-brdf nd-analysis --out nd.npz --theta-step-deg 0.1")


def register(sub):
    p = sub.add_parser(
        "export-brdf", help="write a results folder's thin-film microfacet BRDF as one file",
        description=(
            "Tabulate the film reflectance averaged over the fitted thickness mixture, "
            "<R>(theta_d, wavelength), and write it with the NDF lobes, the thickness mixture "
            "and the optical constants' names to one .npz file (plain ZIP: three .npy arrays "
            "and metadata.json; the layout is in docs/rendering.md). The extension is added "
            "when missing. microfacet render and Mitsuba read it."),
        epilog=example_epilog(*_EXAMPLES), formatter_class=HelpFormatter)
    p.add_argument("results", metavar="RESULTS", help="an analyze results folder")
    p.add_argument("--out", required=True, metavar="FILE", help="the material file to write")
    p.add_argument("--theta-step-deg", type=float, default=None, metavar="DEG",
                   help="table step in the facet incidence angle (default 0.25)")
    p.add_argument("--wavelength-step-nm", type=float, default=None, metavar="NM",
                   help="table step in wavelength over 360-825 nm (default 1)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace FILE when it is a material file")
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    grid = {k: v for k, v in (("theta_step_deg", args.theta_step_deg),
                              ("wavelength_step_nm", args.wavelength_step_nm)) if v is not None}
    done = workflow.export_material(args.results, args.out, overwrite=args.overwrite, **grid)
    if not args.quiet:
        m = done.material
        lobes = ", ".join(f"{sd:.1f}° ({w:.0%})" for w, sd in m.ndf.components)
        print(f"wrote {done.path} ({m.film_average.shape[0]} angles x "
              f"{m.film_average.shape[1]} wavelengths; NDF lobes {lobes}) in "
              f"{done.seconds:.1f} s")
        source = m.metadata.get("source", {})
        if source and not source.get("ndf_identified", True):
            print(f"note: the analysis did not identify this NDF "
                  f"({source.get('ndf_reason') or 'no reason recorded'}); the material "
                  "renders it as fitted", file=sys.stderr)
    return 0
