"""Options shared by several subcommands."""

from __future__ import annotations

import argparse
import logging
import math
import textwrap
from pathlib import Path

from .. import analysis, workflow
from ..core.errors import InputError
from ..core.options import option_fields
from ..core.pixels import pixel_size_value
from ..io import limits
from ..io.limits import DEFAULT_MAX_MEGAPIXELS, DEFAULT_MAX_STACK_MEGAPIXELS
from ..io.vendor import is_vendor


def add_optics_options(p: argparse.ArgumentParser) -> None:
    """``--film``, ``--substrate``, ``--illuminant``, ``--observer``: the flags of
    :class:`~microfacet.workflow.simulate.FilmOptics` (``simulate``, ``fit-spectrum``)."""
    add_option_fields(p, workflow.FilmOptics, title="optics")


def optics_options(args):
    """:class:`~microfacet.workflow.simulate.FilmOptics` from the flags given (None where not
    given); an unknown set is an InputError naming the option."""
    return options_from_args(args, workflow.FilmOptics)


def optics_kwargs(args) -> dict:
    """``film``, ``substrate``, ``illuminant``, ``observer`` from the options, the defaults for
    those not given (:meth:`~microfacet.workflow.simulate.FilmOptics.resolved`)."""
    return optics_options(args).resolved()


def add_limit_options(p: argparse.ArgumentParser) -> None:
    """``--max-megapixels``, ``--max-stack-megapixels`` (see :mod:`microfacet.io.limits`)."""
    g = p.add_argument_group("limits (checked from the image headers before any work)")
    g.add_argument("--max-megapixels", type=float, default=DEFAULT_MAX_MEGAPIXELS, metavar="MP",
                   help=f"largest image, megapixels (default {DEFAULT_MAX_MEGAPIXELS:g})")
    g.add_argument("--max-stack-megapixels", type=float, default=DEFAULT_MAX_STACK_MEGAPIXELS,
                   metavar="MP", help="largest total of all slices of a stack, megapixels "
                                      f"(default {DEFAULT_MAX_STACK_MEGAPIXELS:g})")


def limits_from_args(args):
    """:class:`~microfacet.io.limits.Limits` from ``--max-megapixels`` and
    ``--max-stack-megapixels``."""
    return limits.Limits(max_megapixels=args.max_megapixels,
                  max_stack_megapixels=args.max_stack_megapixels)


def add_plain_folder_options(p: argparse.ArgumentParser) -> None:
    """``--pixel-size-um``, ``--z-step-um``: read a plain folder of images (no stack.json) as a
    stack (``height``, ``analyze``)."""
    p.add_argument("--pixel-size-um", type=pixel_size_arg, default=None, metavar="UM",
                   help="for a plain image folder without stack.json: pixel size in µm "
                        "(Y,X for non-square pixels)")
    p.add_argument("--z-step-um", type=float, default=None, metavar="UM",
                   help="for a plain image folder without stack.json: z step in µm")
    p.add_argument("--series", type=int, default=None, metavar="N",
                   help="which z-stack of a .czi (scene), .nd2 (XY position) or .lif (image) "
                        "file, counted from 0 (default 0, or stack.json's series)")


def plain_folder_values(args) -> tuple[float | None, float | None]:
    """``(pixel_size_um, z_step_um)`` to read ``args.stack`` with: both None for a stack with a
    stack.json, both given for a plain folder of images.

    Options given for a stack that has a stack.json are ignored, with a one-line warning each
    (the stack.json's values are used); a folder without stack.json needs both options (an
    :class:`~microfacet.core.errors.InputError` names the missing stack.json or option).
    """
    path = Path(args.stack)
    folder = path.parent if path.name == "stack.json" else path
    given = {"--pixel-size-um": args.pixel_size_um, "--z-step-um": args.z_step_um}
    jpath = folder / "stack.json"
    if path.is_file() and is_vendor(path):   # the file's values unless given
        return args.pixel_size_um, args.z_step_um
    if jpath.is_file():
        what = {"--pixel-size-um": "pixel size", "--z-step-um": "slice heights"}
        for option, value in given.items():
            if value is not None:
                logging.getLogger("microfacet.cli").warning(
                    "%s %s ignored: %s gives the %s", option, value, jpath, what[option])
        return None, None
    if not folder.is_dir():  # read_stack says what is wrong with it
        return None, None
    if all(v is None for v in given.values()):
        raise InputError(f"{jpath}: missing stack.json (for a plain folder of images give "
                         f"--pixel-size-um and --z-step-um)")
    if any(v is None for v in given.values()):
        raise InputError(f"{folder}: no stack.json; give both --pixel-size-um and "
                         f"--z-step-um to read the images in the folder as a stack")
    if not (math.isfinite(args.z_step_um) and args.z_step_um != 0):
        raise InputError(f"must be a finite non-zero number, got {args.z_step_um}",
                         param="z_step_um")
    return args.pixel_size_um, args.z_step_um


def pixel_size_arg(text: str):
    """argparse type of ``--pixel-size-um``: one size in µm, or ``Y,X`` for non-square pixels.

    >>> pixel_size_arg("0.5"), pixel_size_arg("0.25,0.5")
    (0.5, [0.25, 0.5])
    """
    try:
        parts = [float(v) for v in text.replace(";", ",").split(",")]
        return pixel_size_value(parts[0] if len(parts) == 1 else parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be a finite number > 0 (µm), or Y,X for non-square pixels (e.g. 0.25,0.5), "
            f"got {text!r}") from None


