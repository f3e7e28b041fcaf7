"""``microfacet synth OUT --preset NAME --seed N``: a synthetic stack with ground truth."""

from __future__ import annotations

import argparse
import sys

from .. import forward
from ..core.errors import InputError
from ..forward.synth_params import VARIATIONS, parse_variation
from .options import HelpFormatter, example_epilog, pair_type
from .progress import Progress

PRESET_NAMES = ("sd", "nd", "thick", "steep", "thin", "grainy", "noisy", "overexposed", "16bit")


def register(sub):
    p = sub.add_parser(
        "synth",
        help="write a synthetic focus stack of anodized titanium with ground truth",
        description=(
            "Generate a synthetic microscope focus stack (stack format microfacet-stack/1) "
            "of a rough anodized-titanium surface: macro waviness carrying planar "
            "microfacets, oxide-thickness regions from a Gaussian mixture, thin-film colour "
            "at incidence = facet tilt, darkness past asin(NA)/2, defocus blur, shot and "
            "read noise. Ground truth goes to OUT/truth/. Presets: " + ", ".join(PRESET_NAMES)
            + ". Imaging variations (off by default: other facet shapes, terraces, pits, "
            "scratches, dust, tilt-dependent brightness, vignetting, white balance, drift, "
            "JPEG slices, other optical constants) are set with --variation NAME=VALUE."),
        epilog=example_epilog(
            "microfacet synth nd-demo --preset nd --seed 1 --size 512x512 --slices 32",
            "microfacet synth nd-pits --preset nd --seed 1 --variation pit_density_per_mm2=2000 "
            "\\",
            "    --variation jpeg_quality=85 --variation white_balance_gains=1.1,1,0.9"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("out", metavar="OUT", help="output stack folder")
    p.add_argument("--preset", required=True, choices=PRESET_NAMES)
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--size", type=pair_type("x", int, "HxW, e.g. 512x512"), default=None,
                   metavar="HxW",
                   help="image size in pixels (default 256x256)")
    p.add_argument("--slices", type=int, default=None, metavar="K",
                   help="number of focal planes (default 24)")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=None)
    p.add_argument("--variation", action="append", default=[], type=_variation,
                   metavar="NAME=VALUE",
                   help="set an imaging variation (repeatable; docs/synthetic-stacks.md): "
                        + ", ".join(VARIATIONS))
    p.add_argument("--write-exposure", action="store_true",
                   help="write the true exposure into stack.json (else it must be estimated)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace OUT if it is an earlier synthetic stack")
    p.set_defaults(run=run)
    return p


def _variation(text):
    try:
        return parse_variation(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def run(args) -> int:
    over = dict(args.variation)
    over["seed"] = args.seed
    if args.size is not None:
        over["height_px"], over["width_px"] = args.size
    if args.slices is not None:
        over["n_slices"] = args.slices
    if args.bit_depth is not None:
        over["bit_depth"] = args.bit_depth
    if args.write_exposure:
        over["write_exposure"] = True
    try:
        params = forward.synth.preset(args.preset, **over)
    except ValueError as exc:
        name = str(exc).split(":")[0]
        flag = {"height_px": "--size", "width_px": "--size", "n_slices": "--slices",
                "bit_depth": "--bit-depth"}.get(name, "--variation" if name in VARIATIONS
                                                 else None)
        raise ValueError(f"{flag}: {exc}" if flag else str(exc)) from None
    with Progress("synth", total=params.n_slices, unit="slices", quiet=args.quiet) as bar:
        try:
            res = forward.synth.generate_stack(args.out, params, overwrite=args.overwrite,
                                 progress=bar.update)
        except InputError as exc:
            if exc.param in ("height_px", "width_px"):
                raise InputError(exc.reason, param="size") from None
            raise
    if not args.quiet:
        print(f"wrote {res.path} ({params.n_slices} slices {params.height_px}x{params.width_px},"
              f" {res.timings_s['total']:.1f} s)", file=sys.stderr)
    return 0
