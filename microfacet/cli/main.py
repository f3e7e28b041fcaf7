"""The ``microfacet`` command line.

Every subcommand lives in its own module under :mod:`microfacet.cli` and provides

``register(subparsers) -> argparse.ArgumentParser``
    adds its parser (with ``help``, an example in the epilog) and sets
    ``parser.set_defaults(run=<callable(args) -> int>)``.

The run callable imports what it needs (numpy, colour, ...) itself, so that
``microfacet --help`` stays fast. User errors are raised as :class:`ValueError`,
:class:`FileNotFoundError` or :class:`microfacet.core.errors.InputError` and reported here as
one line with exit status 2 (a traceback only with ``-v``).
"""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import signal
import sys

from .. import __version__
from ..core.errors import InputError, one_line
from ..core.threads import ENV_VAR as THREADS_ENV_VAR
from ..core.threads import set_num_threads, threads_from_text
from .options import FLAGS

#: Subcommand modules, in the order ``--help`` lists them.
COMMANDS = (
    "init",
    "analyze",
    "height",
    "synth",
    "simulate",
    "export_brdf",
    "render",
    "fit_spectrum",
    "batch",
)

EXIT_USER_ERROR = 2
EXIT_INTERNAL_ERROR = 1


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``microfacet analyze: error: ... (see --help)``."""

    def error(self, message):
        self.exit(EXIT_USER_ERROR, f"{self.prog}: error: {one_line(message)} "
                                   f"(see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="microfacet",
        description=(
            "Oxide-thickness and microfacet-normal distributions of anodized titanium from "
            "microscope focus stacks, and their thin-film interference colour."
        ),
    )
    parser.add_argument("--version", action="version", version=f"microfacet {__version__}")
    _add_verbosity(parser, dest_prefix="global_")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMANDS:
        try:
            module = importlib.import_module(f"microfacet.cli.{name}")
        except ModuleNotFoundError as exc:  # a command not built yet
            if exc.name != f"microfacet.cli.{name}":
                raise
            continue
        _add_verbosity(module.register(sub))
    return parser


def _add_verbosity(p: argparse.ArgumentParser, dest_prefix: str = "") -> None:
    """``-v``/``-q`` on the main parser (``dest_prefix="global_"``) and on every command, so
    they work before and after the command name. The two sets have their own ``dest``: a
    subparser's defaults would otherwise overwrite what the main parser read."""
    p.add_argument("-v", "--verbose", action="count", default=0, dest=f"{dest_prefix}verbose",
                   help="log progress (-v) and debug details (-vv); show tracebacks")
    p.add_argument("-q", "--quiet", action="store_true", dest=f"{dest_prefix}quiet",
                   help="no progress bars or log messages")


def merge_verbosity(args: argparse.Namespace) -> None:
    """``args.verbose``/``args.quiet`` from the options given before and after the command."""
    args.verbose = getattr(args, "verbose", 0) + getattr(args, "global_verbose", 0)
    args.quiet = bool(getattr(args, "quiet", False) or getattr(args, "global_quiet", False))


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


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that every ``with`` block cleans up (partial
    output folders are removed, locks released) exactly as for Ctrl-C."""


def _on_sigterm(signum, frame):
    raise Terminated()


def _user_message(exc: BaseException) -> str | None:
    """One line for an error caused by the input or the environment, None for a bug."""
    if isinstance(exc, InputError):
        return exc.cli_message(FLAGS)
    if isinstance(exc, OSError):
        name = exc.filename if exc.filename is not None else ""
        what = exc.strerror or str(exc) or type(exc).__name__
        if exc.filename2 is not None:
            name = f"{name} -> {exc.filename2}"
        return f"{name}: {what}" if name else what
    if isinstance(exc, MemoryError):
        return ("out of memory (the input is larger than this machine can hold; see "
                "--max-megapixels and the limits in docs/stack-format.md)")
    if isinstance(exc, RecursionError):
        return "input nested too deeply to read"
    if isinstance(exc, OverflowError):
        return f"a number in the input is out of range ({exc})"
    if isinstance(exc, (ValueError, UnicodeError)):
        return str(exc) or type(exc).__name__
    return None


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``microfacet`` console script; returns the exit status.

    Exit status: 0 success; 2 with one line on stderr for bad input, options or environment
    (a full or read-only disk, too little memory); 1 for an internal error (one line and a
    hint to rerun with ``-v`` for the traceback); 130 after Ctrl-C and 143 after SIGTERM,
    leaving nothing half-written.
    """
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a one-line usage error (_Parser.error)
        return exc.code if isinstance(exc.code, int) else EXIT_USER_ERROR
    if getattr(args, "run", None) is None:
        parser.print_help()
        return EXIT_USER_ERROR
    merge_verbosity(args)
    verbose = args.verbose
    _setup_logging(verbose, args.quiet)
    prog = f"microfacet {args.command}"
    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (embedded use): leave signals alone
        pass
    try:
        set_num_threads(threads_from_text(os.environ.get(THREADS_ENV_VAR)))
        return int(args.run(args) or 0)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"{prog}: terminated", file=sys.stderr)
        return 143
    except Exception as exc:
        if verbose:
            raise
        msg = _user_message(exc)
        if msg is not None:
            print(f"{prog}: error: {one_line(msg)}", file=sys.stderr)
            return EXIT_USER_ERROR
        print(f"{prog}: internal error: {type(exc).__name__}: {one_line(exc)} "
              f"(please report it; rerun with -v for the traceback)", file=sys.stderr)
        return EXIT_INTERNAL_ERROR
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
