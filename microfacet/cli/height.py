"""``microfacet height STACK --out OUT``: height from focus only
(:func:`microfacet.workflow.height.height_to_folder`).

Writes ``height_um.npy`` (float32, NaN where unreliable), ``normals.npy`` (float32 H×W×3, z up),
``all_in_focus.png``, ``reliability_db.npy`` + ``reliability.png``, a ``height.png`` preview and
``height.json`` (inputs, parameters, statistics, timings). The folder is written under a
temporary name beside OUT and renamed when complete.
"""

from __future__ import annotations

import argparse
import logging
import time

from .. import io, workflow
from ..focus.options import FocusOptions
from .options import (
    HelpFormatter,
    add_limit_options,
    add_option_fields,
    add_plain_folder_options,
    limits_from_args,
    options_from_args,
    plain_folder_values,
)
from .progress import Progress

EPILOG = """examples:
  microfacet height my-stack --out my-stack-height
  microfacet height my-stack --out h --operator sml --window-px 9 --fill --overwrite
  microfacet height folder-of-jpegs --pixel-size-um 0.5 --z-step-um 1 --out h --align
"""


def register(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "height",
        help="height map, normals and all-in-focus image from a focus stack",
        description=(
            "Height from focus: for every pixel the stage height where it is sharpest "
            "(sub-slice least-squares peak fit), its uncertainty and a reliability map in "
            "dB, unit normals from the height and the pixel size, and the all-in-focus "
            "composite."),
        epilog=EPILOG, formatter_class=HelpFormatter)

    p.add_argument("stack", metavar="STACK",
                   help="stack folder with stack.json (or its stack.json)")
    p.add_argument("--out", required=True, metavar="OUT",
                   help="output folder (new, empty, or an earlier height folder with "
                        "--overwrite; never an input or a folder holding one)")
    add_option_fields(p, FocusOptions)
    p.add_argument("--smooth-sigma-px", type=float, default=0.0, metavar="S",
                   help="Gaussian smoothing of the slopes for the normals, px (default: 0)")
    add_plain_folder_options(p)
    add_limit_options(p)
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT if it is an earlier microfacet height folder")
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    """Nothing on stdout; the progress bar and a log line (``-v``) on stderr."""
    t0 = time.perf_counter()
    options = options_from_args(args, FocusOptions)
    pixel_size_um, z_step_um = plain_folder_values(args)
    source = io.stack.StackSource(args.stack, pixel_size_um, z_step_um, limits_from_args(args),
                                  args.series)
    with Progress("height", total=1, unit="slices", quiet=args.quiet) as bar:
        res = workflow.height_to_folder(source, args.out, options=options,
                                        smooth_sigma_px=args.smooth_sigma_px,
                                        overwrite=args.overwrite, progress=bar.update)
    logging.getLogger("microfacet.height").info(
        "wrote %s (%.1f%% unreliable) in %.2f s", res.out, 100 * res.unreliable_fraction,
        time.perf_counter() - t0)
    return 0
