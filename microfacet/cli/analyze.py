"""``microfacet analyze STACK --out OUT``: the whole pipeline on one stack."""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path

from .. import io, workflow
from ..analysis.stages import JOINT_ONLY, Stage
from ..core.threads import limit_malloc_arenas
from .options import (
    FLAGS,
    HelpFormatter,
    add_analysis_options,
    add_limit_options,
    add_plain_folder_options,
    analysis_options,
    example_epilog,
    limits_from_args,
    plain_folder_values,
)
from .progress import StageProgress


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
                              "--roi-size-px 128",
                              "microfacet analyze folder-of-jpegs --pixel-size-um 0.5 "
                              "--z-step-um 1 --out res --json"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("stack", metavar="STACK",
                   help="stack folder (microfacet-stack/1), a plain folder of images with "
                        "--pixel-size-um and --z-step-um, or a Zeiss .czi, Nikon .nd2 or Leica "
                        ".lif z-stack (extra microscopes)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="results folder (new, empty, or an earlier results folder with "
                        "--overwrite; never an input or a folder holding one)")
    add_analysis_options(p)
    add_plain_folder_options(p)
    add_limit_options(p)
    p.add_argument("--json", action="store_true",
                   help="print a JSON summary of the results on stdout instead of the text")
    p.add_argument("--no-report", action="store_true", help="skip report.pdf")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT if it is an earlier microfacet results folder")
    p.set_defaults(run=run)
    return p


#: Keys of summary.json that ``--json`` prints (with ``results``, the output folder).
JSON_KEYS = ("mode", "thickness", "ndf", "exposure", "exposure_source", "flat_field",
             "delta_e", "masked_fraction", "warnings", "timings_s")


def json_summary(out: Path) -> dict:
    """The ``--json`` summary of the results folder ``out``: its path, the stack, and the
    :data:`JSON_KEYS` of its ``summary.json`` (mixtures with ``identified`` and ``reason``)."""
    res = io.results.Results(out)
    return {"results": str(out), "stack": res.get("inputs", "stack"),
            **{k: res.get(k) for k in JSON_KEYS}}


def _plus_minus(u) -> str:
    """`` ± σ`` of a component's mean (``mean_uncertainty``), or nothing where unknown."""
    return "" if not u or u.get("sigma_nm") is None else f" ± {u['sigma_nm']:.1f}"


def _text_summary(result, out: Path, elapsed_s: float) -> str:
    dist = result.distributions
    fit = dist.thickness
    unc = (fit.info.get("mean_uncertainty") or []) if fit else []
    comps = ", ".join(f"{m:.1f}{_plus_minus(unc[i] if i < len(unc) else None)} nm "
                      f"({100 * w:.0f}%)" for i, (w, m, _) in enumerate(fit.mixture.components)) \
        if fit else "none"
    lobes = ", ".join(f"{s:.1f}° ({100 * w:.0f}%)" for w, s in dist.ndf.mixture.components) \
        if dist.ndf else "none"
    if any(u.get("sigma_nm") is not None and u.get("white_balance_nm") is None for u in unc):
        comps += " (± without the white balance's part: no estimate of the gains)"
    if fit is not None and not dist.thickness_judgement.identified:
        comps += " -- NOT IDENTIFIED"
    if result.self_check is not None and dist.ndf:
        c = result.self_check
        fixed = "width_correction" in dist.ndf.info
        lobes += ((f", self-check {c.transfer:.2f}±{c.transfer_se:.2f}x slopes, "
                   f"{c.width_transfer:.2f}±{c.width_transfer_se:.2f}x width"
                   + (" (widths corrected for it)" if fixed else ""))
                  if math.isfinite(c.transfer) else ", self-check measured nothing")
    if not dist.ndf_judgement.identified:
        lobes += " -- NOT IDENTIFIED, not a measurement"
    de = result.delta_e_stats
    ff = result.flat_field
    flat = (f", flat field {100 * ff.corner_loss(result.colour.lab.shape[:2]):.0f}% "
            f"lost at the corners ({ff.source})" if ff is not None and ff.applied else "")
    return (f"wrote {out} in {elapsed_s:.1f} s\n"
            f"  thickness: {comps}\n  NDF lobes (slope SD): {lobes}\n"
            f"  exposure {result.exposure:.3f} ({result.scene.exposure_source}), "
            f"mean dE00 {de['mean'] if de['mean'] is None else round(de['mean'], 2)}, "
            f"masked {100 * result.colour.mask.fraction:.1f}%{flat}")


def _skipped(args, options) -> tuple:
    """The stages that will not run (their share of the progress bar)."""
    skip = (Stage.REPORT,) if args.no_report else ()
    return skip + (JOINT_ONLY if options.mode == "seed" else ())


def run(args) -> int:
    """The results summary goes to stdout (text, or JSON with ``--json``); logs, warnings
    and the progress bar to stderr."""
    limit_malloc_arenas()         # before the analysis' threads start (core.threads)
    out = Path(args.out)
    opts = analysis_options(args)
    pixel_size_um, z_step_um = plain_folder_values(args)
    source = io.stack.StackSource(args.stack, pixel_size_um, z_step_um, limits_from_args(args),
                                  args.series)
    t0 = time.perf_counter()
    with StageProgress("analyze", list(Stage), skip=_skipped(args, opts),
                       quiet=args.quiet) as bar:
        result = workflow.analyse_to_folder(source, out, options=opts,
                                            overwrite=args.overwrite, report=not args.no_report,
                                            progress=bar.stage)
        bar.finish()
    for w in result.warnings:
        logging.getLogger(__name__).warning("%s: %s", out, w.render(FLAGS))
    if args.json:
        print(json.dumps(json_summary(out), indent=1))
    elif not args.quiet:
        print(_text_summary(result, out, time.perf_counter() - t0))
    return 0
