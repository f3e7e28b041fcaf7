"""``microfacet render``: the measured material on a plate, a bent sheet, a sphere or a mesh,
photographed under D65 with a camera given as focal length, sensor, f-number, shutter and ISO
(seed §2.6; :mod:`microfacet.workflow.render`, docs/rendering.md)."""

from __future__ import annotations

import sys

from .. import workflow
from ..workflow.render import RenderOptions
from .options import HelpFormatter, add_option_fields, example_epilog, options_from_args
from .progress import Progress

_EXAMPLES = (
    "microfacet render --results nd-analysis --out nd-render",
    "microfacet render --material nd.npz --scene sheet --spp 256 --out nd-sheet",
    "microfacet render --results nd-analysis --scene part.obj --camera-focal-length-mm 90 \\",
    "    --camera-f-number 11 --light-kind sun --light-illuminance-lux 50000 --out nd-part",
)


def register(sub):
    p = sub.add_parser(
        "render", help="render the measured material in Mitsuba 3 (extra: render)",
        description=(
            "Put the fitted thin-film microfacet BRDF on an object and photograph it in "
            "Mitsuba 3's spectral renderer: a D65 lamp or sun with a D65 ambient, a camera "
            "given as focal length, sensor size, f-number, shutter and ISO. Writes "
            "render.exr (linear sRGB, Y in cd/m2), render.png (as the camera exposed it), "
            "render.json, and scene.xml with material.npz beside it for Mitsuba. "
            "Needs pip install \"microfacet[render]\"; the fast LLVM variant needs a "
            "libLLVM >= 16 (Debian: libllvm19), else the scalar one is used, ~100x slower."),
        epilog=example_epilog(*_EXAMPLES), formatter_class=HelpFormatter)
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--results", metavar="DIR", help="an analyze results folder")
    src.add_argument("--material", metavar="FILE", help="a material file of export-brdf")
    p.add_argument("--out", required=True, metavar="OUT", help="output folder")
    p.add_argument("--overwrite", action="store_true", help="replace an existing render OUT")
    add_option_fields(p, RenderOptions, only=("scene", "spp", "seed", "variant"))
    add_option_fields(p, RenderOptions, title="camera",
                      only=[f"camera.{n}" for n in RenderOptions().camera.to_dict()])
    add_option_fields(p, RenderOptions, title="light",
                      only=[f"light.{n}" for n in RenderOptions().light.to_dict()])
    p.set_defaults(run=run)
    return p


def run(args) -> int:
    options = options_from_args(args, RenderOptions)
    with Progress("render", total=1, unit="passes", quiet=args.quiet) as bar:
        done = workflow.render_to_folder(args.out, results=args.results,
                                         material=args.material, options=options,
                                         overwrite=args.overwrite, progress=bar.update)
    if done.note:
        print(f"note: {done.note}", file=sys.stderr)
    if done.source.get("ndf_identified") is False:
        print(f"note: the analysis did not identify this NDF "
              f"({done.source.get('ndf_reason') or 'no reason recorded'}); it is rendered as "
              "fitted", file=sys.stderr)
    if not args.quiet:
        h, w = done.shape
        msg = (f"wrote {args.out}/render.png and render.exr ({w} x {h} px, "
               f"{options.spp} spp, {done.variant}) in {done.seconds:.1f} s")
        if done.saturated_fraction > 0.01:
            msg += (f"; {done.saturated_fraction:.0%} of the pixels saturate (shorter "
                    "--camera-shutter-s or a lower --camera-iso)")
        print(msg)
    return 0