def pair_type(sep: str, cast, example: str):
    """argparse type for two values joined by ``sep`` (e.g. ``512x512``, ``0:400``)."""

    def parse(text):
        try:
            a, b = (cast(v) for v in text.lower().split(sep))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected two values as {example}, got {text!r}") from None
        return a, b

    return parse


def add_option_fields(p, cls, *, title: str | None = None, skip=(), only=None) -> None:
    """Add a flag for every command-line option of the options class ``cls``
    (:func:`microfacet.core.options.option_fields` with ``cli=True``): type, choices, help and
    default from the fields' metadata. Unset flags stay None and take the field's default in
    :func:`options_from_args`.

    Parameters
    ----------
    p : argparse.ArgumentParser
    cls : type
        An :class:`~microfacet.core.options.Options` class (a tree: sub-sections are walked).
    title : str, optional
        An argument group to put them in.
    skip : collection of str
        Dotted paths not to add (a command that fixes them).
    only : collection of str, optional
        Add only these dotted paths (a command that puts the options in several groups).
    """
    g = p.add_argument_group(title) if title else p
    for f in option_fields(cls):
        if f.flag is None or f.path in skip or (only is not None and f.path not in only):
            continue
        meta = f.field.metadata
        kw = dict(dest=_dest(f.path), default=None, metavar=meta.get("metavar"))
        kind = f.kind
        if kind is bool and not meta.get("cli_kwargs"):
            kw.update(action="store_true")
            kw.pop("metavar")
        elif kind is tuple:
            kw["type"] = pair_type(":", float, "LOW:HIGH")
            kw["metavar"] = kw["metavar"] or "LOW:HIGH"
        elif kind in (int, float, str):
            kw["type"] = kind
            kw["metavar"] = kw["metavar"] or {int: "N", float: "X", str: "NAME"}[kind]
        if meta.get("choices") is not None and kind is not tuple:
            kw["choices"] = [c for c in meta["choices"] if c is not None]
            kw.pop("metavar", None)
        kw.update(meta.get("cli_kwargs") or {})
        kw["help"] = f.help + _default_text(f)
        g.add_argument(f.flag, **kw)
        FLAGS[f.path] = f.flag


#: ``{dotted option path: flag}`` of every option a command registered
#: (:func:`add_option_fields`): how an error or a reason naming an option shows it.
FLAGS: dict = {}


def _default_text(f) -> str:
    """`` (default 255 px)``; nothing for a default of None (the help says what happens)."""
    d = f.default
    if d is None or d is False:
        return ""
    shown = (":".join(f"{v:g}" for v in d) if isinstance(d, tuple)
             else f"{d:g}" if isinstance(d, float) and not isinstance(d, bool) else str(d))
    unit = "" if not f.unit else f.unit if f.unit in ("°", "%") else f" {f.unit}"
    return f" (default {shown}{unit})"


def _dest(path: str) -> str:
    return "opt__" + path.replace(".", "__")


def options_from_args(args, cls, **fixed):
    """The options tree ``cls`` from the flags :func:`add_option_fields` added (those given),
    with ``fixed`` dotted-path values on top; validated on construction (an
    :class:`~microfacet.core.errors.InputError` names the option's path, which
    :func:`cli_flags` turns into its flag)."""
    tree: dict = {}
    values = {f.path: getattr(args, _dest(f.path), None) for f in option_fields(cls)
              if f.flag is not None}
    values.update(fixed)
    for path, value in values.items():
        if value is None:
            continue
        node = tree
        *parents, leaf = path.split(".")
        for k in parents:
            node = node.setdefault(k, {})
        node[leaf] = tuple(value) if isinstance(value, list) else value
    return cls.from_dict(tree)


def cli_flags(*classes) -> dict:
    """``{dotted option path: flag}`` of the options classes (for error messages)."""
    return {f.path: f.flag for cls in classes for f in option_fields(cls) if f.flag}


def example_epilog(*lines: str) -> str:
    return "example:\n" + "\n".join(f"  {line}" for line in lines)


#: Options of the tree ``analyze`` does not offer: filling the height map's unreliable pixels
#: would hand the facet planes heights that were not measured (``microfacet height`` offers
#: it).
ANALYSIS_SKIP = ("focus.fill",)


def add_analysis_options(p: argparse.ArgumentParser) -> None:
    """The command-line options of :class:`~microfacet.analysis.options.AnalysisOptions`
    (``analyze``, ``batch``), generated from its fields."""
    add_option_fields(p, analysis.AnalysisOptions, title="analysis", skip=ANALYSIS_SKIP)


def analysis_options(args):
    """:class:`~microfacet.analysis.options.AnalysisOptions` from the parsed options,
    validated (an :class:`~microfacet.core.errors.InputError` names the option)."""
    return options_from_args(args, analysis.AnalysisOptions)


class HelpFormatter(argparse.HelpFormatter):
    """Wraps description paragraphs (split at blank lines) to the terminal width, and keeps
    indented lines (examples) as written."""

    def _fill_text(self, text, width, indent):
        out = []
        for para in text.split("\n\n"):
            lines = para.splitlines()
            if lines and all(line.startswith(" ") or line.endswith(":") for line in lines):
                out.append("\n".join(indent + line for line in lines))
            else:
                out.append(textwrap.fill(" ".join(para.split()), width,
                                         initial_indent=indent, subsequent_indent=indent))
        return "\n\n".join(out)
