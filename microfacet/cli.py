"""The ``microfacet`` command line.

Every subcommand lives in its own module under :mod:`microfacet.commands` and provides

``register(subparsers) -> argparse.ArgumentParser``
    adds its parser (with ``help``, an example in the epilog) and sets
    ``parser.set_defaults(run=<callable(args) -> int>)``.

The run callable imports what it needs (numpy, colour, ...) itself, so that
``microfacet --help`` stays fast. User errors are raised as :class:`ValueError`,
:class:`FileNotFoundError` or :class:`microfacet.errors.InputError` and reported here as
one line with exit status 2 (a traceback only with ``-v``).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys

from . import __version__

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "analyze",
    "height",
    "synth",
    "simulate",
    "fit_spectrum",
    "batch",
)

EXIT_USER_ERROR = 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="microfacet",
        description=(
            "Oxide-thickness and microfacet-normal distributions of anodized titanium from "
            "microscope focus stacks, and their thin-film interference colour."
        ),
    )
    parser.add_argument("--version", action="version", version=f"microfacet {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"microfacet.commands.{name}")
        except ModuleNotFoundError as exc:  # a command not built yet
            if exc.name != f"microfacet.commands.{name}":
                raise
            continue
        p = module.register(sub)
        p.add_argument("-v", "--verbose", action="count", default=0,
                       help="log progress (-v) and debug details (-vv); show tracebacks")
        p.add_argument("-q", "--quiet", action="store_true",
                       help="no progress bars or log messages")
    return parser


def _setup_logging(verbose: int, quiet: bool) -> None:
    level = logging.WARNING
    if quiet:
        level = logging.ERROR
    elif verbose >= 2:
        level = logging.DEBUG
    elif verbose == 1:
        level = logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s",
                        stream=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microfacet`` console script; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "run", None) is None:
        parser.print_help()
        return EXIT_USER_ERROR
    verbose = getattr(args, "verbose", 0)
    _setup_logging(verbose, getattr(args, "quiet", False))
    from .errors import InputError

    try:
        return int(args.run(args) or 0)
    except (InputError, ValueError, FileNotFoundError, NotADirectoryError,
            IsADirectoryError, FileExistsError, PermissionError) as exc:
        if verbose:
            raise
        print(f"microfacet {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("microfacet: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
