"""Options shared by several subcommands."""

from __future__ import annotations

import argparse


def add_optics_options(p: argparse.ArgumentParser) -> None:
    """``--film``, ``--substrate``, ``--illuminant``, ``--observer``."""
    from ..optics import DEFAULT_FILM, DEFAULT_SUBSTRATE  # light module (numpy only)

    g = p.add_argument_group("optics")
    g.add_argument("--film", default=None, metavar="NAME",
                   help=f"optical-constant set of the oxide film (default {DEFAULT_FILM})")
    g.add_argument("--substrate", default=None, metavar="NAME",
                   help=f"optical-constant set of the metal (default {DEFAULT_SUBSTRATE})")
    g.add_argument("--illuminant", default="D65", help="illuminant name (default D65)")
    g.add_argument("--observer", default="2", choices=["2", "10"],
                   help="CIE standard observer in degrees (default 2)")


def optics_kwargs(args) -> dict:
    from ..optics import DEFAULT_FILM, DEFAULT_SUBSTRATE, load_set

    film = args.film or DEFAULT_FILM
    substrate = args.substrate or DEFAULT_SUBSTRATE
    for opt, name in (("--film", film), ("--substrate", substrate)):
        try:
            load_set(name)
        except ValueError as exc:
            raise ValueError(f"{opt}: {exc}") from None
    return dict(film=film, substrate=substrate, illuminant=args.illuminant,
                observer=args.observer)


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


def example_epilog(*lines: str) -> str:
    return "example:\n" + "\n".join(f"  {line}" for line in lines)
