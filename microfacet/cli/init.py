"""``microfacet init FOLDER``: write the stack.json of a plain folder of images.

The images are found and ordered as :func:`microfacet.io.stack.find_images` does (natural
order, ``img_2`` before ``img_10``; one TIFF is a multi-page stack); the pixel size and z step
come from the options or, where an option is not given, from the images' OME or ImageJ
metadata. The stack.json is validated before it is put in place (written under a temporary
name, renamed when valid), so an invalid one is never left in the folder, and an existing
one is replaced only with ``--overwrite``. What was found is printed.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
from pathlib import Path

from .. import io, optics
from ..core.errors import InputError, one_line
from .options import (
    HelpFormatter,
    add_limit_options,
    example_epilog,
    limits_from_args,
    pixel_size_arg,
)


def register(subparsers) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "init",
        help="write stack.json for a plain folder of images (focus-stack slices)",
        description=(
            "Find the images of FOLDER (PNG, TIFF, JPEG; natural order, img_2 before img_10; "
            "one TIFF file is read as a multi-page stack), take the pixel size and z step "
            "from the options or from the images' OME/ImageJ metadata, validate the stack and "
            "write FOLDER/stack.json (microfacet-stack/1). The images are not touched."),
        epilog=example_epilog(
            "microfacet init my-slices --pixel-size-um 0.216 --z-step-um 0.5",
            "microfacet init my-ome-tiff-folder --film TiO2_Jolivet2023_anatase "
            "--numerical-aperture 0.9"),
        formatter_class=HelpFormatter)
    p.add_argument("folder", metavar="FOLDER", help="folder holding the slice images")
    p.add_argument("--pixel-size-um", type=pixel_size_arg, default=None, metavar="UM",
                   help="pixel size on the sample in µm, Y,X for non-square pixels (default: "
                        "from the image metadata)")
    p.add_argument("--z-step-um", type=float, default=None, metavar="UM",
                   help="stage step between slices in µm, slice i at i*UM (default: from the "
                        "image metadata)")
    p.add_argument("--film", default=None, metavar="NAME",
                   help="optical-constant set of the oxide film, written as 'film'")
    p.add_argument("--numerical-aperture", type=float, default=None, metavar="NA",
                   help="numerical aperture of the objective, in (0, 1]")
    add_limit_options(p)
    p.add_argument("--overwrite", action="store_true",
                   help="replace an existing FOLDER/stack.json")
    p.set_defaults(run=run)
    return p


def _check_options(args) -> dict:
    """The optional stack.json keys from the options, each checked with its option's name."""
    optional = {}
    if args.film is not None:
        known = optics.known_sets()
        if args.film not in known:
            raise InputError(f"unknown optical-constant set {args.film!r}; known: "
                             f"{', '.join(known)}", param="film")
        optional["film"] = args.film
    na = args.numerical_aperture
    if na is not None:
        if not (math.isfinite(na) and 0 < na <= 1):
            raise InputError(f"must be a number in (0, 1], got {na:g}",
                             param="numerical_aperture")
        optional["illumination"] = {"geometry": "coaxial", "numerical_aperture": na}
    return optional


def _source(stack, key: str, option: str) -> str:
    src = stack.sources.get(key, "")
    return f"option {option}" if src == "given" else src


class _OnceFilter(logging.Filter):
    """Drops a warning already shown: the folder is validated twice (as found, then as the
    stack.json about to be written), with the same warnings."""

    def __init__(self):
        super().__init__()
        self.seen = set()

    def filter(self, record):
        text = record.getMessage().replace("(no stack.json)", "stack.json")
        new = text not in self.seen
        self.seen.add(text)
        return new


@contextlib.contextmanager
def _warn_once():
    logger, once = logging.getLogger("microfacet.io.stack"), _OnceFilter()
    logger.addFilter(once)
    try:
        yield
    finally:
        logger.removeFilter(once)


def run(args) -> int:
    with _warn_once():
        return _init(args)


def _init(args) -> int:
    folder = Path(args.folder)
    if not folder.is_dir():
        raise InputError(f"{one_line(folder)}: not a folder")
    jpath = folder / "stack.json"
    if jpath.exists() and not args.overwrite:
        raise InputError(f"{one_line(jpath)}: already exists; `overwrite` replaces it")
    optional = _check_options(args)
    limits = limits_from_args(args)
    # everything validated before anything is written; the stack.json in place is ignored
    stack = io.stack.stack_from_images(folder, pixel_size_um=args.pixel_size_um,
                                       z_step_um=args.z_step_um, limits=limits)
    y, x = stack.pixel_size_yx_um
    pixel = x if stack.square_pixels else [y, x]
    z = stack.z_um
    z_step = float(z[1] - z[0]) if z.size > 1 else None
    images = io.stack.find_images(folder)
    path = io.stack.write_stack_json(
        folder, pixel_size_um=pixel, slices=images.get("slices"), tiff=images.get("tiff"),
        z_step_um=z_step, z_um=None if z_step is not None else [float(v) for v in z],
        limits=limits, **optional)

    names = ([p.name for p in stack.slice_paths] if stack.tiff_path is None
             else [f"{stack.tiff_path.name} page 0", f"{stack.tiff_path.name} page "
                   f"{stack.n_slices - 1}"])
    kind = "RGB" if stack.channels == 3 else "grey"
    pixel_text = (f"{x:g} µm" if stack.square_pixels
                  else f"{y:g} µm high x {x:g} µm wide (non-square)")
    print(f"wrote {one_line(path)}")
    print(f"  slices:     {stack.n_slices} ({stack.shape[1]}x{stack.shape[0]} px, "
          f"{stack.dtype.itemsize * 8}-bit {kind})")
    print(f"  order:      {one_line(names[0])} ... {one_line(names[-1])}")
    print(f"  z:          {z.min():g} to {z.max():g} µm"
          + (f" in steps of {z_step:g} µm" if z_step is not None else "")
          + f" ({_source(stack, 'z_um', '--z-step-um')})")
    print(f"  pixel size: {pixel_text} ({_source(stack, 'pixel_size_um', '--pixel-size-um')})")
    for key, value in optional.items():
        print(f"  {key}: {value}")
    return 0
